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
# Chapter 2 introduces. This notebook derives each result of the chapter step by step and
# *checks* it numerically: every check computes the two sides of an equation of the thesis
# independently and stops the notebook if they disagree. The checks that live in
# `vslbook.bounds.foundations` also run in the test suite (`tests/test_bounds_foundations.py`);
# the short cells written out here check the individual derivation steps.
#
# Contents
# 1. Episode-based vs step-based RL — the objective, its likelihood-ratio gradient and a live ERL run (Eq. 2.26–2.38)
# 2. Maximum-entropy RL — the soft Bellman equation and the Boltzmann policy (Eq. 2.39–2.43)
# 3. Self-paced curricula (Eq. 2.44)
# 4. Movement primitives — ProMP, DMP, ProDMP (Eq. 2.45–2.46)
# 5. Mixtures of experts (Eq. 2.47–2.49)
# 6. Diffusion models — the Ornstein–Uhlenbeck forward process (Eq. 2.50–2.55)
# 7. Variational inference — the ELBO, the KL chain rule, the mixture E-step, the diffusion KL, max-ent RL as inference (Eq. 2.56–2.71)
# 8. Mutual-information skill discovery (Eq. 2.72–2.74)

# %%
import math
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np
import torch
from scipy.special import logsumexp, xlogy
from scipy.stats import multivariate_normal, norm

import vslbook
from vslbook.bounds import foundations as F
from vslbook.bounds import show
from vslbook.budget import get_budget
from vslbook.dists import LinearGaussianMoE, condition_gaussian, gaussian_kl, gaussian_log_prob
from vslbook.plots import (
    PALETTE,
    count_phrase,
    learning_curve,
    method_color,
    save_figure,
    use_style,
)

budget = get_budget()
use_style()
ROOT = Path(vslbook.__file__).resolve().parents[1]
print(f"budget: {budget.name}  (set VSLBOOK_BUDGET=smoke|reduced|full)")


# %% [markdown]
# ## 1. Episode-based vs step-based RL
#
# Step-based RL (SRL) perturbs the action at every time step and learns from the tuples
# $(s_t, a_t, r_t, s_{t+1})$. Episode-based RL (ERL) perturbs the *parameters* $\theta$
# of a deterministic low-level controller — here a movement primitive — once per episode
# and treats the episode as a black box that returns one number for the pair $(\theta, c)$.
#
# **The objective (Eqs. 2.26–2.27).** Running the controller with parameters $\theta$ in
# context $c$ produces a trajectory $\tau\sim p_\theta(\tau\mid c)$ that is scored by a return
# $G(\tau, c)$. The learner draws $c$ from the environment's $p(c)$ and $\theta$ from its
# search distribution $\pi_\omega(\theta\mid c)$, so its expected return is
#
# (eq-2-26)=
# $$
# J(\pi_\omega) = \mathbb{E}_{p(c)}\Big[\int \pi_\omega(\theta\mid c) \int p_\theta(\tau\mid c)\, G(\tau, c)\, d\tau\, d\theta\Big]. \tag{2.26}
# $$
#
# ERL never looks inside the episode, so the inner integral can be collapsed into the
# expected return of one parameter vector, $R(\theta, c) = \int p_\theta(\tau\mid c)\, G(\tau, c)\, d\tau$:
#
# (eq-2-27)=
# $$
# J(\pi_\omega) = \mathbb{E}_{p(c)}\Big[\int \pi_\omega(\theta\mid c)\, R(\theta, c)\, d\theta\Big]. \tag{2.27}
# $$
#
# Nothing here asks $G$ to be a discounted sum of per-step rewards: the return may be
# non-Markovian (the final distance to a goal, the maximum height of a jump).
#
# **The gradient (Eqs. 2.29–2.31).** Neither $p(c)$ nor $R$ depends on $\omega$, so the
# gradient of Eq. 2.27 only acts on the search distribution:
#
# (eq-2-29)=
# $$
# \nabla_\omega J(\pi_\omega) = \int p(c) \int \nabla_\omega \pi_\omega(\theta\mid c)\, R(\theta, c)\, d\theta\, dc. \tag{2.29}
# $$
#
# The gradient of a density is not itself a density, so Eq. 2.29 cannot be estimated by
# sampling as it stands. The chain rule for the logarithm, $\nabla_\omega\log\pi_\omega =
# \nabla_\omega\pi_\omega/\pi_\omega$, rewrites $\nabla_\omega\pi_\omega = \pi_\omega\nabla_\omega\log\pi_\omega$
# (the *likelihood-ratio* or *score-function* trick) and turns the integral back into an
# expectation under the policy:
#
# (eq-2-30)=
# $$
# \nabla_\omega J(\pi_\omega) = \int p(c) \int \pi_\omega(\theta\mid c)\, \nabla_\omega \log\pi_\omega(\theta\mid c)\, R(\theta, c)\, d\theta\, dc. \tag{2.30}
# $$
#
# Drawing $c^i\sim p(c)$ and $\theta^i\sim\pi_\omega(\cdot\mid c^i)$ and running one episode
# per pair gives the Monte-Carlo estimate
#
# (eq-2-31)=
# $$
# \nabla_\omega J(\pi_\omega) \approx \frac1N\sum_{i=1}^N \nabla_\omega \log\pi_\omega(\theta^i\mid c^i)\, R(\theta^i, c^i). \tag{2.31}
# $$
#
# The thesis writes the plain sum; the factor $1/N$ only rescales the step size. Only
# $\log\pi_\omega$ has to be differentiable — the return stays a black box
# {cite:p}`williams1992simple`.
#
# **A baseline (Eqs. 2.32–2.33).** The score has mean zero under the policy in every
# context, because the policy integrates to one whatever $\omega$ is:
#
# $$
# \mathbb{E}_{\pi_\omega(\theta\mid c)}\big[\nabla_\omega\log\pi_\omega(\theta\mid c)\big]
# = \int \nabla_\omega\pi_\omega(\theta\mid c)\, d\theta = \nabla_\omega \int \pi_\omega(\theta\mid c)\, d\theta = \nabla_\omega 1 = 0 .
# $$
#
# Hence any $b(c)$ that does not depend on $\theta$ can be subtracted from $R$ without
# changing the expected gradient, $\mathbb{E}[\nabla_\omega\log\pi_\omega\, b(c)] =
# \mathbb{E}_{p(c)}[b(c)\cdot 0] = 0$, while it can shrink the variance of the estimate. The
# usual choice is the expected return of the context, $V^\pi(c) = \int\pi_\omega(\theta\mid c) R(\theta, c)\, d\theta$,
# which turns the weight into the advantage
#
# (eq-2-32)=
# $$
# A^\pi(\theta, c) = R(\theta, c) - V^\pi(c), \tag{2.32}
# $$
#
# and the estimate into
#
# (eq-2-33)=
# $$
# \nabla_\omega J(\pi_\omega) \approx \frac1N\sum_{i=1}^N \nabla_\omega \log\pi_\omega(\theta^i\mid c^i)\, A^\pi(\theta^i, c^i). \tag{2.33}
# $$
#
# **Check: a Gaussian search distribution on a quadratic return.** Take the policy that the
# learner below uses, $\pi_\omega(\theta\mid c) = \mathcal N(Kc + k, \operatorname{diag}\sigma^2)$ with
# $\omega = (K, k, \log\sigma)$, contexts $c\sim\mathcal N(m_c, S_c)$ and the return
# $R(\theta, c) = -(\theta - Mc)^\top A\,(\theta - Mc)$ with $A$ positive definite. With
# $e(c) = (K - M)c + k$ the error of the policy mean, $\theta - Mc = e(c) + \sigma\odot\varepsilon$ and
# $\mathbb E[\varepsilon\varepsilon^\top] = I$ give everything in closed form:
#
# $$
# \begin{aligned}
# V^\pi(c) &= -e(c)^\top A\, e(c) - \textstyle\sum_j A_{jj}\sigma_j^2, \qquad
# J = \mathbb E_{p(c)}[V^\pi(c)], \\
# \nabla_k J &= -2A\,\mathbb E[e(c)] = -2A\big((K - M)m_c + k\big), \\
# \nabla_K J &= -2A\,\mathbb E[e(c)c^\top] = -2A\big((K - M)(S_c + m_cm_c^\top) + k\,m_c^\top\big), \\
# \partial J/\partial\log\sigma_j &= -2A_{jj}\sigma_j^2 .
# \end{aligned}
# $$
#
# The cell compares these exact gradients with the estimates of Eq. 2.31 and Eq. 2.33, where
# $\nabla_\omega\log\pi_\omega$ comes from autograd through `vslbook.dists.gaussian_log_prob`.
# A hundred batches of a thousand episodes give each estimate and its standard error; every
# component must lie within 4.5 standard errors of the closed form, the score alone must
# average to zero, and the baseline must shrink the standard error.

# %%
rng = np.random.default_rng(0)
d_c, d_t = 2, 3
L_ = rng.normal(size=(d_t, d_t)) / math.sqrt(d_t)
A = L_ @ L_.T + 0.5 * np.eye(d_t)                        # curvature of the return
M = rng.normal(size=(d_t, d_c))                          # best parameters theta*(c) = M c
m_c, S_c = rng.normal(size=d_c), 0.5 * np.eye(d_c)       # p(c) = N(m_c, S_c)
K0, k0, log_std0 = rng.normal(size=(d_t, d_c)), rng.normal(size=d_t), rng.normal(scale=0.3, size=d_t)
var0 = np.exp(2 * log_std0)

# Closed-form gradient of J (the left side of Eq. 2.29), ordered (K, k, log sigma).
E_cc = S_c + np.outer(m_c, m_c)
grad_exact = np.concatenate([
    (-2 * A @ ((K0 - M) @ E_cc + np.outer(k0, m_c))).ravel(),
    -2 * A @ ((K0 - M) @ m_c + k0),
    -2 * np.diag(A) * var0,
])

# %% [markdown]
# The score-function estimates (Eqs. 2.31 and 2.33), with torch autograd for
# $\nabla_\omega\log\pi_\omega$, a hundred batches of a thousand episodes, each compared with the
# closed form in standard errors:

# %%
K, k, log_std = (torch.tensor(x, requires_grad=True) for x in (K0, k0, log_std0))
zero, eye = torch.zeros(d_t, dtype=torch.float64), torch.eye(d_t, dtype=torch.float64)
weights = {"R (Eq. 2.31)": [], "A = R - V (Eq. 2.33)": [], "score alone": []}
for _ in range(100):
    c = rng.multivariate_normal(m_c, S_c, size=1000)
    mean0 = c @ K0.T + k0
    theta = mean0 + np.sqrt(var0) * rng.standard_normal(mean0.shape)
    err, err0 = theta - c @ M.T, mean0 - c @ M.T
    R = -np.einsum("ni,ij,nj->n", err, A, err)
    V = -np.einsum("ni,ij,nj->n", err0, A, err0) - np.diag(A) @ var0
    z = (torch.from_numpy(theta) - (torch.from_numpy(c) @ K.T + k)) / log_std.exp()
    log_pi = gaussian_log_prob(z, zero, eye) - log_std.sum()   # log N(theta | Kc + k, diag sigma^2)
    for key, w in zip(weights, (R, R - V, np.ones_like(R)), strict=True):
        g = torch.autograd.grad((log_pi * torch.from_numpy(w)).mean(), (K, k, log_std), retain_graph=True)
        weights[key].append(torch.cat([x.reshape(-1) for x in g]).numpy())

se = {}
for key, g in weights.items():
    g = np.array(g)
    est, se[key] = g.mean(0), g.std(0, ddof=1) / math.sqrt(len(g))
    target = np.zeros_like(grad_exact) if key == "score alone" else grad_exact
    worst = np.max(np.abs(est - target) / se[key])
    print(f"{key:22s} estimate {np.round(est[:4], 3)} …  target {np.round(target[:4], 3)} …  "
          f"mean SE {se[key].mean():.4f}, worst |error| = {worst:.2f} SE")
    assert worst < 4.5, key
assert np.all(se["A = R - V (Eq. 2.33)"] < se["R (Eq. 2.31)"]), "the baseline should reduce the variance"

# %% [markdown]
# **A live run.** `vslbook.erl.pg` implements Eq. 2.33 for the same linear-Gaussian
# $\pi_\omega(\theta\mid c)$ on `vslbook/PointReach-v0`: a planar ProMP starting at the origin
# must end at the goal $c\in[-1,1]^2$. Its baseline $V(c)$ is a least-squares fit on
# quadratic context features, since the true $V^\pi$ is unknown there.

# %%
from vslbook.erl.pg import train

vslbook.show_source(train)

# %% [markdown]
# Train one run per seed at the active budget. Each run writes a resumable run
# directory under `runs/`; running the cell again reuses finished runs. The curves are
# read back through registered tables in `build/tables/` (sha256-checked; `data/results/`
# holds only recorded run sets, `vslbook record`) and aggregated as the
# interquartile mean with a 95 % stratified-bootstrap interval.

# %% tags=["full-width"]
from vslbook.data import collect_runs, load_table
from vslbook.stats import iqm_curve
from vslbook.training import run

runs = [
    run("erl-pg", "vslbook/PointReach-v0", seed=s, budget=budget, root=ROOT / "runs", progress=False)
    for s in range(budget.seeds)
]
tables_dir = ROOT / "build" / "tables" / f"ch2-erl-pg-{budget.name}"
collect_runs(runs, tables_dir)
evals = load_table("evals.csv.gz", tables_dir)

fig, axes = plt.subplots(1, 2, figsize=(10, 3.4))
for ax, metric, label in ((axes[0], "eval_return", "return of the mean policy"),
                          (axes[1], "eval_success", "success rate (final error < 5 cm)")):
    rows = evals[evals.metric == metric]
    curve = iqm_curve(rows, x="step", y="value", run="run", reps=budget.bootstrap_reps)
    learning_curve(ax, curve, x="step", label=f"erl-pg, {count_phrase(len(runs), 'seed')}", method="ours")
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
# **Gradient-free: a trust region solved in closed form (Eqs. 2.35–2.38).** CREPS
# {cite:p}`kupcsik2013data` maximises the same objective, Eq. 2.27, but only over policies
# whose expected KL to the previous policy stays below a bound $\epsilon$, and with every
# $\pi(\cdot\mid c)$ normalised:
#
# (eq-2-35)=
# $$
# \max_{\pi} \int p(c) \int \pi(\theta\mid c)\, R(\theta, c)\, d\theta\, dc \tag{2.35}
# $$
#
# (eq-2-36)=
# $$
# \text{s.t.}\quad \mathbb{E}_{p(c)}\big[\mathrm{KL}\big(\pi(\theta\mid c)\,\|\,\pi_{\rm old}(\theta\mid c)\big)\big] \le \epsilon, \tag{2.36}
# $$
#
# (eq-2-37)=
# $$
# \int \pi(\theta\mid c)\, d\theta = 1 \quad \forall c. \tag{2.37}
# $$
#
# (The thesis prints Eq. 2.36 without the bound $\le\epsilon$.) With a multiplier
# $\lambda\ge0$ for the KL and $p(c)\,\eta(c)$ for each normalisation, the Lagrangian is
#
# $$
# \mathcal L = \int p(c)\int \pi\, R\, d\theta\, dc + \lambda\Big(\epsilon - \int p(c)\int \pi \log\frac{\pi}{\pi_{\rm old}}\, d\theta\, dc\Big)
# + \int p(c)\,\eta(c)\Big(1 - \int \pi\, d\theta\Big) dc .
# $$
#
# Its derivative with respect to the value $\pi(\theta\mid c)$ is
# $p(c)\big[R(\theta, c) - \lambda\log\frac{\pi(\theta\mid c)}{\pi_{\rm old}(\theta\mid c)} - \lambda - \eta(c)\big]$. Setting it
# to zero, $\log\pi = \log\pi_{\rm old} + R/\lambda - 1 - \eta(c)/\lambda$, where the last two terms
# do not depend on $\theta$ and are fixed by the normalisation:
#
# (eq-2-38)=
# $$
# \pi^*(\theta\mid c) \propto \pi_{\rm old}(\theta\mid c)\exp\Big(\frac{R(\theta, c)}{\lambda}\Big), \tag{2.38}
# $$
#
# with normaliser $Z_\lambda(c) = \int\pi_{\rm old}\exp(R/\lambda)\, d\theta$; the term
# $\lambda\log Z_\lambda(c)$ plays the role of the context value $V(c)$ mentioned in the thesis.
# Substituting $\pi^*$ back gives the dual $g(\lambda) = \lambda\epsilon + \lambda\,\mathbb E_{p(c)}[\log Z_\lambda(c)]$
# that CREPS minimises over $\lambda>0$. For a fixed $\lambda$ this is the same
# maximisation as the self-paced curriculum of Section 3 (expected value minus a
# temperature times a KL to a reference distribution); the check there verifies the
# identity that makes Eq. 2.38 optimal.

# %% [markdown]
# ## 2. Maximum-entropy RL
#
# **The objective (Eqs. 2.39–2.40).** Maximum-entropy RL pays the policy a bonus
# $\alpha\ge0$ per nat of entropy in every state it visits:
#
# (eq-2-39)=
# $$
# J(\pi) = \mathbb{E}_{p_\pi}\Big[\sum_{t=0}^\infty \gamma^t\big(r(s_t, a_t) + \alpha\,\mathcal H(\pi(\cdot\mid s_t))\big)\Big]. \tag{2.39}
# $$
#
# The soft Q-function of a policy is the reward collected now plus the discounted,
# entropy-augmented return from the next step on {cite:p}`haarnoja2017reinforcement`:
#
# (eq-2-40)=
# $$
# Q^\pi_{\rm soft}(s_t, a_t) = r(s_t, a_t) + \mathbb{E}_{p_\pi}\Big[\sum_{k=1}^\infty \gamma^k\big(r(s_{t+k}, a_{t+k}) + \alpha\,\mathcal H(\pi(\cdot\mid s_{t+k}))\big)\Big]. \tag{2.40}
# $$
#
# Splitting off the first future step gives a recursion. Let $V^\pi(s) = \mathbb E_{a\sim\pi(\cdot|s)}[Q^\pi_{\rm soft}(s,a)] + \alpha\,\mathcal H(\pi(\cdot\mid s))$
# be the entropy-augmented return from state $s$ on; then
#
# $$
# Q^\pi_{\rm soft}(s, a) = r(s, a) + \gamma\,\mathbb{E}_{s'\sim P(\cdot\mid s, a)}\big[V^\pi(s')\big], \qquad
# V^\pi(s) = \mathbb{E}_{a\sim\pi(\cdot\mid s)}\big[Q^\pi_{\rm soft}(s, a) - \alpha\log\pi(a\mid s)\big],
# $$
#
# and $J(\pi) = \mathbb E_{s_0}[V^\pi(s_0)]$. For a tabular MDP these two lines are a linear
# system in $V^\pi$ (`F.soft_policy_evaluation`).
#
# **Improving one state (Eqs. 2.41–2.42).** Hold $Q = Q_{\rm soft}(s,\cdot)$ fixed and look for the
# action distribution $\pi$ that maximises the bracket of the recursion,
# $\mathbb E_\pi[Q] + \alpha\mathcal H(\pi) = \sum_a \pi(a)\big(Q(s,a) - \alpha\log\pi(a)\big)$. Define the
# normaliser $Z(s) = \sum_a\exp(Q(s,a)/\alpha)$ and the Boltzmann distribution
# $\pi_B(a\mid s) = \exp(Q(s,a)/\alpha)/Z(s)$, i.e. $Q(s,a) = \alpha\log\pi_B(a\mid s) + \alpha\log Z(s)$.
# Substituting this expression for $Q$:
#
# $$
# \mathbb E_\pi[Q(s,\cdot)] + \alpha\,\mathcal H(\pi)
# = \alpha\log Z(s) + \alpha\sum_a\pi(a)\big(\log\pi_B(a\mid s) - \log\pi(a)\big)
# = \alpha\log Z(s) - \alpha\,\mathrm{KL}\big(\pi\,\|\,\pi_B(\cdot\mid s)\big).
# $$
#
# The KL is non-negative and zero only at $\pi = \pi_B$ (Section 7). So $\pi_B$ is the unique
# maximiser and the maximum is $\alpha\log Z(s)$: this log-partition function is the soft
# value, and the Boltzmann distribution, written with it, is the optimal policy
# {cite:p}`ziebart2010modeling,haarnoja2017reinforcement` (for continuous actions the sums are integrals):
#
# (eq-2-41)=
# $$
# V^\pi_{\rm soft}(s_t) = \alpha\log\int\exp\Big(\frac1\alpha Q^\pi_{\rm soft}(s_t, a')\Big)\, da', \tag{2.41}
# $$
#
# (eq-2-42)=
# $$
# \pi^*(a_t\mid s_t) = \exp\Big(\frac1\alpha\big(Q^\pi_{\rm soft}(s_t, a_t) - V^\pi_{\rm soft}(s_t)\big)\Big). \tag{2.42}
# $$
#
# As $\alpha\to0$ the log-sum-exp tends to $\max_a Q$ and $\pi^*$ to the greedy policy.
#
# **The soft Bellman equation.** A policy that is Boltzmann in its *own* soft Q-function
# satisfies both lines of the recursion with $V = \alpha\log Z$:
#
# $$
# Q^*(s, a) = r(s, a) + \gamma\,\mathbb{E}_{s'}\big[V^*(s')\big], \qquad V^*(s) = \alpha\log\sum_a\exp\big(Q^*(s, a)/\alpha\big).
# $$
#
# The log-sum-exp is a smooth maximum and, like the maximum, changes by at most
# $\max_a|\Delta Q(s,a)|$ when $Q$ changes by $\Delta Q$; so the backup $V\mapsto\alpha\log\sum_a\exp((r+\gamma PV)/\alpha)$
# is a $\gamma$-contraction in the sup-norm and iterating it from any start converges to
# the unique fixed point (soft value iteration, `F.soft_value_iteration`).
#
# The first check writes the soft Bellman equation out in the cell and evaluates it at the
# fixed point the package found, on a random MDP with 6 states and 3 actions.

# %%
P, R_sa = F.random_mdp(6, 3, seed=0)
gamma, alpha = 0.9, 0.5
sol = F.soft_value_iteration(P, R_sa, gamma, alpha)
q_backup = R_sa + gamma * P @ sol.v                       # r + gamma E[V(s')]
v_backup = alpha * logsumexp(q_backup / alpha, axis=1)    # alpha log sum_a exp(Q / alpha)
pi_backup = np.exp((q_backup - v_backup[:, None]) / alpha)
print(f"soft Bellman residual max_s |V - backup(V)| = {np.abs(sol.v - v_backup).max():.1e}")
print(f"Boltzmann policy: max_s |sum_a pi(a|s) - 1| = {np.abs(pi_backup.sum(1) - 1).max():.1e}, "
      f"max |pi - package policy| = {np.abs(pi_backup - sol.policy).max():.1e}")
assert np.abs(sol.v - v_backup).max() < 1e-8
assert np.abs(pi_backup.sum(1) - 1).max() < 1e-12
assert np.abs(pi_backup - sol.policy).max() < 1e-8

# %% [markdown]
# The second check tests the per-state step by brute force: with three actions the action
# distributions form a triangle, which we cover with a grid of spacing $1/400$ and evaluate
# $\mathbb E_\pi[Q^*(s,\cdot)] + \alpha\mathcal H(\pi)$ at every grid point in every state. The best grid
# value must equal $V^*(s) = \alpha\log Z(s)$ up to the grid resolution and never exceed it, and
# the best grid point must sit next to $\pi^*(\cdot\mid s)$. For 200 random action distributions
# the identity $\mathbb E_\pi[Q] + \alpha\mathcal H(\pi) = V^*(s) - \alpha\,\mathrm{KL}(\pi\|\pi^*)$ must hold exactly.

# %%
n_grid = 400
i, j = np.meshgrid(np.arange(n_grid + 1), np.arange(n_grid + 1), indexing="ij")
keep = i + j <= n_grid
simplex = np.stack([i[keep], j[keep], n_grid - i[keep] - j[keep]], -1) / n_grid   # (G, 3)
scores = simplex @ sol.q.T - alpha * xlogy(simplex, simplex).sum(-1)[:, None]       # (G, S)
best, argbest = scores.max(0), simplex[scores.argmax(0)]
print(f"max over the grid - V*: between {np.min(best - sol.v):.1e} and {np.max(best - sol.v):.1e}; "
      f"best grid point vs pi*: {np.abs(argbest - sol.policy).max():.4f}")
assert np.all(best <= sol.v + 1e-12) and np.all(best >= sol.v - 1e-4)
assert np.abs(argbest - sol.policy).max() <= 2 / n_grid

rand_pi = np.random.default_rng(1).dirichlet(np.ones(3), size=(200, 6))            # (200, S, A)
lhs = (rand_pi * sol.q).sum(-1) - alpha * xlogy(rand_pi, rand_pi).sum(-1)
rhs = sol.v - alpha * (xlogy(rand_pi, rand_pi) - rand_pi * np.log(sol.policy)).sum(-1)
print(f"E[Q] + alpha H = V* - alpha KL(pi || pi*) for 1200 (policy, state) pairs: "
      f"max error {np.abs(lhs - rhs).max():.1e}")
assert np.abs(lhs - rhs).max() < 1e-10

# %% [markdown]
# **Greedy in every state is optimal overall.** Compare $\pi^*$ with any other policy $\pi'$.
# The recursions for the two policies give $Q^{\pi'}_{\rm soft} = Q^* + \gamma\,\mathbb E_{s'}[V^{\pi'}(s') - V^*(s')]$,
# and the per-state identity above with $Q = Q^*$ gives
# $\mathbb E_{\pi'}[Q^* - \alpha\log\pi'] = V^* - \alpha\,\mathrm{KL}(\pi'\|\pi^*)$. Together,
#
# $$
# V^{\pi'}(s) - V^*(s) = -\alpha\,\mathrm{KL}\big(\pi'(\cdot\mid s)\,\|\,\pi^*(\cdot\mid s)\big)
# + \gamma\,\mathbb E_{a\sim\pi'(\cdot|s),\, s'\sim P(\cdot|s,a)}\big[V^{\pi'}(s') - V^*(s')\big].
# $$
#
# With $\Delta = V^{\pi'} - V^*$, $\kappa(s) = \mathrm{KL}(\pi'(\cdot\mid s)\|\pi^*(\cdot\mid s))$ and the state-to-state
# matrix $P_{\pi'}(s, s') = \sum_a\pi'(a\mid s)P(s'\mid s, a)$ this reads $\Delta = -\alpha\kappa + \gamma P_{\pi'}\Delta$, so
#
# $$
# V^{\pi'} - V^* = -\alpha\,(I - \gamma P_{\pi'})^{-1}\kappa \;\le\; 0,
# $$
#
# because $(I-\gamma P_{\pi'})^{-1} = \sum_t\gamma^tP_{\pi'}^t$ has non-negative entries. No policy does
# better than $\pi^*$ in any state, so $J(\pi')\le J(\pi^*)$ for every start distribution; the loss
# is the discounted KL to $\pi^*$ along the states that $\pi'$ visits. The cell evaluates 20
# random policies with the package's linear solve and compares with the right-hand side.

# %%
gaps = []
for pi_other in rand_pi[:20]:
    v_other, _ = F.soft_policy_evaluation(P, R_sa, pi_other, gamma, alpha)
    kappa = (xlogy(pi_other, pi_other) - pi_other * np.log(sol.policy)).sum(-1)
    P_other = np.einsum("sa,sat->st", pi_other, P)
    predicted = np.linalg.solve(np.eye(len(kappa)) - gamma * P_other, -alpha * kappa)
    gaps.append((v_other - sol.v, predicted))
gaps = np.array(gaps)
print(f"V^pi' - V*: from {gaps[:, 0].min():.3f} to {gaps[:, 0].max():.3f}; "
      f"max |(V^pi' - V*) - (-alpha (I - gamma P)^-1 KL)| = {np.abs(gaps[:, 0] - gaps[:, 1]).max():.1e}")
assert np.abs(gaps[:, 0] - gaps[:, 1]).max() < 1e-7
assert gaps[:, 0].max() <= 1e-8

# %% [markdown]
# The package's own check of Section 2.4.1 repeats the optimality test against random
# policies and single-state perturbations, measured by Eq. 2.39 itself, and follows the soft
# value towards the ordinary optimal value as $\alpha\to0$: since $0\le\alpha\mathcal H\le\alpha\log|A|$
# per step, the two differ by at most $\alpha\log|A|/(1-\gamma)$.

# %% tags=["full-width"]
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
# **Episode-based maximum-entropy RL (Eq. 2.43).** In ERL the entropy bonus is paid on the
# search distribution over parameters, once per episode:
#
# (eq-2-43)=
# $$
# J(\pi_\omega) = \mathbb{E}_{p(c)}\Big[\int \pi_\omega(\theta\mid c)\big(R(\theta, c) + \alpha\,\mathcal H(\pi_\omega(\cdot\mid c))\big)\, d\theta\Big]. \tag{2.43}
# $$
#
# The entropy does not depend on $\theta$ and $\pi_\omega$ integrates to one, so the bracket is
# $\mathbb E_{\pi_\omega}[R] + \alpha\mathcal H(\pi_\omega(\cdot\mid c))$ for each context. This is the per-state
# problem above with no next state ($\gamma = 0$) and $R(\cdot, c)$ in the role of $Q$: the
# optimal search distribution is $\pi^*(\theta\mid c) = \exp(R(\theta, c)/\alpha)/Z(c)$ with value
# $\alpha\log Z(c)$. Section 7 derives the same answer from a KL divergence (Eq. 2.67).

# %% [markdown]
# ## 3. Self-paced curricula
#
# The self-paced objective {cite:p}`klink2020self` lets the learner choose the contexts
# it trains on from its own distribution $\pi_\omega(c)$, but charges $\beta$ times the KL to
# the environment's $p(c)$:
#
# (eq-2-44)=
# $$
# J(\pi_\omega) = \mathbb{E}_{\pi_\omega(c)}\Big[\int\pi_\omega(\theta\mid c)\, R(\theta, c)\, d\theta\Big] - \beta\,\mathrm{KL}\big(\pi_\omega(c)\,\|\,p(c)\big). \tag{2.44}
# $$
#
# **The optimal curriculum for a fixed policy.** The thesis does not write it out, but it
# follows in two lines. With $\pi_\omega(\theta\mid c)$ fixed, the inner integral is a function of
# the context alone, $\bar R(c) = \int\pi_\omega(\theta\mid c)R(\theta, c)\, d\theta$, and Eq. 2.44 becomes
# $J(\pi) = \mathbb E_{\pi}[\bar R] - \beta\,\mathrm{KL}(\pi\|p)$ over context distributions $\pi$. Define
#
# $$
# \pi^*(c) = \frac{p(c)\exp(\bar R(c)/\beta)}{Z_\beta}, \qquad Z_\beta = \mathbb E_{p(c)}\big[\exp(\bar R(c)/\beta)\big],
# \qquad\text{so}\qquad \bar R(c) = \beta\log\frac{\pi^*(c)}{p(c)} + \beta\log Z_\beta .
# $$
#
# Substituting this expression for $\bar R$:
#
# $$
# J(\pi) = \mathbb E_\pi\Big[\beta\log\frac{\pi^*}{p} + \beta\log Z_\beta - \beta\log\frac{\pi}{p}\Big]
# = \beta\log Z_\beta - \beta\,\mathrm{KL}(\pi\,\|\,\pi^*).
# $$
#
# So $\pi^*$ is the unique maximiser, with value $\beta\log\mathbb E_p[\exp(\bar R/\beta)]$. Small $\beta$
# concentrates $\pi^*$ on easy, high-return contexts; as $\beta\to\infty$ it returns to $p(c)$. The
# same algebra, with $p\to\pi_{\rm old}$ and $\beta\to\lambda$, is what makes Eq. 2.38 optimal, and with
# $p$ uniform it is the per-state step of Section 2.
#
# The check takes the toy curriculum of `F.self_paced_problem` (contexts on a grid, uniform
# $p$, easy contexts near 0), evaluates Eq. 2.44 with the package for 50 random context
# distributions at three temperatures and compares with $\beta\log Z_\beta - \beta\,\mathrm{KL}(\pi\|\pi^*)$
# computed in the cell.

# %%
contexts_sp, p_sp, r_sp = F.self_paced_problem()
rng = np.random.default_rng(2)
errors = []
for beta in (0.1, 1.0, 10.0):
    log_z = logsumexp(r_sp / beta, b=p_sp)                 # log E_p[exp(R / beta)]
    pi_star = p_sp * np.exp(r_sp / beta - log_z)
    errors.append(np.abs(pi_star - F.self_paced_optimum(beta, p_sp, r_sp)).max())
    for pi_c in rng.dirichlet(np.ones(p_sp.size), size=50):
        lhs = F.self_paced_objective(pi_c, p_sp, r_sp, beta)
        rhs = beta * log_z - beta * np.sum(xlogy(pi_c, pi_c) - xlogy(pi_c, pi_star))
        errors.append(abs(lhs - rhs))
    print(f"beta = {beta:5g}: J(pi*) = {beta * log_z:.4f}, last random pi: J = {lhs:.4f} = {rhs:.4f}")
print(f"max error over 150 random curricula and the closed form: {max(errors):.1e}")
assert max(errors) < 1e-10

# %% [markdown]
# The package's check compares the closed form with perturbed and Gaussian-shaped context
# distributions for eight temperatures and follows the KL to $p$ as $\beta$ grows (for large
# $\beta$ it approaches $\mathrm{Var}_p[\bar R]/(2\beta^2)$).

# %% tags=["full-width"]
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

# %% tags=["full-width"]
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
# **Mixture models (Eq. 2.47).** Give every point $x$ a discrete label $o\in\{1,\dots,N\}$ drawn
# first, $p(x, o) = p(o)\,p(x\mid o)$. Summing the label out (the sum rule) gives the mixture
# {cite:p}`bishop2006pattern`:
#
# (eq-2-47)=
# $$
# p(x) = \sum_{o=1}^N p(o)\, p(x\mid o). \tag{2.47}
# $$
#
# **Mixtures of experts (Eqs. 2.48–2.49).** The same sum rule, with everything conditioned on
# the context, gives the contextual policy as a gated sum of experts,
#
# (eq-2-48)=
# $$
# \pi_\omega(\theta\mid c) = \sum_{o=1}^N \pi(o\mid c)\, \pi_\omega(\theta\mid o, c), \tag{2.48}
# $$
#
# with Gaussian experts whose mean depends on the context,
#
# (eq-2-49)=
# $$
# \pi_\omega(\theta\mid o, c) = \mathcal N\big(\theta\mid f_{\omega_o}(c), \Sigma_o\big). \tag{2.49}
# $$
#
# **Gating by Bayes' rule.** Chapters 3 and 4 never parameterise the gating $\pi(o\mid c)$
# directly: each expert owns a context distribution $\pi(c\mid o)$, there are weights $\pi(o)$, and
# the gating is the posterior of the label given the context,
#
# $$
# \pi(o\mid c) = \frac{\pi(c\mid o)\,\pi(o)}{\pi(c)}, \qquad \pi(c) = \sum_{o'}\pi(c\mid o')\,\pi(o').
# $$
#
# It sums to one over $o$ by construction, and multiplying Eq. 2.48 by $\pi(c)$ gives the joint
# $\pi(\theta, c) = \sum_o\pi(o)\pi(c\mid o)\pi(\theta\mid o, c)$. Once a parameter $\theta$ has been drawn as
# well, Bayes' rule applied once more gives the responsibility of each expert for the pair,
#
# $$
# \pi(o\mid c, \theta) = \frac{\pi(o\mid c)\,\pi(\theta\mid o, c)}{\pi(\theta\mid c)}
# = \frac{\pi(o)\,\pi(c\mid o)\,\pi(\theta\mid o, c)}{\sum_{o'}\pi(o')\,\pi(c\mid o')\,\pi(\theta\mid o', c)},
# $$
#
# the quantity that the per-expert objectives of Chapter 3 reward. `vslbook.dists.LinearGaussianMoE`
# implements the model with linear $f_{\omega_o}(c) = K_oc + k_o$. The package's check compares
# its gating with the ratio of scipy densities, tests $\log\pi(\theta\mid c) = \log\pi(\theta, c) - \log\pi(c)$,
# integrates the densities on grids and compares sample means with the mixture mean.

# %% tags=["full-width"]
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
# The responsibilities $\pi(o\mid c, \theta)$ from the package (gating times expert density over
# the mixture density, all in log space) against the right-hand fraction above, evaluated
# with scipy densities for 500 sampled pairs $(c, \theta)$.

# %%
moe_model = LinearGaussianMoE.random(3, 2, 2, seed=0)
gen = torch.Generator().manual_seed(0)
c_s, _ = moe_model.sample_contexts(500, gen)
theta_s, _ = moe_model.sample(c_s, gen)
resp_pkg = (moe_model.log_gating(c_s) + moe_model.expert_log_prob(theta_s, c_s)
            - moe_model.log_prob(theta_s, c_s)[:, None]).exp().numpy()

cn, tn = c_s.numpy(), theta_s.numpy()
joint_o = np.stack([
    moe_model.weights[o].item()
    * multivariate_normal(moe_model.context_means[o].numpy(), moe_model.context_covs[o].numpy()).pdf(cn)
    * multivariate_normal(np.zeros(2), moe_model.covs[o].numpy()).pdf(
        tn - cn @ moe_model.gains[o].numpy().T - moe_model.offsets[o].numpy())
    for o in range(moe_model.n_components)
], axis=-1)
resp_direct = joint_o / joint_o.sum(-1, keepdims=True)
print(f"max |sum_o pi(o|c,theta) - 1| = {np.abs(resp_pkg.sum(-1) - 1).max():.1e}; "
      f"max |package - direct| = {np.abs(resp_pkg - resp_direct).max():.1e}")
assert np.abs(resp_pkg.sum(-1) - 1).max() < 1e-12
assert np.abs(resp_pkg - resp_direct).max() < 1e-10

# %% [markdown]
# ## 6. Diffusion models: the forward process
#
# A diffusion model moves a random variable along a stochastic differential equation
# $dx_t = g(x_t)\,dt + \sigma_t\,dB_t$ (Eq. 2.50). The noising process of a denoising diffusion
# model is the Ornstein–Uhlenbeck SDE
#
# (eq-2-51)=
# $$
# dx_t = -\beta_t x_t\, dt + \eta\sqrt{2\beta_t}\, dB_t, \qquad x_0\sim p(x_0). \tag{2.51}
# $$
#
# **Its marginals.** Take a constant $\beta$. The noise has mean zero, so the mean obeys
# $\frac{d}{dt}\mathbb E[x_t] = -\beta\,\mathbb E[x_t]$, i.e. $m_t = m_0e^{-\beta t}$. By Itô's rule,
# $d(x_t^2) = 2x_t\,dx_t + (dx_t)^2 = (-2\beta x_t^2 + 2\beta\eta^2)\,dt + (\text{mean-zero noise})$, so the
# variance $v_t = \mathbb E[x_t^2] - m_t^2$ obeys $\frac{d}{dt}v_t = -2\beta v_t + 2\beta\eta^2$, whose solution is
# $v_t = v_0e^{-2\beta t} + \eta^2(1 - e^{-2\beta t})$. The process is linear, so Gaussian initial
# conditions stay Gaussian: the data are forgotten at rate $\beta$ and the marginal tends to
# $\mathcal N(0, \eta^2)$, the prior that the generative (reverse) process of Eq. 2.52 starts from.
#
# **Discretisation (Eqs. 2.53–2.55).** One Euler–Maruyama step of length $\Delta t$ replaces the
# SDE by $x^{n+1} = (1 - \beta\Delta t)\,x^n + \eta\sqrt{2\beta\Delta t}\,\varepsilon$, a Gaussian kernel
# $\vec p_{n+1|n}(x^{n+1}\mid x^n) = \mathcal N\big((1-\beta\Delta t)x^n, 2\beta\eta^2\Delta t\big)$. Chaining the kernels
# of the forward and of the backward process gives the two joint distributions over
# $x^{0:N}$ (the chain rule of probability, since each step depends only on the previous one):
#
# (eq-2-53)=
# $$
# \vec p_{0:N}(x^{0:N}) = \vec p_0(x^0)\prod_{n=0}^{N-1}\vec p_{n+1|n}(x^{n+1}\mid x^n), \tag{2.53}
# $$
#
# (eq-2-54)=
# $$
# \overleftarrow p_{0:N}(x^{0:N}) = \overleftarrow p_N(x^N)\prod_{n=1}^{N}\overleftarrow p_{n-1|n}(x^{n-1}\mid x^n), \tag{2.54}
# $$
#
# and integrating the intermediate states out of the backward chain makes the generated
# sample a latent-variable model with latents $x^{1:N}$:
#
# (eq-2-55)=
# $$
# \overleftarrow p_0(x^0) = \int \overleftarrow p_{0:N}(x^{0:N})\, dx^{1:N}. \tag{2.55}
# $$
#
# The check simulates the Euler–Maruyama recursion and compares sample moments with the
# closed-form marginals (its tolerance allows for the known discretisation bias).

# %% tags=["full-width"]
ou = show(F.check_ou_marginals(seed=0))
d = ou.data
every = max(1, len(d["times"]) // 15)
fig, axes = plt.subplots(1, 2, figsize=(10, 3.2))
axes[0].plot(np.linspace(0, float(d["times"][-1]), d["paths"].shape[0]), d["paths"], lw=0.5, color="#999999")
axes[0].set(xlabel="t", ylabel="x_t", title="Euler–Maruyama sample paths")
axes[1].plot(d["times"], d["exact_mean"], "-", color="k", label="exact mean")
axes[1].plot(d["times"][::every], d["sample_mean"][::every], "o", color=method_color("ours"), label="sampled mean")
axes[1].plot(d["times"], d["exact_var"], "--", color="k", label="exact variance")
axes[1].plot(d["times"][::every], d["sample_var"][::every], "s", color=PALETTE[1], label="sampled variance")
axes[1].set(xlabel="t", title="marginal moments")
axes[1].legend(fontsize=8)
fig.tight_layout()
plt.show()

# %% [markdown]
# ## 7. Variational inference
#
# **The reverse KL (Eqs. 2.56–2.57).** Variational inference fits a tractable $p(x)$ to a
# target $q(x)$ by minimising
#
# (eq-2-56)=
# $$
# \arg\min_{p(x)}\mathrm{KL}\big(p(x)\,\|\,q(x)\big) = \arg\min_{p(x)}\int p(x)\log\frac{p(x)}{q(x)}\, dx. \tag{2.56}
# $$
#
# The KL is never negative: by Jensen's inequality for the concave logarithm,
# $-\mathrm{KL}(p\|q) = \mathbb E_p[\log(q/p)] \le \log\mathbb E_p[q/p] = \log\int q\, dx = 0$, with equality only if
# $q/p$ is constant, i.e. $p = q$. The target is usually known only up to its normaliser,
# $q = \tilde q/\mathcal Z$ with $\mathcal Z = \int\tilde q\, dx$. Then $\log(p/q) = \log(p/\tilde q) + \log\mathcal Z$ and
#
# (eq-2-57)=
# $$
# \arg\min_{p(x)}\mathrm{KL}\big(p(x)\,\|\,q(x)\big) = \arg\min_{p(x)}\int p(x)\log\frac{p(x)}{\tilde q(x)}\, dx + \log\mathcal Z, \tag{2.57}
# $$
#
# where $\log\mathcal Z$ does not depend on $p$ and drops out of the minimisation.
#
# **The ELBO.** Read Eq. 2.57 the other way round: with the evidence lower bound
# $\mathrm{ELBO}(p) = \mathbb E_p[\log\tilde q(x) - \log p(x)]$,
#
# $$
# \log\mathcal Z = \mathrm{ELBO}(p) + \mathrm{KL}(p\,\|\,q) \;\ge\; \mathrm{ELBO}(p).
# $$
#
# Minimising the KL is maximising a lower bound on the log-normaliser, tight exactly at
# $p = q$. In a Bayesian model with latent $z$ and data $x$, take $\tilde q(z) = p(x, z)$: then
# $\mathcal Z = p(x)$ is the evidence and $q(z) = p(z\mid x)$ the posterior. The check uses the
# conjugate model $z\sim\mathcal N(0, s_0^2)$, $x\mid z\sim\mathcal N(wz, s^2)$, where
# $\log p(x) = \log\mathcal N(x\mid 0, w^2s_0^2 + s^2)$. For Gaussian $p(z) = \mathcal N(m, v)$ the ELBO is closed form,
#
# $$
# \mathrm{ELBO}(m, v) = -\tfrac12\log(2\pi s^2) - \frac{(x - wm)^2 + w^2v}{2s^2}
# - \tfrac12\log(2\pi s_0^2) - \frac{m^2 + v}{2s_0^2} + \tfrac12\log(2\pi e\, v),
# $$
#
# the posterior comes from conditioning the joint Gaussian of $(z, x)$ (`condition_gaussian`) and
# the KL from `gaussian_kl`. For 30 random $(m, v)$ and for the posterior itself, the
# evidence must equal ELBO + KL.

# %%
s0, w_lik, s_lik, x_obs = 1.2, 0.8, 0.5, 1.7
log_evidence = norm.logpdf(x_obs, 0.0, math.sqrt(w_lik**2 * s0**2 + s_lik**2))
cov_zx = torch.tensor([[s0**2, w_lik * s0**2], [w_lik * s0**2, w_lik**2 * s0**2 + s_lik**2]], dtype=torch.float64)
post_mean, post_cov = condition_gaussian(torch.zeros(2, dtype=torch.float64), cov_zx, [1],
                                         torch.tensor([x_obs], dtype=torch.float64))
rng = np.random.default_rng(3)
m_q = np.r_[rng.normal(size=30), post_mean.item()]
v_q = np.r_[rng.uniform(0.05, 2.0, 30), post_cov.item()]
elbo = (-0.5 * np.log(2 * np.pi * s_lik**2) - ((x_obs - w_lik * m_q) ** 2 + w_lik**2 * v_q) / (2 * s_lik**2)
        - 0.5 * np.log(2 * np.pi * s0**2) - (m_q**2 + v_q) / (2 * s0**2)
        + 0.5 * np.log(2 * np.pi * np.e * v_q))
kl_post = gaussian_kl(torch.from_numpy(m_q)[:, None], torch.from_numpy(v_q)[:, None, None],
                      post_mean, post_cov).numpy()
print(f"log p(x) = {log_evidence:.6f}; ELBO ranges from {elbo.min():.3f} to {elbo.max():.6f} (posterior)")
print(f"max |log p(x) - (ELBO + KL)| = {np.abs(log_evidence - (elbo + kl_post)).max():.1e}")
assert np.abs(log_evidence - (elbo + kl_post)).max() < 1e-10
assert np.all(elbo <= log_evidence + 1e-12) and abs(elbo[-1] - log_evidence) < 1e-10

# %% [markdown]
# **Conditional targets (Eqs. 2.58–2.59).** With a context $c\sim p(c)$ the same objective is
# averaged over contexts (the thesis leaves the outer expectation implicit on the right of
# Eq. 2.58):
#
# (eq-2-58)=
# $$
# \arg\min_{p(x|c)}\mathbb E_{p(c)}\big[\mathrm{KL}\big(p(x\mid c)\,\|\,q(x\mid c)\big)\big]
# = \arg\min_{p(x|c)}\mathbb E_{p(c)}\Big[\int p(x\mid c)\log\frac{p(x\mid c)}{q(x\mid c)}\, dx\Big], \tag{2.58}
# $$
#
# and with $q(x\mid c) = \tilde q(x\mid c)/\mathcal Z(c)$ each context contributes its own constant:
#
# (eq-2-59)=
# $$
# \arg\min_{p(x|c)}\mathbb E_{p(c)}\Big[\int p(x\mid c)\log\frac{p(x\mid c)}{\tilde q(x\mid c)}\, dx + \log\mathcal Z(c)\Big]. \tag{2.59}
# $$
#
# **Latent-variable models: the chain rule of the KL (Eqs. 2.60–2.61).** For
# $p_\theta(x) = \int p_\theta(x, z)\, dz$ the integral sits inside the logarithm of Eq. 2.56. To get it
# out, pick any conditional $q_\phi(z\mid x)$ and attach it to the target,
#
# (eq-2-61)=
# $$
# q_\phi(x, z) = q_\phi(z\mid x)\, q(x), \tag{2.61}
# $$
#
# a joint whose $x$-marginal is the target whatever $\phi$ is. Factorising both joints into
# marginal times conditional, $\log\frac{p_\theta(x,z)}{q_\phi(x,z)} = \log\frac{p_\theta(x)}{q(x)} + \log\frac{p_\theta(z|x)}{q_\phi(z|x)}$; taking the
# expectation under $p_\theta(x, z) = p_\theta(x)p_\theta(z\mid x)$ and moving the second term to the other side
# {cite:p}`cover1999elements`,
#
# (eq-2-60)=
# $$
# \mathrm{KL}\big(p_\theta(x)\,\|\,q(x)\big) = \underbrace{\mathrm{KL}\big(p_\theta(x, z)\,\|\,q_\phi(x, z)\big)}_{\mathcal L(\theta, \phi)}
# - \underbrace{\mathbb E_{p_\theta(x)}\big[\mathrm{KL}\big(p_\theta(z\mid x)\,\|\,q_\phi(z\mid x)\big)\big]}_{\mathcal J(\phi, \theta)}. \tag{2.60}
# $$
#
# Because $\mathcal J\ge0$, the joint KL $\mathcal L$ is an *upper bound* on the marginal KL, tight when
# $q_\phi(z\mid x) = p_\theta(z\mid x)$; and $\mathcal L$ only needs $\log p_\theta(x, z)$, no integral inside a
# logarithm. The check evaluates all three terms in closed form for random joint Gaussians.

# %%
show(F.check_kl_chain_rule(seed=0))

# %% [markdown]
# **EM (Eqs. 2.62–2.63).** The left side of Eq. 2.60 does not depend on $\phi$, so minimising $\mathcal J$
# over $\phi$ is the same as minimising $\mathcal L$ over $\phi$. Alternating the two minimisations of $\mathcal L$
# {cite:p}`dempster1977maximum`,
#
# (eq-2-62)=
# $$
# \theta_{i+1} = \arg\min_\theta\mathcal L(\theta, \phi^{(i)}), \tag{2.62}
# $$
#
# (eq-2-63)=
# $$
# \phi_{i+1} = \arg\min_\phi\mathcal J(\phi, \theta^{(i)}), \tag{2.63}
# $$
#
# never increases the marginal KL: if the E-step is exact ($\mathcal J = 0$ after it), then
# $\mathrm{KL}(p_{\theta_{i+1}}\|q)\le\mathcal L(\theta_{i+1}, \phi_{i+1})\le\mathcal L(\theta_i, \phi_{i+1}) = \mathrm{KL}(p_{\theta_i}\|q)$.
#
# **Mixtures: the E-step in closed form (Eq. 2.64).** For a mixture the latent is the label $o$
# and $\mathcal J = \mathbb E_{p_\theta(x)}[\mathrm{KL}(p_\theta(o\mid x)\|q_\phi(o\mid x))]$. A KL is zero exactly when its
# arguments agree, so the best variational distribution is the model's posterior over
# labels — the responsibilities, by Bayes' rule on Eq. 2.47:
#
# (eq-2-64)=
# $$
# q_{\phi^{(i+1)}}(o\mid x) = p_{\theta^{(i)}}(o\mid x) = \frac{p_{\theta^{(i)}}(x\mid o)\, p_{\theta^{(i)}}(o)}{\sum_{o'=1}^N p_{\theta^{(i)}}(x\mid o')\, p_{\theta^{(i)}}(o')}. \tag{2.64}
# $$
#
# This is the scheme used to fit Gaussian mixtures by policy search {cite:p}`arenz2018efficient`, which
# Chapter 3 extends. The check integrates $p(x)$, the bound $\mathcal L$ for 21 arbitrary $q(o\mid x)$
# and the gap $\mathcal J$ on a fine grid: $\mathcal L\ge\mathrm{KL}$ every time, $\mathcal L - \mathrm{KL} = \mathcal J$, and
# $\mathcal L = \mathrm{KL}$ at the responsibilities.

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
# **Diffusion models (Eqs. 2.65–2.66).** For the discretised diffusion model of Section 6 the
# latents are the intermediate states $x^{1:N}$ and the model is the backward chain
# $\overleftarrow p^\theta_{0:N}$ of Eq. 2.54, whose kernels contain the learned score. As the joint
# $q_\phi(x, z)$ take the noising chain *started at the target*,
# $\vec q_{0:N}(x^{0:N}) = q(x^0)\prod_{n=1}^N\vec q_{n|n-1}(x^n\mid x^{n-1})$: its $x^0$-marginal is the target, as
# Eq. 2.61 requires, and it has no parameters, so only the M-step remains:
#
# (eq-2-65)=
# $$
# \arg\min_\theta\mathrm{KL}\big(\overleftarrow p^\theta_{0:N}(x^{0:N})\,\|\,\vec q_{0:N}(x^{0:N})\big). \tag{2.65}
# $$
#
# Writing both joints as products of their kernels turns the log-ratio into a sum of one
# term per step, each evaluated along a trajectory of the model:
#
# (eq-2-66)=
# $$
# = \arg\min_\theta\mathbb E_{\overleftarrow p^\theta_{0:N}(x^{0:N})}\Big[\log\overleftarrow p_N(x^N)
# + \sum_{n=1}^N\log\frac{\overleftarrow p^\theta_{n-1|n}(x^{n-1}\mid x^n)}{\vec q_{n|n-1}(x^n\mid x^{n-1})} - \log q(x^0)\Big]. \tag{2.66}
# $$
#
# The target appears only through $\log q(x^0)$; with an unnormalised target the expectation
# shifts by the constant $\log\mathcal Z$ {cite:p}`richter2024improved`.
#
# **Check, term by term.** On a 1-D chain with $N = 3$ steps, a Gaussian target
# $q(x^0) = \mathcal N(m_0, s_0^2)$, the Euler–Maruyama forward kernels and random linear-Gaussian backward
# kernels $x^{n-1} = g_nx^n + b_n + \sqrt{v_n}\,\varepsilon$ from $x^N\sim\mathcal N(0, \eta^2)$, every term of Eq. 2.66 is
# an expected log of a Gaussian, hence a function of the first two moments of the model's
# trajectory. The cell propagates those moments backwards through the chain and adds up the
# expectations of Eq. 2.66. Independently, it writes both chains as joint Gaussians over
# $(x^0,\dots,x^N)$ (a linear system $x = Bx + b + D\varepsilon$) and computes Eq. 2.65 with `gaussian_kl`.

# %%
N_steps, beta_ou, eta_ou = 3, 1.0, 1.0
dt_ou = 1.0 / N_steps
a_fwd, var_fwd = 1 - beta_ou * dt_ou, 2 * beta_ou * eta_ou**2 * dt_ou     # forward kernel N(a x, var_fwd)
m0, sd0 = 0.4, 0.7                                                        # target q(x^0)
rng = np.random.default_rng(4)
g_b, b_b = rng.uniform(0.9, 1.4, N_steps), rng.normal(scale=0.3, size=N_steps)
v_b = rng.uniform(0.2, 0.6, N_steps) * var_fwd                            # backward kernel n -> n-1

# Moments of the model's trajectory, propagated from x^N down to x^0.
mu, var, cov_up = np.zeros(N_steps + 1), np.zeros(N_steps + 1), np.zeros(N_steps + 1)
var[N_steps] = eta_ou**2
for n in range(N_steps, 0, -1):
    mu[n - 1] = g_b[n - 1] * mu[n] + b_b[n - 1]
    var[n - 1] = g_b[n - 1] ** 2 * var[n] + v_b[n - 1]
    cov_up[n - 1] = g_b[n - 1] * var[n]                                   # Cov(x^{n-1}, x^n)

# %% [markdown]
# Eq. 2.66 term by term from these moments, then Eq. 2.65 as one KL between the two joint
# Gaussians (`vslbook.bounds.gaussian_chains`):

# %%
from vslbook.bounds.gaussian_chains import chain_joint, expected_log_normal

eq_266 = expected_log_normal(var[N_steps], eta_ou**2)                     # E log p_N(x^N)
for n in range(1, N_steps + 1):
    eq_266 += expected_log_normal(v_b[n - 1], v_b[n - 1])                 # E log p_{n-1|n}
    sq = var[n] + a_fwd**2 * var[n - 1] - 2 * a_fwd * cov_up[n - 1] + (mu[n] - a_fwd * mu[n - 1]) ** 2
    eq_266 -= expected_log_normal(sq, var_fwd)                            # E log q_{n|n-1}
eq_266 -= expected_log_normal(var[0] + (mu[0] - m0) ** 2, sd0**2)         # E log q(x^0)

B_fwd = np.diag(np.full(N_steps, a_fwd), -1)                              # x^n depends on x^{n-1}
B_bwd = np.diag(g_b, 1)                                                   # x^{n-1} depends on x^n
mean_q, cov_q = chain_joint(B_fwd, np.r_[m0, np.zeros(N_steps)], np.r_[sd0, np.full(N_steps, math.sqrt(var_fwd))])
mean_p, cov_p = chain_joint(B_bwd, np.r_[b_b, 0.0], np.r_[np.sqrt(v_b), eta_ou])
eq_265 = gaussian_kl(*(torch.from_numpy(a) for a in (mean_p, cov_p, mean_q, cov_q))).item()
print(f"Eq. 2.66 term by term: {eq_266:.10f};  Eq. 2.65 joint Gaussian KL: {eq_265:.10f}")
assert abs(eq_266 - eq_265) < 1e-10

# %% [markdown]
# The package's check builds a similar chain, estimates the expectation of Eq. 2.66 by Monte
# Carlo from the model's own samples, and confirms that the joint KL bounds the marginal
# $\mathrm{KL}(\overleftarrow p_0\|q)$ with the gap of Eq. 2.60.

# %%
dk = show(F.check_diffusion_kl(seed=0, n_samples=budget.pick(smoke=20_000, reduced=100_000, full=400_000)))
d = dk.data
print(f"joint KL {float(d['joint_kl']):.4f} ≥ marginal KL {float(d['marginal_kl']):.4f}; "
      f"MC estimate {float(d['mc_estimate']):.4f} ± {float(d['mc_stderr']):.4f}")

# %% [markdown]
# **Episode-based max-ent RL as inference (Eq. 2.67).** Take as target the Boltzmann
# distribution of the return, $q(\theta\mid c) = \exp(R(\theta, c)/\alpha)/Z(c)$ with
# $Z(c) = \int\exp(R(\theta, c)/\alpha)\, d\theta$. Then $\log q = R/\alpha - \log Z(c)$ and, per context,
#
# $$
# \mathrm{KL}\big(\pi_\omega(\cdot\mid c)\,\|\,q(\cdot\mid c)\big) = \mathbb E_{\pi_\omega}[\log\pi_\omega] - \frac1\alpha\mathbb E_{\pi_\omega}[R] + \log Z(c)
# = -\frac1\alpha\Big(\mathbb E_{\pi_\omega}[R] + \alpha\,\mathcal H(\pi_\omega(\cdot\mid c))\Big) + \log Z(c).
# $$
#
# Averaging over $p(c)$,
#
# (eq-2-67)=
# $$
# L(\omega) = \mathbb E_{p(c)}\Big[\mathrm{KL}\Big(\pi_\omega(\theta\mid c)\,\Big\|\,\frac{\exp(R(\theta, c)/\alpha)}{Z(c)}\Big)\Big]
# = -\frac1\alpha J_{2.43}(\pi_\omega) + \mathbb E_{p(c)}[\log Z(c)], \tag{2.67}
# $$
#
# where $J_{2.43}$ is the objective of Eq. 2.43. The last term does not depend on $\omega$, so
# minimising this KL is maximising Eq. 2.43, and the minimum $L = 0$ is reached at
# $\pi_\omega = \exp(R/\alpha)/Z$ — the answer of Section 2 — with $J_{2.43} = \alpha\,\mathbb E_{p(c)}[\log Z(c)]$.
# This is Eq. 2.58 with the Boltzmann distribution as target
# {cite:p}`levine2018reinforcement`.
#
# The check uses a discrete problem: 4 contexts, 7 candidate parameter vectors and a random
# return table. $J_{2.43}$ comes from the package's `F.maxent_objective` (a one-step MDP,
# $\gamma = 0$, whose states are the contexts and whose actions are the parameters); the KL
# and $\log Z$ are computed in the cell, for 100 random search distributions and for the
# Boltzmann one.

# %%
rng = np.random.default_rng(5)
n_ctx, n_par, alpha_erl = 4, 7, 0.6
R_ct = rng.normal(scale=2.0, size=(n_ctx, n_par))
p_ctx = rng.dirichlet(np.ones(n_ctx))
log_Z = logsumexp(R_ct / alpha_erl, axis=1)
boltzmann = np.exp(R_ct / alpha_erl - log_Z[:, None])
one_step = np.full((n_ctx, n_par, n_ctx), 1.0 / n_ctx)       # transitions are irrelevant at gamma = 0
rows = []
for pi_erl in [*rng.dirichlet(np.ones(n_par), size=(100, n_ctx)), boltzmann]:
    kl_term = p_ctx @ np.sum(xlogy(pi_erl, pi_erl) - pi_erl * np.log(boltzmann), -1)
    j_243 = F.maxent_objective(one_step, R_ct, pi_erl, 0.0, alpha_erl, rho0=p_ctx)
    rows.append((kl_term, -j_243 / alpha_erl + p_ctx @ log_Z, j_243))
rows = np.array(rows)
print(f"max |L - (-J/alpha + E log Z)| = {np.abs(rows[:, 0] - rows[:, 1]).max():.1e}")
print(f"Boltzmann: L = {rows[-1, 0]:.1e}, J = {rows[-1, 2]:.4f} = alpha E log Z = {alpha_erl * p_ctx @ log_Z:.4f}; "
      f"best random J = {rows[:-1, 2].max():.4f}")
assert np.abs(rows[:, 0] - rows[:, 1]).max() < 1e-10
assert abs(rows[-1, 0]) < 1e-12 and np.all(rows[:-1, 2] < rows[-1, 2])

# %% [markdown]
# **Step-based max-ent RL as inference (Eqs. 2.68–2.71).** Section 2 found the optimal policy
#
# (eq-2-68)=
# $$
# \pi^*(a_t\mid s_t) = \exp\Big(\frac1\alpha\big(Q^\pi_{\rm soft}(s_t, a_t) - V^\pi_{\rm soft}(s_t)\big)\Big). \tag{2.68}
# $$
#
# The same distribution solves a KL problem with the Boltzmann distribution of the soft
# Q-function as target, averaged over a state distribution $\rho(s)$:
#
# (eq-2-69)=
# $$
# L(\theta) = \mathbb E_{s\sim\rho(s)}\Big[\mathrm{KL}\Big(\pi_\theta(a\mid s)\,\Big\|\,\frac{\exp(Q^\pi_{\rm soft}(s, a)/\alpha)}{Z(s)}\Big)\Big],
# \qquad Z(s) = \int\exp(Q^\pi_{\rm soft}(s, a)/\alpha)\, da. \tag{2.69}
# $$
#
# Expanding the KL exactly as for Eq. 2.67 gives, per state,
# $-\frac1\alpha\big(\mathbb E_{\pi_\theta}[Q^\pi_{\rm soft}] + \alpha\mathcal H(\pi_\theta(\cdot\mid s))\big) + \log Z(s)$ — the per-state quantity that
# Section 2 maximised. The KL vanishes when the policy equals its target,
#
# (eq-2-70)=
# $$
# \pi^*(a\mid s) = \frac{\exp\big(Q^\pi_{\rm soft}(s, a)/\alpha\big)}{Z(s)}, \tag{2.70}
# $$
#
# (the thesis prints the normaliser inside the exponential, a typo). Since
# $V^\pi_{\rm soft}(s) = \alpha\log Z(s)$ by Eq. 2.41, dividing by $Z(s)$ is subtracting $V^\pi_{\rm soft}/\alpha$ in the exponent:
#
# (eq-2-71)=
# $$
# \pi^*(a\mid s) = \exp\Big(\frac1\alpha\big(Q^\pi_{\rm soft}(s, a) - V^\pi_{\rm soft}(s)\big)\Big), \tag{2.71}
# $$
#
# which is Eq. 2.68. The check compares Eqs. 2.70 and 2.71, confirms $L = 0$ at the candidate,
# compares with random policies and with a numerical (L-BFGS) minimiser of Eq. 2.69, and
# tests the KL identity for random policies.

# %%
show(F.check_maxent_as_inference(seed=0))

# %% [markdown]
# ## 8. Mutual-information skill discovery
#
# **Three forms (Eqs. 2.72–2.74).** The mutual information between a skill $z$ and a state $s$
# is the KL between their joint and the product of their marginals:
#
# (eq-2-72)=
# $$
# I(z, s) = \int p(z, s)\log\frac{p(z, s)}{p(z)\,p(s)}\, dz\, ds. \tag{2.72}
# $$
#
# Writing $p(z, s) = p(s)p(z\mid s)$ the ratio becomes $p(z\mid s)/p(z)$, and splitting the logarithm
# gives $I = \mathbb E_{p(z,s)}[\log p(z\mid s)] - \mathbb E_{p(z)}[\log p(z)]$:
#
# (eq-2-73)=
# $$
# I(z, s) = \mathcal H(p(z)) - \mathbb E_{p(s)}\big[\mathcal H(p(z\mid s))\big]. \tag{2.73}
# $$
#
# Writing $p(z, s) = p(z)p(s\mid z)$ instead gives the mirror image:
#
# (eq-2-74)=
# $$
# I(z, s) = \mathcal H(p(s)) - \mathbb E_{p(z)}\big[\mathcal H(p(s\mid z))\big]. \tag{2.74}
# $$
#
# **The variational bound.** The posterior $p(z\mid s)$ in Eq. 2.73 is usually intractable.
# For any $q_\phi(z\mid s)$, $\mathbb E_{p(z,s)}[\log p(z\mid s)] = \mathbb E_{p(z,s)}[\log q_\phi(z\mid s)] + \mathbb E_{p(s)}[\mathrm{KL}(p(z\mid s)\|q_\phi(z\mid s))]$,
# so dropping the non-negative KL gives the lower bound used by skill-discovery methods
# {cite:p}`eysenbach2019diversity`,
#
# $$
# I(z, s) \ge \mathcal H(p(z)) + \mathbb E_{p(z,s)}\big[\log q_\phi(z\mid s)\big],
# $$
#
# tight at $q_\phi = p(z\mid s)$. The check compares the three forms on a random discrete joint
# and the bound and its gap for random $q_\phi$.

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
# Each derivation above ends in a check: the cells written out in this notebook test the
# individual steps (the score-function gradient against a closed form, the soft Bellman
# fixed point against brute force, the free-energy identities behind Eqs. 2.38, 2.44 and
# 2.67, the responsibilities, the ELBO and the term-by-term diffusion KL), and the
# `F.check_*` reports test the results as a whole. The reports are also run by the test
# suite; together they take about a second. Here they run once more for a second seed.

# %%
reports = F.foundations_checks(seed=1)
for rep in reports:
    rep.require()
print(f"{sum(len(r) for r in reports)} checks in {len(reports)} groups pass for a second seed")
