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
# # vslbook — the map of the book
#
# A companion to the PhD thesis *Learning Versatile Skills using Reinforcement Learning*
# {cite:p}`celik2025learning`. Each chapter notebook explains the chapter's idea in our
# own words, derives every lower bound step by step and checks it numerically, runs the
# algorithms at a budget that fits the machine, and puts our figures next to the thesis's.
# The importable package `vslbook` holds everything the notebooks run; a notebook only
# calls it.
#
# ## What the thesis contributes
#
# A robot that masters a task in *one* way breaks when that way is blocked; a robot with
# several ways, each tuned to the situation, does not. The thesis learns such **versatile
# skills** with maximum-entropy reinforcement learning, twice on the level of whole
# episodes (a movement primitive's parameters chosen once per episode) and once step by
# step:
#
# - **SVSL (Chapter 3)** {cite:p}`celik2022specializing`: a mixture of linear-Gaussian
#   experts, each with its own Gaussian distribution over the contexts it practises on.
#   Rewriting the maximum-entropy objective through Bayes' rule and bounding it from below
#   with variational responsibilities gives one bound per expert, per context
#   distribution and for the weights: each part of the mixture is updated on its own
#   (MORE, contextual MORE, REPS), experts are added one at a time, and each expert
#   becomes a local specialist that other experts are pushed away from.
# - **Di-SkilL (Chapter 4)** {cite:p}`celik2024acquiring`: the same idea with deep
#   experts, energy-based per-expert context distributions that form an automatic
#   curriculum without knowing the context space's bounds, and trust-region projection
#   layers {cite:p}`otto2021differentiable` for stable updates.
# - **DIME (Chapter 5)** {cite:p}`celik2025dime`: a diffusion model as the policy of
#   off-policy maximum-entropy RL. Its marginal entropy is intractable; a lower bound
#   through the denoising chain and a matching forward (noising) chain makes soft policy
#   iteration possible, with a distributional CrossQ critic {cite:p}`bhatt2024crossq`.
#
# Chapter 2 lays the foundations all three share: episode-based against step-based RL,
# the maximum-entropy objective, self-paced curricula, movement primitives, mixtures of
# experts, diffusion models and variational inference.
#
# ## The map: chapters → notebooks → modules → figures
#
# | thesis | notebook | modules | figures here |
# |---|---|---|---|
# | Ch. 2 Foundations | [`02_foundations`](02_foundations.ipynb) | `vslbook.bounds.foundations`, `vslbook.dists`, `vslbook.movement`, `vslbook.erl.pg`, `vslbook.envs` | ERL against SRL learning curves, movement primitives (ProMP / DMP / ProDMP), diffusion forward process, live |
# | Ch. 3 SVSL | [`03_svsl`](03_svsl.ipynb) | `vslbook.erl.svsl` (Algorithm 1), `svsl_model`, `more`, `surrogate`, `reps`, `hireps`, `ladips`, `ppo`; `vslbook.bounds.svsl`; `vslbook.experiments.svsl_*`; `vslbook.envs.robot` | Figs. 3.1, 3.2 (beer pong, table tennis), 3.5, A.1, A.2, live |
# | Ch. 4 Di-SkilL | `04_diskill` (planned) | `vslbook.erl` | — |
# | Ch. 5 DIME | [`05_dime`](05_dime.ipynb) | `vslbook.srl` (diffusion policy, distributional CrossQ critic, BatchRenorm, the loop `srl.dime`), `vslbook.bounds.dime`, `vslbook.envs.step_based`, `vslbook.experiments` | Fig. 5.1, 5.7 and the ablations (5.2c, 5.4, 5.6, 5.8, C.2) live; Figs. 5.2a–b and 5.3 from the published runs next to ours |
#
# The [bibliography](bibliography.md) lists the works the notebooks cite. Numbers the
# thesis reports are always labelled as the thesis's; every other number in these
# notebooks is computed by the code in this repository when the notebook runs.

# %% [markdown]
# ## Budgets
#
# One environment variable decides how much compute the book spends. Budgets scale
# counts only (iterations, environment steps, seeds, bootstrap resamples), never an
# algorithm or a hyper-parameter; a smaller network for a CPU is a *named configuration*
# that a notebook picks in plain sight.
#
# ```bash
# make book                          # the site at the default budget, VSLBOOK_BUDGET=reduced
# make book VSLBOOK_BUDGET=smoke     # every notebook in a few minutes (what CI runs)
# VSLBOOK_BUDGET=full vslbook sweep ...   # the thesis's budgets, on a cluster
# ```
#
# What each notebook runs, and how long it took on a 2-core x86_64 CPU (no GPU), the
# machine CI runs on:
#
# | notebook | `smoke` | `reduced` |
# |---|---|---|
# | `02_foundations` | ERL against SRL on the point-reach task, smoke counts; about 30 s | the same at 5 % of the thesis's counts |
# | `03_svsl` | every SVSL figure at a few iterations, 2 seeds; 30–100 s | Figs. 3.1, 3.2, 3.5 at 5 % of the thesis's counts, 3 seeds; about 1.5 h (estimated from the per-iteration times, not yet measured end to end) |
# | `05_dime` | two DIME seeds of a few hundred steps, the ablations at smoke counts; about 85 s | cheetah-run 3 × 50k steps (`cpu-256`), eight Pendulum ablations, three point-mass runs; about 3 h from scratch |
#
# A second `make book` executes only the notebooks whose code changed (an execution cache
# per budget) and every finished training run is reused from `runs/`.

# %%
from vslbook.budget import BUDGETS, get_budget

active = get_budget()
print(f"active budget: {active.name}")
for b in BUDGETS.values():
    print(f"  {b.name:8s} {b.fraction:>7.3f} of the thesis's counts, {b.seeds:2d} seeds, "
          f"{b.bootstrap_reps:>6d} bootstrap resamples")

# %% [markdown]
# ## Algorithms and figures available from the command line
#
# `vslbook run ALGO --env ENV --seed S --budget B` trains into a run directory that an
# interrupted run resumes from; `vslbook figure ID` redraws a figure into `build/figures`.

# %%
from vslbook.registry import ALGORITHMS, FIGURES, load_plugins

load_plugins()
for name, algo in sorted(ALGORITHMS.items()):
    print(f"run     {name:22s} {algo.doc}")
for fig_id, fig in sorted(FIGURES.items()):
    print(f"figure  {fig_id:22s} {fig.doc}")
assert ALGORITHMS and FIGURES, "the registries should not be empty"

# %% [markdown]
# ## Using the package in your own analysis
#
# ```python
# import vslbook
# from vslbook.results import paper_curves
# from vslbook.stats import iqm_curve
#
# curve = iqm_curve(paper_curves("dmc_humanoid_run"))   # the published DIME runs, IQM + 95 % CI
# vslbook.show_source(iqm_curve)                        # read the implementation inline
# ```
