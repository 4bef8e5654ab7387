"""Chapter 4's run sets at a budget and their learning curves (Figs. 4.3b, 4.3c, 4.4).

Each figure of Chapter 4 compares methods on one task (:data:`FIGURES`). :func:`counts`
gives what a budget changes (seeds, iterations, evaluation points; at ``smoke`` also the
experts and samples per expert, a "does it run" setting); every other number is the
thesis's (:func:`vslbook.erl.diskill_config.diskill_config`, Tables B.2-B.7).
:func:`figure_runs` declares each figure's runs at a budget (the ones ``vslbook run``
and ``vslbook plan`` name); :func:`run_set` trains them through
:func:`vslbook.training.run` (resumable, reused when finished) and :func:`curves` turns their test
rows into IQM curves with 95 % stratified-bootstrap intervals over seeds.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pandas as pd

from vslbook.budget import Budget, get_budget
from vslbook.erl.diskill_config import diskill_config
from vslbook.experiments.ch4_algorithms import DISKILL_ENVS

__all__ = [
    "FIGURES", "LABELS", "METRIC", "METRIC_LABELS", "PPO_TASKS", "REDUCED", "THESIS_AHEAD",
    "THESIS_OUTCOME",
    "counts", "curves", "env_id", "figure_runs", "load_model", "ppo_steps",
    "run_set",
]  # fmt: skip

#: figure → (task, methods) as in the thesis (PPO runs separately, step-based). Fig. 4.3b
#: also draws SVSL (Chapter 3's algorithm, 20 linear experts, Table B.1:
#: :mod:`vslbook.experiments.svsl_table_tennis_4d`).
FIGURES: dict[str, tuple[str, tuple[str, ...]]] = {
    "4.3b": ("table-tennis-4d", ("diskill", "bbrl", "diskill-v2", "diskill-v3", "svsl")),
    "4.3c": ("reacher5", ("diskill", "bbrl", "lindiskill")),
    "4.4a": ("hopper-jump", ("diskill", "bbrl", "lindiskill")),
    "4.4b": ("box-pushing-obstacle", ("diskill", "bbrl", "lindiskill")),
    "4.4c": ("table-tennis-hard", ("diskill", "bbrl", "lindiskill")),
    "4.4d": ("mini-golf", ("diskill", "bbrl", "lindiskill")),
}
#: method → the label of the thesis's figures.
LABELS = {
    "diskill": "Di-SkilL", "bbrl": "BBRL", "lindiskill": "LinDi-SkilL",
    "diskill-v2": "Di-SkilLV2", "diskill-v3": "Di-SkilLV3", "ppo": "PPO", "svsl": "SVSL",
}  # fmt: skip
#: figure → (method, method) pairs the thesis reports the first above the second at the
#: end of training (Section 4.5.3 and the caption of Fig. 4.3b). "On par" gives no pair:
#: hopper jump (Di-SkilL on par with BBRL, LinDi-SkilL similar after more samples).
#: Fig. 4.3b: "SVSL shows worse performance, even though the model has 20 experts"
#: (Section 4.5.2), as V3, which "needs more samples to reach the level of Di-SkilL".
THESIS_AHEAD: dict[str, tuple[tuple[str, str], ...]] = {
    "4.3b": (("diskill", "diskill-v2"), ("diskill", "diskill-v3"), ("diskill", "svsl")),
    "4.3c": (("diskill", "bbrl"), ("diskill", "lindiskill"), ("diskill", "ppo")),
    "4.4a": (),
    "4.4b": (("diskill", "lindiskill"), ("lindiskill", "bbrl"), ("diskill", "ppo")),
    "4.4c": (("diskill", "bbrl"), ("diskill", "lindiskill"), ("bbrl", "lindiskill")),
    "4.4d": (("diskill", "bbrl"), ("diskill", "lindiskill"), ("bbrl", "lindiskill")),
}
#: figure → the thesis's outcome in a line (the legend note of each panel).
THESIS_OUTCOME = {
    "4.3b": "thesis: BBRL ≳ Di-SkilL > V3 > V2; SVSL worse, needs more samples to reach "
    "about 80 % success",
    "4.3c": "thesis: Di-SkilL > BBRL > LinDi-SkilL, PPO poor",
    "4.4a": "thesis: Di-SkilL ≈ BBRL, LinDi-SkilL slower",
    "4.4b": "thesis: Di-SkilL > LinDi-SkilL > BBRL, PPO poor",
    "4.4c": "thesis: Di-SkilL slightly > BBRL at the end > LinDi-SkilL",
    "4.4d": "thesis: Di-SkilL > BBRL > LinDi-SkilL",
}
#: What a metric of the runs measures, in words (the figures' axis labels).
METRIC_LABELS = {
    "test_return": "test return", "test_success": "test success rate",
    "test_max_height": "maximal height [m]", "test_goal_distance": "goal distance [m]",
}  # fmt: skip
#: figure → what its panel plots: the test return (5LR, hopper jump) or success rate.
METRIC = {
    "4.3b": "test_success", "4.3c": "test_return", "4.4a": "test_return",
    "4.4b": "test_success", "4.4c": "test_success", "4.4d": "test_success",
}  # fmt: skip
#: tasks where the thesis also runs step-based PPO (Figs. 4.3c and 4.4b; Tables B.3, B.6).
PPO_TASKS = ("reacher5", "box-pushing-obstacle")


def env_id(task: str) -> str:
    """The one-step gymnasium id of a Chapter 4 task."""
    for env, name in DISKILL_ENVS.items():
        if name == task:
            return env
    raise ValueError(
        f"task {task!r} has no Di-SkilL preset; expected one of {sorted(DISKILL_ENVS.values())}"
    )


#: task → (share of the thesis's iterations, most experts) at the reduced budget: the
#: 5-link reacher keeps its 10 experts and gets 10 % of the iterations (300), because the
#: qualitative result of Fig. 4.2 / 4.3c must show and Di-SkilL passes BBRL only after
#: about 200 iterations: at 300, seeds 0-2 end at −7.0 / −6.0 / −7.7 against BBRL's
#: −17.3 / −16.2 / −12.7; at 150, the 5 % this preset used to give, BBRL was ahead (IQM
#: over five seeds −22.1 against −20.9). The tasks with slower episodes get 2 % and at most
#: 5 experts (an iteration of box pushing with 10 experts runs 500 episodes, about 25 s on
#: one core). Their success panels stay at 0 at this share: a probe of table tennis
#: (Di-SkilL, seed 0, 600 iterations, 13 %) had a test return of 0.17 at 90 and 200
#: iterations (no hit; most samples still rejected as invalid), 0.49 at 300, 1.6 at 450 and
#: 2.1 at 600 (the ball hit, returns beginning to land), and a test success of 0 throughout.
REDUCED = {
    "reacher5": (0.10, None),
    "table-tennis-4d": (0.02, None),
    "table-tennis-hard": (0.02, 5),
    "hopper-jump": (0.02, None),
    "box-pushing-obstacle": (0.02, 5),
    "mini-golf": (0.02, 5),
}


def counts(task: str, method: str, budget: Budget | str | None = None) -> dict[str, Any]:
    """What a budget sets for ``method`` on ``task`` (the rest is the thesis's).

    * full: the thesis's iterations, its 24 seeds (Section 4.5.3; Fig. 4.3b: "at least 4",
      we use 24 there too), evaluation every 5 iterations on 75 contexts (the authors');
    * reduced: 3 seeds, evaluation every 5 iterations, and the share of iterations and
      experts of :data:`REDUCED` (at least 20 iterations);
    * smoke ("does it run"): 2 iterations of at most 2 experts with 4 samples each,
      1 seed, evaluation after each iteration on 10 contexts.

    SVSL (Fig. 4.3b) takes its own counts
    (:func:`vslbook.experiments.svsl_table_tennis_4d.svsl_counts`, the same seeds and test
    contexts), with ``iterations`` its N·K + weight iterations at the budget.
    """
    b = get_budget(budget)
    if method == "svsl":
        return _svsl_counts(task, b)
    cfg = diskill_config(task, method)
    share, most = REDUCED[task]
    out: dict[str, Any] = {
        "seeds": b.pick(smoke=1, reduced=3, full=24),
        "iterations": b.pick(
            smoke=2, reduced=max(20, round(share * cfg.iterations)), full=cfg.iterations
        ),
        "test_every": b.pick(smoke=1, reduced=5, full=5),
        "test_contexts": b.pick(smoke=10, reduced=75, full=75),
    }
    if b.name == "smoke":
        out["n_experts"] = min(cfg.n_experts, 2)
        out["samples_per_expert"] = 4
    elif b.name == "reduced" and most is not None and cfg.n_experts > most:
        out["n_experts"] = most
    return out


def _svsl_counts(task: str, b: Budget) -> dict[str, Any]:
    """:func:`counts` of SVSL: its counts at ``b`` and ``iterations``, N·K + weight
    iterations (Chapter 4's table tennis only)."""
    from vslbook.experiments import svsl_table_tennis_4d as TT

    if task != TT.TASK:
        raise ValueError(f"SVSL runs on {TT.TASK} in Chapter 4 (Fig. 4.3b), not on {task!r}")
    c = TT.svsl_counts(b)
    return c | {"iterations": TT.svsl_tt_config(b).total_iterations}


def figure_runs(figure: str, budget: Budget | str | None = None) -> list[Any]:
    """The runs Fig. ``figure`` (``fig4-3b`` ... ``fig4-4d``, or ``4.3b`` ...) draws at
    ``budget``, as :class:`vslbook.experiments.run_plan.FigureRun` values: each method of
    :data:`FIGURES` with :func:`counts`'s seeds (SVSL's length in its iterations, N·K plus
    the weight iterations), and PPO where the thesis runs it (on box
    pushing only above ``smoke``: one rollout takes about 15 s there). They carry no
    overrides: ``vslbook run METHOD --env ENV --seed S --budget B`` trains the same runs."""
    from vslbook.experiments.ch4_algorithms import PPO_ENVS
    from vslbook.experiments.run_plan import FigureRun

    key = figure.removeprefix("fig").replace("-", ".")
    if key not in FIGURES:
        raise ValueError(f"unknown figure {figure!r}; expected one of {sorted(FIGURES)}")
    b = get_budget(budget)
    fig_id = "fig" + key.replace(".", "-")
    task, methods = FIGURES[key]
    runs = []
    for method in methods:
        c = counts(task, method, b)
        runs += [FigureRun(fig_id, method, method, env_id(task), seed, b.name, c["iterations"])
                 for seed in range(c["seeds"])]  # fmt: skip
    if task == "reacher5" or (task in PPO_TASKS and b.name != "smoke"):
        env = next(e for e, t in PPO_ENVS.items() if t == task)
        runs += [FigureRun(fig_id, "ppo", "ppo-ch4", env, seed, b.name, ppo_steps(task, b),
                           unit="env_steps")
                 for seed in range(counts(task, "diskill", b)["seeds"])]  # fmt: skip
    return runs


def run_set(
    figure: str,
    budget: Budget | str | None = None,
    root: str | Path = "runs",
    *,
    methods: tuple[str, ...] | None = None,
    progress: bool = False,
) -> dict[str, list[Path]]:
    """Train (or reuse) every run of ``figure`` (``4.3b`` or ``fig4-3b``) at ``budget``
    (:func:`figure_runs`): method → run directories; ``methods`` picks some of them.
    :func:`vslbook.experiments.figure_sources.figure_set` in mode ``retrain``."""
    from vslbook.experiments.figure_sources import figure_set

    fig_id = "fig" + figure.removeprefix("fig").replace(".", "-")
    return figure_set(fig_id, budget, root, methods=methods, mode="retrain",
                      progress=progress).runs  # fmt: skip


def ppo_steps(task: str, budget: Budget | str | None = None) -> int:
    """PPO's environment steps on ``task`` at a budget, in whole rollouts of 16384 steps.

    * full: as many episodes as Di-SkilL's full run
      (:func:`vslbook.erl.ppo_ch4.matched_total_steps`);
    * reduced: as many episodes as Di-SkilL's run at this budget, but at most the budget's
      share (5 %) of the full run's steps. PPO is the costliest run of its figure (5LR at
      5 %: 7.5M steps, about 36 minutes a seed on one core), so on 5LR, where Di-SkilL gets
      10 % of its iterations (:data:`REDUCED`), PPO's curve spans half of Fig. 4.3c's
      episode axis; on box pushing (2 % of the iterations with 5 of the 10 experts) it
      matches Di-SkilL's episodes;
    * smoke: one rollout.
    """
    from vslbook.erl.ppo_ch4 import N_ROLLOUT_STEPS, matched_total_steps

    if task not in PPO_TASKS:
        raise ValueError(f"the thesis runs PPO on {PPO_TASKS}, not on {task!r}")
    b = get_budget(budget)
    if b.name == "full":
        return matched_total_steps(task)
    if b.name == "smoke":
        return N_ROLLOUT_STEPS
    c = counts(task, "diskill", b)
    cfg = diskill_config(task, "diskill", **{k: v for k, v in c.items() if k != "seeds"})
    horizon = {"reacher5": 200, "box-pushing-obstacle": 100}[task]
    steps = min(cfg.iterations * cfg.episodes_per_iteration * horizon,
                round(b.fraction * matched_total_steps(task)))  # fmt: skip
    return -(-steps // N_ROLLOUT_STEPS) * N_ROLLOUT_STEPS


def curves(
    runs: dict[str, list[Path]], y: str = "test_return", *, reps: int | None = None
) -> pd.DataFrame:
    """IQM over seeds with 95 % stratified-bootstrap CIs of ``y`` against executed episodes,
    one row per (method label, grid point)."""
    from vslbook.experiments.svsl_mixtures import learning_curves

    labelled = {LABELS[m]: v for m, v in runs.items()}
    return learning_curves(labelled, y, reps=reps, methods=tuple(LABELS.values()))


def load_model(path: str | Path) -> Any:
    """The trained :class:`~vslbook.erl.diskill.DiSkill` of a run directory (last checkpoint)."""
    from vslbook.envs.robot import make_task
    from vslbook.erl.diskill import DiSkill
    from vslbook.experiments.ch4_algorithms import DiSkillRun
    from vslbook.registry import config_from_record
    from vslbook.results import RunDir

    rd = RunDir.open(path)
    record = rd.config
    config = config_from_record(DiSkillRun, record)
    task = make_task(DISKILL_ENVS[record["env"]])
    model = DiSkill(task, config, int(record["seed"]), workers=0)
    saved = rd.load_checkpoint()
    if saved is None:
        raise FileNotFoundError(f"{rd.path} has no checkpoint to load")
    model.load_state_dict(saved["diskill"])
    return model
