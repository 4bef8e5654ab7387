# ---
# jupyter:
#   jupytext:
#     text_representation:
#       extension: .py
#       format_name: percent
#   kernelspec:
#     display_name: Python 3
#     language: python
#     name: python3
# ---

# %% [markdown]
# # Chapter 2 — Foundations
#
# The thesis builds three algorithms (SVSL, Di-SkilL, DIME) on a handful of ideas that
# Chapter 2 introduces. This notebook restates each idea in a few lines and then
# *checks* it numerically with code from `vslbook`: every check compares the two sides
# of an equation of the thesis and stops the notebook if they disagree. The same checks
# run in the test suite (`tests/test_bounds_foundations.py`).
#
# Contents
# 1. Episode-based vs step-based RL — a live ERL run (Eq. 2.26–2.33)
# 2. Maximum-entropy RL — soft value iteration and the Boltzmann policy (Eq. 2.39–2.43)
# 3. Self-paced curricula (Eq. 2.44)
# 4. Movement primitives — ProMP, DMP, ProDMP (Eq. 2.45–2.46)
# 5. Mixtures of experts (Eq. 2.47–2.49)
# 6. Diffusion models — the Ornstein–Uhlenbeck forward process (Eq. 2.50–2.55)
# 7. Variational inference — KL chain rule, the mixture E-step, the diffusion KL, max-ent RL as inference (Eq. 2.56–2.71)
# 8. Mutual-information skill discovery (Eq. 2.72–2.74)

# %%
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np
from IPython.display import display

import vslbook
from vslbook.bounds import foundations as F
from vslbook.budget import get_budget
from vslbook.plots import learning_curve, method_color, save_figure, use_style

budget = get_budget()
use_style()
ROOT = Path(vslbook.__file__).resolve().parents[1]
print(f"budget: {budget.name}  (set VSLBOOK_BUDGET=smoke|reduced|full)")


def show(report):
    """Display a CheckReport and stop the notebook if any of its checks failed."""
    display(report)
    return report.require()


# %% [markdown]
# ## 1. Episode-based vs step-based RL
#
# Step-based RL (SRL) perturbs the action at every time step and learns from the tuples
# $(s_t, a_t, r_t, s_{t+1})$. Episode-based RL (ERL) perturbs the *parameters* $\theta$
# of a deterministic low-level controller — here a movement primitive — once per episode
# and treats the episode as a black box that returns $R(\theta, c)$ for a context $c$
# (Eq. 2.27):
#
# $$J(\pi_\omega) = \mathbb{E}_{p(c)}\Big[\int \pi_\omega(\theta\mid c)\, R(\theta, c)\, d\theta\Big].$$
#
# Because nothing inside the episode is used, the return may be non-Markovian (the final
# distance to a goal, the maximum height of a jump). The simplest learner is the
# likelihood-ratio gradient with a context-dependent baseline $V(c)$ (Eq. 2.31–2.33):
#
# $$\nabla_\omega J \approx \frac1N\sum_i \nabla_\omega \log\pi_\omega(\theta_i\mid c_i)\,\big(R(\theta_i,c_i)-V(c_i)\big).$$
#
# `vslbook.erl.pg` implements it for a linear-Gaussian $\pi_\omega(\theta\mid c)=\mathcal N(Kc+k,\operatorname{diag}\sigma^2)$
# on `vslbook/PointReach-v0`: a planar ProMP starting at the origin must end at the goal $c\in[-1,1]^2$.

# %%
from vslbook.erl.pg import train

vslbook.show_source(train)

# %% [markdown]
# Train one run per seed at the active budget. Each run writes a resumable run
# directory under `runs/`; running the cell again reuses finished runs. The curves are
# read back through the `data/results` tables (sha256-checked) and aggregated as the
# interquartile mean with a 95 % stratified-bootstrap interval.

# %%
from vslbook.results import collect_runs, load_table
from vslbook.stats import iqm_curve
from vslbook.training import run

runs = [
    run("erl-pg", "vslbook/PointReach-v0", seed=s, budget=budget, root=ROOT / "runs", progress=False)
    for s in range(budget.seeds)
]
tables_dir = ROOT / "data" / "results" / f"ch2-erl-pg-{budget.name}"
collect_runs(runs, tables_dir)
evals = load_table("evals.csv.gz", tables_dir)

fig, axes = plt.subplots(1, 2, figsize=(10, 3.4))
for ax, metric, label in ((axes[0], "eval_return", "return of the mean policy"),
                          (axes[1], "eval_success", "success rate (final error < 5 cm)")):
    rows = evals[evals.metric == metric]
    curve = iqm_curve(rows, x="step", y="value", run="run", reps=budget.bootstrap_reps)
    learning_curve(ax, curve, x="step", label=f"erl-pg, {len(runs)} seeds", color=method_color("ours"))
    ax.set(xlabel="iteration", ylabel=label)
axes[0].legend()
fig.suptitle(f"Episode-based policy gradient on PointReach ({budget.name} budget): IQM ± 95 % CI")
fig.tight_layout()
save_figure(fig, f"ch2-erl-pg-{budget.name}")
plt.show()

final = evals[(evals.metric == "eval_return")].groupby("run").value.last()
first = evals[(evals.metric == "eval_return")].groupby("run").value.first()
assert (final > first).all(), "every seed should improve on its initial return"

# %% [markdown]
# ## 2. Maximum-entropy RL
#
# Adding the policy's entropy to the reward (Eq. 2.39),
# $J(\pi)=\mathbb E\big[\sum_t\gamma^t\big(r(s_t,a_t)+\alpha\mathcal H(\pi(\cdot\mid s_t))\big)\big]$,
# changes the Bellman backup into a *soft* one: the value of a state is a log-sum-exp of
# the soft Q-values (Eq. 2.41), $V_{\rm soft}(s)=\alpha\log\sum_a\exp(Q_{\rm soft}(s,a)/\alpha)$,
# and the optimal policy is the Boltzmann distribution of $Q_{\rm soft}$ (Eq. 2.42),
# $\pi^*(a\mid s)=\exp\big((Q_{\rm soft}(s,a)-V_{\rm soft}(s))/\alpha\big)$.
#
# On a random tabular MDP we run soft value iteration and check three things: evaluating
# the Boltzmann policy gives back $V_{\rm soft}$; no random policy and no single-state
# perturbation of it scores higher on Eq. 2.39; and as $\alpha\to0$ the soft value
# approaches the ordinary optimal value within $\alpha\log|A|/(1-\gamma)$.

# %%
soft = show(F.check_soft_optimal_policy(seed=0))
d = soft.data
fig, axes = plt.subplots(1, 2, figsize=(10, 3.2))
axes[0].hist(d["j_random"], bins=30, color="#bbbbbb", label="random policies")
axes[0].axvline(float(d["j_policy"]), color=method_color("ours"), lw=2, label="Boltzmann π* (Eq. 2.42)")
gap = float(d["j_policy"]) - np.max(d["j_perturbed"])
axes[0].set(xlabel="max-ent objective (Eq. 2.39)", ylabel="count",
            title=f"{len(d['j_perturbed'])} single-state perturbations: all lower by ≥ {gap:.1e}")
axes[0].legend(fontsize=8)
axes[1].loglog(d["alphas"], d["v_gap"], "o-", label="max_s V_soft − V*")
axes[1].loglog(d["alphas"], d["v_gap_bound"], "--", label="α log|A| / (1−γ)")
axes[1].set(xlabel="α", ylabel="gap")
axes[1].legend(fontsize=8)
fig.tight_layout()
plt.show()

# %% [markdown]
# ## 3. Self-paced curricula
#
# Eq. 2.44 lets the learner choose its own context distribution $\pi(c)$ but charges it
# $\beta\,\mathrm{KL}(\pi\,\|\,p)$ for straying from the environment's $p(c)$:
# $\max_\pi \mathbb E_{\pi(c)}[R(c)]-\beta\,\mathrm{KL}(\pi\|p)$. Setting the derivative of the
# Lagrangian to zero gives $\pi^*(c)\propto p(c)\exp(R(c)/\beta)$: small $\beta$
# concentrates on easy, high-return contexts; large $\beta$ returns to $p(c)$. The check
# confirms the closed form beats random perturbations for every $\beta$ and that the KL
# to $p$ shrinks as $\beta$ grows.

# %%
sp = show(F.check_self_paced(seed=0))
d = sp.data
fig, axes = plt.subplots(1, 2, figsize=(10, 3.2))
for beta, pi in zip(d["betas"], d["pi"], strict=True):
    axes[0].plot(d["contexts"], pi / np.diff(d["contexts"]).mean(), label=f"β={beta:g}")
axes[0].plot(d["contexts"], d["p"] / np.diff(d["contexts"]).mean(), "k--", label="p(c)")
axes[0].set(xlabel="context c (larger = harder)", ylabel="density π*(c)")
axes[0].legend(fontsize=7, ncol=2)
axes[1].loglog(d["betas"], d["kl"], "o-")
axes[1].set(xlabel="β", ylabel="KL(π* ‖ p)")
fig.tight_layout()
plt.show()

# %% [markdown]
# ## 4. Movement primitives
#
# ERL needs a compact trajectory generator. **ProMPs** (Eq. 2.46) are linear in their
# weights, $\tau=\Phi^\top\theta$, so a Gaussian over $\theta$ is a Gaussian over
# trajectories and can be conditioned on a via-point in closed form. **DMPs** (Eq. 2.45)
# integrate a spring–damper pulled towards a goal $g$ plus a phase-gated forcing term, so
# they start anywhere and always converge to $g$, but need numerical integration per
# sample. **ProDMPs** solve the same ODE once, offline: the position is again linear in
# (weights, goal) plus two homogeneous solutions whose coefficients are fixed by the
# initial position and velocity — so the boundary conditions hold *exactly*.

# %%
from vslbook.figures import draw_movement_primitives
from vslbook.movement import DMP, ProDMP, ProMP

fig = draw_movement_primitives(seed=0)
save_figure(fig, "ch2-movement-primitives")
plt.show()

# %%
import torch

gen = torch.Generator().manual_seed(0)
prodmp = ProDMP(n_basis=8, n_dof=2, duration=1.0, dt=0.01)
params = 50 * torch.randn(16, prodmp.n_params, generator=gen, dtype=torch.float64)
y0 = torch.randn(16, 2, generator=gen, dtype=torch.float64)
dy0 = torch.randn(16, 2, generator=gen, dtype=torch.float64)
pos, vel = prodmp.trajectory(params, y0, dy0)
err_pos = (pos[:, 0] - y0).abs().max().item()
err_vel = (vel[:, 0] - dy0).abs().max().item()
print(f"ProDMP boundary conditions over 16 random draws: |y(0)-y0| ≤ {err_pos:.1e}, |ẏ(0)-ẏ0| ≤ {err_vel:.1e}")
assert err_pos < 1e-10 and err_vel < 1e-10

promp = ProMP(n_basis=8, n_dof=1, duration=1.0, dt=0.01)
mean_w, cov_w = promp.condition(torch.zeros(8, dtype=torch.float64), torch.eye(8, dtype=torch.float64),
                                0.6, torch.tensor([1.0]), 1e-4)
idx = int(round(0.6 / 0.01))
print(f"ProMP conditioned on y(0.6)=1: mean {promp.trajectory(mean_w)[idx, 0].item():.6f}, "
      f"std {promp.marginal_std(cov_w)[idx, 0].item():.2e}")
assert abs(promp.trajectory(mean_w)[idx, 0].item() - 1.0) < 1e-4

dmp = DMP(n_basis=8, n_dof=1, duration=3.0, dt=0.01)
end, _ = dmp.rollout(100 * torch.randn(8, 8, generator=gen, dtype=torch.float64),
                     torch.zeros(1), torch.zeros(1), torch.ones(1))
print(f"DMP end positions after 3 s (goal 1.0): max error {(end[:, -1, 0] - 1).abs().max().item():.1e}")
assert (end[:, -1, 0] - 1).abs().max() < 1e-2

# %% [markdown]
# ## 5. Mixtures of experts
#
# A mixture of experts (Eq. 2.48) $\pi(\theta\mid c)=\sum_o\pi(o\mid c)\,\pi(\theta\mid c,o)$
# needs a gating $\pi(o\mid c)$. Chapters 3 and 4 never learn the gating directly: each
# expert owns a context distribution $\pi(c\mid o)$ and the gating follows from Bayes'
# rule, $\pi(o\mid c)\propto\pi(c\mid o)\pi(o)$. The check compares that with the direct
# ratio $p(o,c)/\sum_{o'}p(o',c)$ and integrates the densities numerically.

# %%
moe = show(F.check_moe_gating(seed=0))
d = moe.data
fig, axes = plt.subplots(1, 2, figsize=(10, 3.2))
axes[0].stackplot(d["contexts"][:, 0] if d["contexts"].ndim > 1 else d["contexts"], d["gating"].T,
                  labels=[f"expert {o}" for o in range(d["gating"].shape[1])], alpha=0.8)
axes[0].set(xlabel="context c", ylabel="π(o | c)", title="Bayes-rule gating")
axes[0].legend(fontsize=8, loc="upper right")
axes[1].imshow(d["density"], origin="lower", aspect="auto", cmap="viridis")
axes[1].set(xlabel="context index", ylabel="θ index", title="π(θ | c) of the mixture")
fig.tight_layout()
plt.show()

# %% [markdown]
# ## 6. Diffusion models: the forward process
#
# The noising process of a denoising diffusion model is the Ornstein–Uhlenbeck SDE
# (Eq. 2.51) $dx_t=-\beta x_t\,dt+\eta\sqrt{2\beta}\,dB_t$. It is linear, so Gaussian
# initial conditions stay Gaussian: mean $m_0e^{-\beta t}$ and variance
# $v_0e^{-2\beta t}+\eta^2(1-e^{-2\beta t})$ — the data are forgotten and the marginal
# tends to $\mathcal N(0,\eta^2)$, the prior the generative (reverse) process starts from.
# We simulate it with Euler–Maruyama (the discretisation behind Eq. 2.53–2.54).

# %%
ou = show(F.check_ou_marginals(seed=0))
d = ou.data
every = max(1, len(d["times"]) // 15)
fig, axes = plt.subplots(1, 2, figsize=(10, 3.2))
axes[0].plot(np.linspace(0, float(d["times"][-1]), d["paths"].shape[0]), d["paths"], lw=0.5, color="#999999")
axes[0].set(xlabel="t", ylabel="x_t", title="Euler–Maruyama sample paths")
axes[1].plot(d["times"], d["exact_mean"], "-", color="k", label="exact mean")
axes[1].plot(d["times"][::every], d["sample_mean"][::every], "o", color=method_color("ours"), label="sampled mean")
axes[1].plot(d["times"], d["exact_var"], "--", color="k", label="exact variance")
axes[1].plot(d["times"][::every], d["sample_var"][::every], "s", color=method_color("DIME"), label="sampled variance")
axes[1].set(xlabel="t", title="marginal moments")
axes[1].legend(fontsize=8)
fig.tight_layout()
plt.show()

# %% [markdown]
# ## 7. Variational inference
#
# **Chain rule (Eq. 2.60).** For a latent-variable model the marginal KL is the joint KL
# minus the expected KL of the posteriors:
# $\mathrm{KL}(p(x)\|q(x))=\mathrm{KL}(p(x,z)\|q(x,z))-\mathbb E_{p(x)}[\mathrm{KL}(p(z\mid x)\|q(z\mid x))]$.
# Hence the joint KL is an *upper bound* on the marginal one, tight when the posteriors agree.
# All terms are closed form for joint Gaussians.

# %%
show(F.check_kl_chain_rule(seed=0))

# %% [markdown]
# **Mixture E-step (Eq. 2.64).** For a mixture, the joint-KL bound holds for any
# variational $q(o\mid x)$ and is tight exactly at the responsibilities
# $p(o\mid x)\propto p(x\mid o)p(o)$ — so the E-step is closed form.

# %%
est = show(F.check_mixture_estep_bound(seed=0))
d = est.data
fig, ax = plt.subplots(figsize=(5, 3))
ax.hist(d["bounds"], bins=20, color="#bbbbbb", label="bound, random q(o|x)")
ax.axvline(float(np.atleast_1d(d["kl"])[0]), color=method_color("ours"), lw=2, label="KL(p(x) ‖ q(x))")
ax.set(xlabel="upper bound on the KL")
ax.legend(fontsize=8)
plt.show()

# %% [markdown]
# **Diffusion KL (Eq. 2.65–2.66).** For a diffusion model the latents are the whole chain
# $x^{1:N}$ and the variational posterior is the fixed noising process started at the
# target. On a linear-Gaussian chain every joint is Gaussian, so the joint KL is closed
# form; we compare it with the Monte-Carlo estimate of the expectation in Eq. 2.66 and
# with the marginal KL it upper-bounds.

# %%
dk = show(F.check_diffusion_kl(seed=0, n_samples=budget.pick(smoke=20_000, reduced=100_000, full=400_000)))
d = dk.data
print(f"joint KL {float(d['joint_kl']):.4f} ≥ marginal KL {float(d['marginal_kl']):.4f}; "
      f"MC estimate {float(d['mc_estimate']):.4f} ± {float(d['mc_stderr']):.4f}")

# %% [markdown]
# **Max-ent RL as inference (Eq. 2.67–2.71).** Minimising
# $\mathbb E_s\,\mathrm{KL}(\pi(\cdot\mid s)\,\|\,\exp(Q/\alpha)/Z(s))$ over policies gives
# $\exp(Q/\alpha)/Z$, which with $V=\alpha\log Z$ is exactly the Boltzmann policy of
# Section 2; the KL equals $-(\mathbb E_\pi[Q]/\alpha+\mathcal H(\pi))+\log Z$, i.e. the
# (negated, scaled) max-ent objective plus a constant.

# %%
show(F.check_maxent_as_inference(seed=0))

# %% [markdown]
# ## 8. Mutual-information skill discovery
#
# The three forms of the mutual information (Eq. 2.72–2.74) agree, and replacing the
# intractable posterior by any $q_\phi(z\mid s)$ gives the variational lower bound
# $I(z;s)\ge\mathcal H(z)+\mathbb E_{p(z,s)}[\log q_\phi(z\mid s)]$ used by skill-discovery
# methods, tight at $q_\phi=p(z\mid s)$.

# %%
mi = show(F.check_mutual_information(seed=0))
d = mi.data
fig, ax = plt.subplots(figsize=(5, 3))
ax.hist(d["bounds"], bins=20, color="#bbbbbb", label="bound, random q(z|s)")
ax.axvline(float(d["mi"]), color=method_color("ours"), lw=2, label="I(z; s)")
ax.set(xlabel="nats")
ax.legend(fontsize=8)
plt.show()

# %% [markdown]
# ## Summary
#
# Every check above is also run by the test suite; together they take about a second.

# %%
reports = F.foundations_checks(seed=1)
for rep in reports:
    rep.require()
print(f"{sum(len(r) for r in reports)} checks in {len(reports)} groups pass for a second seed")
