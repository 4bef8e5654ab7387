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
# A companion to the thesis *Learning Versatile Skills using Reinforcement Learning*
# (Onur Celik). Each chapter notebook explains the chapter's idea in our own words,
# derives each lower bound and checks it numerically, runs the algorithms at a budget
# that fits the machine, and puts our figures next to the thesis's.
#
# | chapter | notebook | what it covers | modules |
# |---|---|---|---|
# | 2 Foundations | `02_foundations` | max-entropy RL, ERL vs SRL, curricula, ProMP/DMP/ProDMP, mixtures of experts, diffusion, variational inference, mutual information | `vslbook.bounds.foundations`, `vslbook.dists`, `vslbook.movement`, `vslbook.erl.pg`, `vslbook.envs` |
# | 3 SVSL | `03_svsl` | mixture of linear experts with per-expert context distributions: the bounds 3.4–3.7 checked, MORE / contextual MORE / REPS, Figs. 3.1, 3.2 (beer pong), 3.5, A.1 live | `vslbook.erl.svsl`, `vslbook.bounds.svsl`, `vslbook.experiments.svsl_*` |
# | 4 Di-SkilL | `04_diskill` (planned) | energy-based per-expert curricula, deep experts with trust-region projection layers | `vslbook.erl` |
# | 5 DIME | `05_dime` | the entropy lower bound of a diffusion policy and its gap, soft policy iteration, Figs. 5.1-5.3 and 5.7 live or from the published data, the chapter's ablations | `vslbook.bounds.dime`, `vslbook.srl`, `vslbook.envs.step_based`, `vslbook.experiments` |
#
# Numbers the thesis reports are always labelled as the thesis's; every other number
# in these notebooks is computed by the code in this repository when the notebook runs.

# %% [markdown]
# ## Budgets
#
# One environment variable decides how much compute the book spends. Budgets scale
# counts only (iterations, environment steps, seeds, bootstrap resamples), never an
# algorithm or a hyper-parameter.
#
# ```bash
# make book                          # default: VSLBOOK_BUDGET=reduced
# make book VSLBOOK_BUDGET=smoke     # every notebook in about a minute (what CI runs)
# VSLBOOK_BUDGET=full vslbook sweep ...   # the thesis's budgets, on a cluster
# ```

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
