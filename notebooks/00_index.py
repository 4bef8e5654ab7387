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
# | Chs. 3–4 tasks | [`01_tasks`](01_tasks.ipynb) | `vslbook.envs.robot` (every task; `render` for the pictures) | a picture of each MuJoCo scene, live |
# | Ch. 2 Foundations | [`02_foundations`](02_foundations.ipynb) | `vslbook.bounds.foundations`, `vslbook.dists`, `vslbook.movement`, `vslbook.erl.pg`, `vslbook.envs` | ERL against SRL learning curves, movement primitives (ProMP / DMP / ProDMP), diffusion forward process, live |
# | Ch. 3 SVSL | [`03_svsl`](03_svsl.ipynb) | `vslbook.erl.svsl` (Algorithm 1), `svsl_model`, `more` (`more_dual`), `surrogate`, `reps`, `hireps`, `ladips`, `ppo`; `vslbook.bounds.svsl`; `vslbook.experiments.svsl_*`; `vslbook.envs.robot` | Figs. 3.1, 3.2 (beer pong, table tennis), 3.3 (rendered), 3.5, A.1, A.2, live |
# | Ch. 4 Di-SkilL | [`04_diskill`](04_diskill.ipynb) | `vslbook.erl.diskill` (Algorithms 2, 3), `diskill_nets`, `diskill_config`, `trpl` (trust-region projection), `ppo_ch4`; `vslbook.bounds.diskill`; `vslbook.experiments.diskill_*`, `ch4_algorithms`, `svsl_experts`; `vslbook.envs.robot` | Figs. 4.2, 4.3b, 4.3c, 4.4, live |
# | Ch. 5 DIME | [`05_dime`](05_dime.ipynb) | `vslbook.srl` (diffusion policy, distributional CrossQ critic, BatchRenorm, Algorithm 4 as a loop `srl.dime_loop`, several seeds in one process `srl.seed_axis` and `srl.dime_seeds`, CUDA graphs `srl.cuda_graphs`), `vslbook.bounds.dime`, `vslbook.envs.step_based`, `vslbook.experiments` | Fig. 5.1, 5.7 and the ablations (5.2c, 5.4, 5.6, 5.8, C.2) live; Figs. 5.2a–b and 5.3 from the published runs next to ours |
#
# The [bibliography](bibliography.md) lists the works the notebooks cite. Numbers the
# thesis reports are always labelled as the thesis's; every other number in these
# notebooks is computed by the code in this repository when the notebook runs.

# %% [markdown]
# ## Derivations and where they are checked
#
# Every result the thesis derives is derived again, step by step, in its chapter's
# notebook, numbered like the thesis (the equation links below jump to it). Each step is
# algebra or a numerical check placed right after it; a failing check stops the notebook,
# and so the book. The last column names the test in `tests/` that checks the same formula
# against an independent computation (— where only the notebook checks it).
#
# | equations | notebook section | check in the notebook | test |
# |---|---|---|---|
# | [2.29](#eq-2-29)–[2.33](#eq-2-33) ERL gradient, baseline | 2 §1 | score-function estimate of a Gaussian's gradient on a quadratic return against the exact gradient; the baseline lowers every standard error | — |
# | [2.39](#eq-2-39)–[2.42](#eq-2-42) soft Bellman, Boltzmann policy | 2 §2 | fixed-point residual of soft value iteration; brute force over the action simplex against $V^*=\alpha\log Z$; $V^{\pi'}-V^*$ identity | `test_bounds_foundations.py::test_soft_value_iteration_limits` |
# | [2.44](#eq-2-44) self-paced objective | 2 §3 | objective $=\beta\log Z_\beta-\beta\,\mathrm{KL}(\pi\|\pi^*)$ for random curricula; the closed-form optimum | `test_bounds_foundations.py::test_self_paced_optimum_limits` |
# | [2.47](#eq-2-47)–[2.49](#eq-2-49) mixture gating | 2 §5 | Bayes responsibilities of `LinearGaussianMoE` against scipy densities | `test_dists.py::test_gating_is_bayes_rule` |
# | [2.51](#eq-2-51)–[2.55](#eq-2-55) Ornstein–Uhlenbeck forward process | 2 §6 | closed-form marginals against simulated chains | `test_bounds_foundations.py::test_wrong_ou_variance_formula_fails` |
# | [2.56](#eq-2-56)–[2.57](#eq-2-57) ELBO | 2 §7 | log-evidence $=$ ELBO $+$ KL on a conjugate Gaussian model | — |
# | [2.60](#eq-2-60)–[2.61](#eq-2-61) KL chain rule | 2 §7 | joint KL against marginal plus conditional KL | `test_bounds_foundations.py::test_kl_that_ignores_means_breaks_the_chain_rule` |
# | [2.64](#eq-2-64) mixture E-step bound | 2 §7 | bound below the objective, tight at the responsibilities | `test_bounds_foundations.py::test_non_tight_variational_distribution_fails` |
# | [2.65](#eq-2-65)–[2.66](#eq-2-66) KL of diffusion chains | 2 §7 | term-by-term sum against the joint-Gaussian KL; Monte Carlo | `test_bounds_foundations.py::test_diffusion_kl_with_wrong_kernel_variance_fails` |
# | [2.67](#eq-2-67) episode-based RL as inference | 2 §7 | KL $=-J/\alpha+\mathbb E\log Z$ on a discrete problem | — |
# | [2.68](#eq-2-68)–[2.71](#eq-2-71) step-based RL as inference | 2 §7 | the Boltzmann policy solves the inference problem | `test_bounds_foundations.py::test_policy_at_wrong_temperature_is_not_the_inference_solution` |
# | [3.1](#eq-3-1)–[3.4](#eq-3-4), [A.2](#eq-A-2) SVSL decomposition | 3 §1 | Eq. 3.4 against a Monte-Carlo estimate of Eq. 3.3 | `test_bounds_svsl.py::test_decomposition_equals_a_monte_carlo_estimate_of_eq_3_3` |
# | [A.4](#eq-A-4), [3.5](#eq-3-5) expert bound | 3 §2 | bound below the objective, tight at the old model; improvements carry over | `test_bounds_svsl.py::test_expert_objective_with_flipped_responsibility_sign_fails` |
# | [3.6](#eq-3-6) context-distribution bound | 3 §3 | the same for $\pi(c\mid o)$ | `test_bounds_svsl.py::test_context_objective_missing_responsibility_term_fails` |
# | [3.7](#eq-3-7), A.5–A.7 weights, REPS | 3 §4 | bound on $\pi(o)$; the REPS update against the expected softmax | `test_bounds_svsl.py::test_weight_objective_maximiser_is_softmax` |
# | MORE, contextual MORE | 3 §5 | MORE on a quadratic reward reaches the analytic optimum | `test_erl_more.py::test_more_reaches_analytic_optimum_with_large_eps` |
# | [4.2](#eq-4-2)–[4.3](#eq-4-3), [B.1](#eq-B-1) curriculum objective | 4 §1 | Eq. B.1 term by term against Eq. 4.3 from the mixture densities (quadrature); the bound's gap is $\alpha\,\mathbb E[\mathrm{KL}_\theta]+(\beta-\alpha)\,\mathbb E[\mathrm{KL}_c]$ | `test_bounds_diskill.py::test_eq_b1_equals_a_monte_carlo_estimate_of_eq_4_3` |
# | [4.4](#eq-4-4) expert bound | 4 §2 | bound below Eq. 4.3, tight at the old model; improvements carry over | `test_bounds_diskill.py::test_expert_objective_without_entropy_bonus_fails` |
# | [4.5](#eq-4-5) context-distribution bound | 4 §2 | the same for the energies $\phi_o$; needs $\beta\ge\alpha$ | `test_bounds_diskill.py::test_beta_below_alpha_breaks_the_bound` |
# | [4.6](#eq-4-6) energy-based $\pi(c\mid o)$, Bayes gating | 4 §3 | Monte-Carlo normaliser against quadrature in 1-D and 2-D; gating from batch-normalised categoricals | `test_bounds_diskill.py::test_normaliser_and_entropy_against_the_trapezoid_rule` |
# | [4.7](#eq-4-7) trust-region projection | 4 §4 | KL within its bounds after projection, the identity inside | `test_erl_trpl.py::test_bounds_hold_on_random_gaussians`, `test_gradcheck_project_cov` |
# | [4.8](#eq-4-8) sample form of the context objective | 4 §5 | Eq. 4.8 over samples of $p(c)$ against Eq. 4.5 by quadrature | `test_bounds_diskill.py::test_wrong_sample_objectives_fail` |
# | [5.9](#eq-5-9)–5.10 denoising score matching | 5 §1 | the average conditional score is the marginal score; Eq. 5.9 minus the explicit loss is a constant; the fitted score against the exact one | `test_bounds_dime_bridges.py::test_minimiser_of_eq_5_9_over_affine_scores_is_the_marginal_score` |
# | [C.1](#eq-C-1)–[C.3](#eq-C-3), [5.15](#eq-5-15) entropy lower bound | 5 §1.2 | Monte-Carlo and closed-form $\ell\le\mathcal H$ on a linear-Gaussian chain; the gap equals the chains' KL | `test_bounds_dime.py::test_wrong_bound_estimator_fails` |
# | [C.29](#eq-C-29)–[C.30](#eq-C-30) tanh correction | 5 §1.3 | squashed entropy by quadrature against $\ell$ plus the log-Jacobian | `test_srl_components.py::test_squash_adds_tanh_correction_to_running_cost` |
# | [5.16](#eq-5-16)–[5.20](#eq-5-20), [C.11](#eq-C-11) the inference problem | 5 §1.4 | joint KL $=-\mathbb E[Q]-\ell+\log Z$; marginal KL below joint KL | `test_bounds_dime.py::test_check_passes` |
# | [5.21](#eq-5-21), Prop. 5.4.1 policy evaluation | 5 §2 | the backup with $\alpha\ell$ contracts at rate $\gamma$ to the series of Eq. 5.17 | `test_bounds_dime_policy_iteration.py::test_wrong_sign_of_the_bound_in_the_backup_fails_prop_541` |
# | [5.22](#eq-5-22), Prop. 5.4.2 policy improvement | 5 §2 | $Q_{\rm new}\ge Q_{\rm old}$ everywhere; the step beats random members of the family | `test_bounds_dime_policy_iteration.py::test_improvement_away_from_the_target_fails_prop_542` |
# | Prop. 5.4.3 policy iteration | 5 §2 | monotone, ends at the family's optimum found by value iteration | `test_bounds_dime_policy_iteration.py::test_no_improvement_is_monotone_but_not_optimal` |
# | [5.29](#eq-5-29)–[5.38](#eq-5-37) general bridges | 5 §5c | ℓ and Eq. 5.37 by Monte Carlo against exact values (affine, 2-D) and grid quadrature (double well, 1-D); DIME and the library's policy as special cases | `test_bounds_dime_bridges.py::test_transfer_quadrature_against_brute_force_grid`, `test_policy_bridge_reproduces_the_library_entropy_bound` |
# | [5.24](#eq-5-24)–[5.28](#eq-5-28) practical losses | 5 §2b | critic, actor and $\alpha$ losses of a tiny agent against the formulas computed in the cell | `test_dime_update_maths.py::test_actor_loss_and_gradient_follow_eq_5_27` |

# %% [markdown]
# ## Budgets, and where the figures' runs come from
#
# One environment variable decides how much compute the book spends. Budgets scale
# counts only (iterations, environment steps, seeds, bootstrap resamples), never an
# algorithm or a hyper-parameter; a smaller network for a CPU is a *named configuration*
# that a notebook picks in plain sight.
#
# ```bash
# make book                          # figures from recorded runs (data/results/), the rest at reduced
# make book VSLBOOK_BUDGET=smoke     # every notebook at smoke, what CI runs
# make book RETRAIN=1                # train every run of the budget (the plan's core-hours first)
# vslbook train fig4-3c --budget full --jobs 2   # the thesis's budget, one run per core
# ```
#
# The long run sets of Chapters 3–5 take hours to days of CPU, so by default a figure draws
# the runs recorded in `data/results/` (the largest budget recorded, with their provenance)
# or finished in `runs/`, and trains smoke runs only where neither exists; each figure
# prints where its runs came from (`vslbook.experiments.figure_sources`). The derivations,
# the checks and the cheap live runs always execute. How long each notebook and its run
# sets took on a 2-core x86_64 CPU, the machine CI runs on (measured while this code was
# written; `data/measurements/notebook_times.csv`, with its provenance):

# %%
from IPython.display import display

from vslbook.data import measurements

times = measurements("notebook_times.csv")
times["wall"] = [f"{s / 3600:.1f} h" if s >= 3600 else f"{s / 60:.0f} min" if s >= 120
                 else f"{s:.0f} s" for s in times["wall_seconds"]]  # fmt: skip
display(times.drop(columns="wall_seconds").fillna(""))
reduced = times[(times["budget"] == "reduced") & (times["runs"] == "trained")]
print(f"every run set at reduced from scratch: {reduced['wall_seconds'].sum() / 3600:.1f} h of "
      "wall time (cores as listed); the default book reads recorded runs instead")

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
# from vslbook.data import paper_curves
# from vslbook.stats import iqm_curve
#
# curve = iqm_curve(paper_curves("dmc_humanoid_run"))   # the published DIME runs, IQM + 95 % CI
# vslbook.show_source(iqm_curve)                        # read the implementation inline
# ```
