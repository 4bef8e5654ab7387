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
# # Chapter 5 — DIME: diffusion-based maximum-entropy RL
#
# A diffusion policy can represent multimodal action distributions, but its marginal
# density $\pi(a\mid s)$ — and hence its entropy — is intractable, which seems to rule out
# the maximum-entropy objective (Eq. 2.39). DIME's way out: treat the denoising chain
# $x^N\to\dots\to x^0=a$ as a latent-variable model and bound the entropy from below by
# comparing it with a *noising* chain, exactly as Section 2.7.3 bounds a marginal KL by a
# joint one. Everything the actor and the critic need is then a sum of Gaussian
# log-densities along the sampled chain.
#
# 1. The entropy lower bound ℓ (Eq. 5.15) and its gap (Eq. 5.18–5.20), checked in closed form
# 2. Soft policy iteration with the bound (Eq. 5.21, Props. 5.4.1–5.4.3)
# 3. Fig. 5.1 — what α does to the denoising chain (live)
# 4. Figs. 5.2a–b / 5.3 — all 13 published panels; our cheetah-run next to its published curve
# 5. Ablations (Figs. 5.2c, 5.4, 5.6, 5.8, C.2) and the point-mass study (Fig. 5.7) at the active budget
# 6. Speed (the benchmark script)

# %%
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np
import pandas as pd
import torch
from IPython.display import display

import vslbook
from vslbook.bounds import dime as D
from vslbook.budget import get_budget
from vslbook.experiments.dime_runs import load_agent, run_variants
from vslbook.plots import learning_curve, method_color, save_figure, thesis_vs_ours, use_style
from vslbook.results import paper_curves
from vslbook.srl.dime_config import DIMEConfig, describe_differences, named_config
from vslbook.stats import iqm_curve

budget = get_budget()
use_style()
ROOT = Path(vslbook.__file__).resolve().parents[1]
RUNS = ROOT / "runs"
TABLES = ROOT / "data" / "results"
print(f"budget: {budget.name} ({budget.seeds} seeds per configuration)")


def show(report):
    """Display a CheckReport and stop the notebook if any of its checks failed."""
    display(report)
    return report.require()


# %% [markdown]
# **Which network the live runs use.** The budget only scales counts (steps, seeds). The
# thesis's networks (Table C.2: a 2048-wide critic, 16 diffusion steps) make about three
# critic updates per second on a 2-core CPU, so the live runs below use *named*
# configurations, chosen here in plain sight: `cpu-256` for the DeepMind Control run and
# `cpu-64` for the small tasks. Every figure made from our runs prints, generated from the
# run's config, how it differs from the thesis's table. Set `VSLBOOK_DIME_CONFIG=thesis` (a
# GPU or a cluster) to run everything at the thesis's sizes.

# %%
import os

LIVE = {"dmc": os.environ.get("VSLBOOK_DIME_CONFIG", "cpu-256"),
        "small": os.environ.get("VSLBOOK_DIME_CONFIG", "cpu-64")}
for use, name in LIVE.items():
    print(f"{use:6s} {name:8s} {describe_differences(named_config(name), DIMEConfig)}")

# %% [markdown]
# ## 1. The entropy lower bound
#
# The policy samples $x^N\sim p_N=\mathcal N(0,\sigma_0^2I)$ and runs $N$ Euler–Maruyama steps
# of a learned denoising SDE, $x^{n-1}=x^n+\eta_n(\nabla\log p_N(x^n)+f_\theta(x^n,n,s))+\sqrt{2\eta_n}\,\varepsilon$.
# Call this joint $\pi(x^{0:N})$. A *noising* chain $\vec\pi$ runs the other way with the fixed
# OU kernels $x^n\sim\mathcal N(x^{n-1}+\eta_n\nabla\log p_N(x^{n-1}),2\eta_n)$, started at
# the policy's own marginal $\pi_0$. By the chain rule of the KL (Eq. 2.60 with $z=x^{1:N}$),
#
# $$\mathcal H(\pi_0)=\underbrace{\mathbb E_\pi\Big[\textstyle\sum_n\log\vec\pi_{n|n-1}(x^n\mid x^{n-1})-\log p_N(x^N)-\sum_n\log\pi_{n-1|n}(x^{n-1}\mid x^n)\Big]}_{\ell\ \text{(Eq. 5.15)}}+\mathrm{KL}\big(\pi(x^{0:N})\,\|\,\vec\pi(x^{0:N})\big),$$
#
# so $\ell\le\mathcal H$ with the gap the KL between the two chains (Eq. 5.18–5.20), and $\ell$
# needs only the Gaussian kernels along one sampled chain. When $f_\theta$ is linear the
# chain is linear-Gaussian: $\mathcal H$, $\ell$ and the gap are all closed form. The check
# runs the library's `DiffusionPolicy` with such a score network and compares the Monte-Carlo
# estimate of its `entropy_bound` with the closed forms.

# %%
vslbook.show_source(vslbook.srl.diffusion_policy.DiffusionPolicy.sample)

# %%
lb = show(D.check_entropy_lower_bound(seed=0))
d = lb.data
fig, axes = plt.subplots(1, 2, figsize=(10, 3.2))
axes[0].hist(d["bound_samples"], bins=60, color="#bbbbbb", label="single-chain estimates")
axes[0].axvline(float(d["bound"]), color=method_color("ours"), lw=2, label="ℓ (closed form)")
axes[0].axvline(float(d["entropy"]), color="k", ls="--", lw=2, label="H(π₀) (closed form)")
axes[0].set(xlabel="nats", title=f"ℓ ≤ H, gap {float(d['gap']):.3f} = KL of the chains")
axes[0].legend(fontsize=8)
axes[1].semilogy(d["series_steps"], d["series_gap"], "o-", label="affine score network")
axes[1].semilogy(d["series_steps"], d["series_gap_zero_drift"], "s--", label="f_θ ≡ 0")
axes[1].set(xlabel="diffusion steps N", ylabel="H − ℓ (nats)", title="gap vs number of steps")
axes[1].legend(fontsize=8)
fig.tight_layout()
plt.show()

# %% [markdown]
# ## 2. Soft policy iteration with the bound
#
# Replacing $\mathcal H$ by $\ell$ in the soft Bellman operator (Eq. 5.21) keeps it a
# $\gamma$-contraction (Prop. 5.4.1), so policy evaluation converges — to a Q that is below the
# exact soft Q, since $\ell\le\mathcal H$. Improving the policy by decreasing the KL to
# $\exp(Q/\alpha)/Z$ never lowers Q (Prop. 5.4.2), and alternating both converges
# (Prop. 5.4.3). On a tabular MDP with exact entropies (SAC's setting) all of this can be
# computed exactly; the second check below does it with the diffusion chain and ℓ.

# %%
contraction = show(D.check_soft_bellman_contraction(seed=0))
spi = show(D.check_soft_policy_iteration(seed=0))
d = spi.data
fig, axes = plt.subplots(1, 2, figsize=(10, 3.2))
axes[0].hist(contraction.data["ratios"], bins=40, color="#bbbbbb")
axes[0].axvline(0.9, color="k", ls="--", label="γ")
axes[0].set(xlabel="‖TQ₁ − TQ₂‖∞ / ‖Q₁ − Q₂‖∞", title="contraction (Prop. 5.4.1)")
axes[0].legend()
for key, label in (("j_exact", "exact improvement"), ("j_mirror", "partial step"),
                   ("j_restricted", "restricted family")):
    axes[1].plot(d[key], label=label)
axes[1].axhline(float(d["j_optimal"]), color="k", ls="--", label="soft optimum")
axes[1].set(xlabel="iteration", ylabel="max-ent objective", title="soft policy iteration")
axes[1].legend(fontsize=8)
fig.tight_layout()
plt.show()

# %% [markdown]
# The tabular check above uses a discrete policy and its exact entropy: it is SAC's soft
# policy iteration, and no diffusion chain and no ℓ appear in it. The next check runs the
# three propositions with the diffusion policies of Section 1 and with ℓ itself. That needs a
# problem where both sides can be computed: a one-dimensional linear-quadratic task
# ($s'=As+Ba+w$, quadratic reward) and the linear-Gaussian chains of Section 1 with the score
# $f_k(x,s)=\text{slope}\cdot x+c_k+g_k\,s$ at step $k$. Then every Q-function is quadratic,
# every chain is Gaussian, and the improvement step, which minimises the joint KL of Eq. 5.22
# between the policy's chain and the noising chain started at $\exp(Q/\alpha)/Z$, has a
# closed-form objective. The check compares the closed-form Q with repeated backups of
# Eq. 5.21 (Prop. 5.4.1), Q before and after every improvement (Prop. 5.4.2), and the end
# point of policy iteration with the best member of the family, found separately by
# maximising $\bar J$ (Eq. 5.16) with a general-purpose optimiser (Prop. 5.4.3).
#
# What it does not show: the end point is the best policy of the family *for the bound*
# $\bar J$, not for the true objective with the exact entropy. ℓ stays below H there, and
# another member of the same family scores higher on the true objective (printed below). It
# is also one small, exactly solvable setting: a one-dimensional action, a family in which
# Eq. 5.22 can be solved at every state at once, and no neural network or stochastic
# gradients as in DIME itself.

# %%
dpi = show(D.check_diffusion_policy_iteration(seed=0))
d = dpi.data
gap = float(d["entropy"]) - d["bound"]
j_limit, j_best = d["j_exact_entropy"]
print(f"end point: J̄ = {d['j_bar'][-1]:.3f} (direct maximum {float(d['j_bar_direct']):.3f}); "
      f"H − ℓ(s) = {gap.min():.2f} to {gap.max():.2f} nats for s in [−2, 2]")
print(f"true objective with H: {j_limit:.3f} at the end point, {j_best:.3f} for the family's best")
fig, axes = plt.subplots(1, 2, figsize=(10, 3.2))
axes[0].plot(d["j_bar"], "o-", color=method_color("ours"), label="policy iteration")
axes[0].axhline(float(d["j_bar_direct"]), color="k", ls="--", label="max of J̄ over the family")
axes[0].set(xlabel="iteration", ylabel="J̄ (Eq. 5.16)", title="policy iteration with ℓ (Prop. 5.4.3)")
axes[0].legend(fontsize=8)
i = int(np.argmin(np.abs(d["s_axis"])))  # the slice at s = 0
axes[1].plot(d["a_axis"], d["q_old"][i], label="Q of π₀")
axes[1].plot(d["a_axis"], d["q_new"][i], label="Q after one improvement")
axes[1].plot(d["a_axis"], d["q_iterates"][-1][i], "k--", label="Q at the end point")
axes[1].set(xlabel="action a", ylabel="Q(s = 0, a)", title="Q never decreases (Prop. 5.4.2)")
axes[1].legend(fontsize=8)
fig.tight_layout()
plt.show()

# %% [markdown]
# ## 3. Fig. 5.1 — the effect of α
#
# With a single state, DIME's actor loss (Eq. 5.27) is $\mathbb E[-Q(a)+\alpha\,(\text{running}+\text{terminal cost})]$,
# an upper bound on $\alpha\,\mathrm{KL}(\pi\,\|\,e^{Q/\alpha}/Z)$ up to a constant. We fit the
# library's diffusion policy to a double-well $Q$ for three temperatures and draw the chains
# from the prior to the action, next to the target they approximate.

# %%
from vslbook.experiments.dime_toy import fit_boltzmann

iters = budget.pick(smoke=60, reduced=400, full=1000)
fits = [fit_boltzmann(alpha, iterations=iters, seed=0) for alpha in (0.1, 1.0, 10.0)]
fig, axes = plt.subplots(1, 3, figsize=(13, 3.6), sharey=True)
for ax, fit in zip(axes, fits, strict=True):
    traj = fit.trajectories[:, :60, 0]
    ax.plot(np.arange(traj.shape[0]), traj, color=method_color("ours"), lw=0.5, alpha=0.5)
    scale = 0.35 * traj.shape[0] / fit.target.max()
    ax.plot(traj.shape[0] - 1 + scale * fit.target, fit.grid, color="k", lw=1.5)
    ax.set(title=f"α = {fit.alpha:g}   (KL bound {fit.kl_upper:.2f} nats)",
           xlabel="denoising step (prior → action) | target exp(Q/α)/Z", ylim=(-2.5, 2.5))
axes[0].set_ylabel("x")
fig.suptitle(f"Fig. 5.1, live: diffusion chains after {iters} actor updates")
fig.tight_layout()
save_figure(fig, f"fig5-1-alpha-{budget.name}")
plt.show()

# %% [markdown]
# ## 4. Figs. 5.2a–b and 5.3 — the published curves, and ours
#
# The authors published DIME's 10-seed learning curves (`data/paper/`, see its README); they
# are drawn here as IQM with 95 % stratified-bootstrap intervals, labelled as the thesis's.
# The baselines of these figures (BRO, CrossQ, QSM, DIPO, DACER, …) have no public curves
# and are therefore *named, not drawn*. The thesis ran gymnasium's Ant-v3 / Humanoid-v3;
# those need the retired mujoco-py, so our own runs would use **v5**: same models and
# reward terms, observations of 105 / 348 dimensions (v3: 111 / 376, always-zero contact
# entries dropped), and no healthy reward on the final unhealthy step.

# %%
from vslbook.figures import draw_fig_5_2_published, draw_fig_5_3_published

fig = draw_fig_5_2_published(budget=budget)
save_figure(fig, f"fig5-2ab-published-{budget.name}")
plt.show()
fig = draw_fig_5_3_published(budget=budget)
save_figure(fig, f"fig5-3-published-{budget.name}")
plt.show()

# %% [markdown]
# **Our runs next to a published curve: DeepMind Control cheetah-run.** Cheetah-run is *not* a
# panel of Figs. 5.2/5.3; the authors published its curve with the others (`data/paper/`),
# and it is the cheapest of their DMC tasks (17-dim observations, 6-dim actions), so it is
# where our implementation can be held against theirs on a CPU. Everything is Table C.2
# (5000 exploration steps included) except the named network printed under the figure; the
# run length is the thesis's 1M steps scaled by the budget (50k at `reduced`), with
# `budget.seeds` seeds.

# %%
ENV = "dm_control/cheetah-run-v0"
cheetah = run_variants(
    ENV,
    {"DIME": ("dime", {})},
    # total_steps is the thesis's count (1M), scaled by the budget; evaluation every 24k
    # steps at `full` (as published), every 6k at `reduced`, once at the end at `smoke`.
    common={**named_config(LIVE["dmc"]), "total_steps": 1_000_000,
            "eval_every": budget.pick(smoke=1_000_000, reduced=120_000, full=24_000)},
    seeds=budget.seeds, budget=budget, root=RUNS, tables=TABLES / f"ch5-cheetah-{budget.name}")
ours_curve = iqm_curve(cheetah.curve_rows().rename(columns={"step": "env_steps"}),
                       x="env_steps", y="value", run="run", reps=budget.bootstrap_reps)
published = iqm_curve(paper_curves("dmc_cheetah_run"), reps=budget.bootstrap_reps)
horizon = max(ours_curve.env_steps.max(), 24_000)
fig, axes = plt.subplots(1, 2, figsize=(11, 3.9))
n_ours = cheetah.seeds("DIME")
thesis_vs_ours(axes[0], published, ours_curve, budget=budget.name,
               title="cheetah-run: published (10 seeds, 1M steps) vs ours")
thesis_vs_ours(axes[1], published[published.env_steps <= 1.05 * horizon], ours_curve,
               budget=budget.name, title=f"zoom on our {budget.name} budget ({n_ours} seeds)")
fig.text(0.01, 0.005, "ours: " + cheetah.captions(), fontsize=7, va="bottom")
fig.tight_layout(rect=(0, 0.06, 1, 1))
save_figure(fig, f"ch5-cheetah-run-ours-vs-published-{budget.name}")
plt.show()
# Side by side at the published evaluation steps our runs reached (24k and 48k at `reduced`).
first, last = ours_curve.env_steps.min(), ours_curve.env_steps.max()
side = pd.merge(
    published[published.env_steps.between(first, last)],
    ours_curve[["env_steps", "iqm", "lo", "hi", "n_runs"]], on="env_steps",
    suffixes=(" (thesis)", " (ours)"))
print(cheetah.captions())
display(side.round(1))

# %% [markdown]
# ## 5. Ablations at the active budget
#
# Each switch of the chapter is a config field of `vslbook.srl.dime`. The thesis ran its
# ablations on dog and humanoid tasks at 1M steps and 10 seeds; here every one runs on
# gymnasium's `Pendulum-v1` (200-step episodes), a task cheap enough for every budget, with
# the `cpu-64` network and `budget.seeds` seeds. Each panel says which thesis panel it stands
# for and what differs:
#
# | panel | thesis (task, seeds) | change here |
# |---|---|---|
# | diffusion steps | Fig. 5.2c–d (humanoid-run, 10) | `n_diffusion_steps=2` vs the config's 4 |
# | fixed α | Fig. 5.4a–b (dog-run, 10) | `fixed_alpha=0.1` vs autotuned α |
# | Gaussian policy | Fig. 5.4c–d (humanoid-run, dog-run, 10) | `dime-gaussian` |
# | no distributional Q | Figs. 5.5c–d / 5.6 (Ant, Humanoid, dogs, 10) | `critic="scalar"` (Eq. 5.24) |
# | general bridges | Fig. 5.8a–b (humanoid-run, 10) | `general_bridges=True` |
# | fixed β | Fig. C.2 (dog-run, 10; the thesis plots the learned β) | `learn_beta=False` |
# | CrossQ | the baseline of Figs. 5.2–5.3 | `crossq` (Table C.3) |
#
# The runs keep Table C.2's 5000 uniform exploration steps, so learning starts at step 5000;
# how long they run after that is the budget's choice (50 steps at `smoke`, 3000 at
# `reduced`). With three seeds of a small network these panels show that every switch trains
# and which way it points on this task, not the thesis's rankings.

# %%
variants = {
    "DIME": ("dime", {}),
    "2 steps": ("dime", {"n_diffusion_steps": 2}),
    "fixed α = 0.1": ("dime", {"fixed_alpha": 0.1}),
    "Gaussian": ("dime-gaussian", {}),
    "no distr. Q": ("dime", {"critic": "scalar"}),
    "GB": ("dime", {"general_bridges": True}),
    "fixed β": ("dime", {"learn_beta": False}),
    "CrossQ": ("crossq", {}),
}
steps = budget.pick(smoke=5_050, reduced=8_000, full=100_000)  # env steps at this budget
common = {**named_config(LIVE["small"]), "total_steps": budget.full_count(steps),
          "eval_every": budget.full_count(budget.pick(smoke=5_050, reduced=1_000, full=5_000)),
          "v_min": -1600.0, "v_max": 100.0}
abl = run_variants("Pendulum-v1", variants, seeds=budget.seeds, budget=budget, root=RUNS,
                   tables=TABLES / f"ch5-ablations-{budget.name}", common=common)
rows_all = abl.curve_rows()
curves = {label: iqm_curve(rows_all[rows_all.variant == label], x="step", y="value", run="run",
                           reps=budget.bootstrap_reps) for label in variants}
panels = [("Fig. 5.2c–d: diffusion steps", "2 steps"), ("Fig. 5.4a–b: fixed α", "fixed α = 0.1"),
          ("Fig. 5.4c–d: Gaussian policy", "Gaussian"), ("Figs. 5.5/5.6: distr. Q", "no distr. Q"),
          ("Fig. 5.8a–b: general bridges", "GB"), ("Fig. C.2: learned β", "fixed β"),
          ("Figs. 5.2–5.3: CrossQ", "CrossQ")]
fig, axes = plt.subplots(2, 4, figsize=(15, 6.4))
for ax in axes.flat[1:-1]:
    ax.sharey(axes.flat[0])  # the seven return panels share one scale; β has its own
for ax, (title, label) in zip(axes.flat, panels, strict=False):
    for name in ("DIME", label):
        learning_curve(ax, curves[name], x="step", label=f"{name} ({abl.seeds(name)} seeds)",
                       color=method_color(name))
    ax.axvline(5000, color="0.6", lw=0.8, ls=":")
    ax.set(title=f"stands for {title}", xlabel="env steps")
    ax.legend(fontsize=7, loc="lower right")
for ax in axes.flat[:-1]:
    ax.set_ylabel("eval return (Pendulum-v1)")
# Fig. C.2 proper: the learned β_k (the scale of the diffusion coefficient) over training
beta = abl.evals[(abl.evals.variant == "DIME") & (abl.evals.metric == "beta_0")]
learning_curve(axes.flat[-1], iqm_curve(beta, x="step", y="value", run="run",
                                        reps=budget.bootstrap_reps),
               x="step", label="DIME: learned β₀", color=method_color("DIME"))
axes.flat[-1].set(title="Fig. C.2: learned β₀ over training", ylabel="β₀", xlabel="env steps")
axes.flat[-1].legend(fontsize=7)
fig.suptitle(f"Ablations on Pendulum-v1 instead of the thesis's tasks ({budget.name} budget, "
             f"IQM ± 95 % CI over seeds; dotted: end of the 5000 exploration steps)")
fig.text(0.01, 0.005, abl.captions(), fontsize=6.5, va="bottom")
fig.tight_layout(rect=(0, 0.14, 1, 0.97))
save_figure(fig, f"ch5-ablations-pendulum-{budget.name}")
plt.show()
final = rows_all.sort_values("step").groupby(["variant", "run"]).value.last()
print(final.groupby("variant").agg(["mean", "min", "max", "count"]).round(1).to_string())

# %% [markdown]
# ## 5b. Fig. 5.7 — multimodality on the four-goal point mass
#
# The point starts at the origin; any of four goals ends the episode with a bonus. With a
# target network (as in the thesis's study) and a fixed α, we roll the trained policy out
# 50 times and count which goals it reaches; the value map is the thesis's sample estimate
# $V(s)\approx\frac1{15}\sum_{i}Q(s,a_i)$, $a_i\sim\pi(\cdot\mid s)$, on a 50×50 grid.

# %%
from vslbook.envs.point_mass import GOALS

alphas = (0.01, 1.0, 5.0)  # the thesis's panels run from small α up to 4 and 5
pm_steps = budget.pick(smoke=5_050, reduced=10_000, full=100_000)
pm_variants = {f"α = {a:g}": ("dime", {"fixed_alpha": a}) for a in alphas}
# One seed per α: the figure shows one agent's value map and rollouts, as the thesis's does.
pm = run_variants("vslbook/PointMassFourGoals-v0", pm_variants, seeds=1, budget=budget,
                  root=RUNS, tables=TABLES / f"ch5-pointmass-{budget.name}",
                  common={**named_config(LIVE["small"]), "use_target_network": True,
                          "total_steps": budget.full_count(pm_steps),
                          "eval_every": budget.full_count(pm_steps)})
fig, axes = plt.subplots(1, len(alphas), figsize=(5 * len(alphas), 4.2))
grid = np.stack(np.meshgrid(np.linspace(-1, 1, 50), np.linspace(-1, 1, 50)), -1).reshape(-1, 2)
summary = {}
for ax, label in zip(axes, pm_variants, strict=True):
    agent, env = load_agent(pm.runs[label][0])
    torch.manual_seed(0)  # the policy's noise: the same rollouts every time
    with torch.no_grad():
        obs = torch.as_tensor(np.repeat(grid, 15, 0), dtype=torch.float32)
        acts = agent.policy.sample(obs).action
        q = agent.support.mean(torch.softmax(agent.critic(obs, acts), -1)).mean(0)
        value = q.reshape(-1, 15).mean(1).reshape(50, 50).numpy()
    ax.imshow(value, origin="lower", extent=(-1, 1, -1, 1), cmap="viridis")
    reached = []
    for episode in range(50):
        o, _ = env.reset(seed=episode)
        path, done, info = [o], False, {}
        while not done:
            with torch.no_grad():
                a = agent.policy.sample(torch.as_tensor(o[None], dtype=torch.float32)).action[0].numpy()
            o, _, term, trunc, info = env.step(a)
            path.append(o)
            done = term or trunc
        reached.append(info.get("goal", -1))
        ax.plot(*np.array(path).T, color="w", lw=0.6, alpha=0.6)
    ax.plot(*GOALS.T, "o", color="red", ms=8)
    counts = np.bincount(np.array(reached) + 1, minlength=len(GOALS) + 1)
    summary[label] = {"no goal": counts[0], **{f"goal {g}": counts[g + 1] for g in range(len(GOALS))}}
    modes = [g for g in range(len(GOALS)) if counts[g + 1]]
    ax.set(title=f"{label}: goals reached {modes}", xlim=(-1, 1), ylim=(-1, 1))
fig.suptitle(f"Fig. 5.7, live ({budget.name} budget, {pm_steps} env steps, 1 seed per α): "
             "value estimate and 50 rollouts")
fig.text(0.01, 0.005, pm.captions(), fontsize=7, va="bottom")
fig.tight_layout(rect=(0, 0.1, 1, 1))
save_figure(fig, f"fig5-7-pointmass-{budget.name}")
plt.show()
display(pd.DataFrame(summary).T.rename_axis("rollouts ending at"))

# %% [markdown]
# ## 6. Speed
#
# `benchmarks/dime_throughput.py` times the real update functions at humanoid-run sizes
# (obs 67, act 21, batch 256) and prints critic / actor updates per second next to the
# official JAX implementation's on the same kind of 2-core CPU. Our numbers are in the
# README's performance section; run it yourself with
#
# ```bash
# .venv/bin/python benchmarks/dime_throughput.py --seconds 60
# ```
