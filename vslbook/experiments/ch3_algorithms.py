"""Chapter 3's algorithms as ``vslbook run`` / ``vslbook sweep`` entries.

    vslbook run svsl   --env vslbook/BeerPong-v0 --seed 0 --budget reduced
    vslbook run svsl   --env vslbook/PlanarReacher-v0 --set responsibilities=false
    vslbook run hireps --env vslbook/TableTennisCh3-v0 --budget full
    vslbook run svsl   --env vslbook/Reacher5Ch3-v0 --set reward=3.10
    vslbook run ppo    --env vslbook/Reacher5Ch3Step-v0 --set reward=3.8
    vslbook run svsl   --env vslbook/TableTennis4D-v0 --budget smoke

SVSL also runs on Chapter 4's table tennis (``vslbook/TableTennis4D-v0``), its curve in
Fig. 4.3b, with Table B.1's hyper-parameters and the counts of
:func:`vslbook.experiments.svsl_table_tennis_4d.svsl_counts`; the baselines do not.

Registered here: ``svsl`` (Algorithm 1, Appendix A.2), ``hireps`` and ``ladips`` (the
baselines of Fig. 3.2, Tables A.2 and A.3) and ``ppo`` (Fig. 3.5, Table A.5). The
configuration of a run is the one the Chapter 3 notebook trains at the same budget: the
thesis's hyper-parameters (:func:`vslbook.erl.svsl.svsl_config`, the baselines' task
presets, :class:`vslbook.erl.ppo.PPOConfig`) with the counts of that figure's
``*_counts(budget)`` function (N, K, weight iterations, baseline iterations, PPO steps,
test points). Unlike DIME's configs, these hold the budget's counts themselves: ``--set
n_experts=5`` means five experts at any budget. The run directory (``runs/`` by default) is
:func:`vslbook.training.run`'s: named after algorithm, env, seed, budget and configuration,
resumed from its checkpoint when interrupted.

Each algorithm's config class is the algorithm's own with the run's options added:

* :class:`SVSLRun` — ``reward`` of the 5-link reacher (Eqs. 3.8-3.10; required there);
* :class:`HiREPSRun`, :class:`LaDiPSRun` — ``test_every`` and ``test_contexts``: the
  baselines are tested as often as SVSL over their run, θ ~ π(θ | c) on fixed contexts;
* :class:`PPORun` — ``reward``, ``eval_every`` (environment steps) and ``eval_episodes``
  (the fixed evaluation goals SVSL is also tested on).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from vslbook.budget import Budget
from vslbook.erl.hireps import HiREPSConfig
from vslbook.erl.ladips import LaDiPSConfig
from vslbook.erl.ppo import PPOConfig
from vslbook.erl.svsl_config import SVSLConfig
from vslbook.registry import config_from_record, register_algorithm
from vslbook.results import RunDir

__all__ = ["EntropyProbe", "HiREPSRun", "LaDiPSRun", "PPORun", "SVSLRun", "env_of",
           "final_metrics", "task_counts", "task_of"]

#: Rewards of the Chapter 3 5-link reacher (Eqs. 3.8, 3.9, 3.10).
REWARDS = ("3.8", "3.9", "3.10")

#: env id → task name (:data:`vslbook.envs.robot.TASKS`) for each algorithm.
SVSL_ENVS = {
    "vslbook/PlanarReacher-v0": "planar-reacher",
    "vslbook/BeerPong-v0": "beer-pong",
    "vslbook/TableTennisCh3-v0": "table-tennis-ch3",
    "vslbook/Reacher5Ch3-v0": "reacher5-ch3",
    "vslbook/TableTennis4D-v0": "table-tennis-4d",  # Chapter 4's table tennis (Fig. 4.3b)
}
HIREPS_ENVS = {k: v for k, v in SVSL_ENVS.items()
               if v not in ("reacher5-ch3", "table-tennis-4d")}  # fmt: skip
LADIPS_ENVS = {k: v for k, v in HIREPS_ENVS.items() if v != "planar-reacher"}
PPO_ENVS = {"vslbook/Reacher5Ch3Step-v0": "reacher5-ch3"}


def _check_reward(reward: Any, env: str, required: bool) -> str | None:
    if reward is None and not required:
        return None
    if reward not in REWARDS:
        raise ValueError(
            f"{env} needs reward= one of {', '.join(REWARDS)} (Eqs. 3.8-3.10), got {reward!r}"
        )
    return str(reward)


@dataclass(frozen=True)
class EntropyProbe:
    """Where a run estimates the expected mixture entropy E_c H[π(θ | c)] at its test
    points (Figs. A.1, A.2; :func:`vslbook.experiments.svsl_context.entropy_contexts`):
    ``entropy_draws`` θ per context on an ``entropy_grid`` of cells or on
    ``entropy_contexts`` draws from p(c), at every ``entropy_every``-th test point. None:
    not estimated."""

    entropy_draws: int | None = None
    entropy_grid: tuple[int, ...] | None = None
    entropy_contexts: int | None = None
    entropy_every: int = 1

    def entropy_spec(self) -> dict[str, Any] | None:
        """The probe as the dict :func:`entropy_contexts` reads, or None."""
        if self.entropy_draws is None:
            return None
        spec: dict[str, Any] = {"entropy_draws": self.entropy_draws,
                                "entropy_every": self.entropy_every}  # fmt: skip
        if self.entropy_grid is not None:
            spec["entropy_grid"] = list(self.entropy_grid)
        else:
            spec["entropy_contexts"] = self.entropy_contexts
        return spec


def _entropy_fields(counts: dict[str, Any]) -> dict[str, Any]:
    """The :class:`EntropyProbe` fields of a task's counts (beer pong, table tennis; none
    where the counts have no ``entropy_draws``: Chapter 4's table tennis)."""
    return {"entropy_draws": counts.get("entropy_draws"),
            "entropy_grid": tuple(counts["entropy_grid"]) if "entropy_grid" in counts else None,
            "entropy_contexts": counts.get("entropy_contexts"),
            "entropy_every": counts.get("entropy_every", 1)}  # fmt: skip


@dataclass(frozen=True)
class SVSLRun(EntropyProbe, SVSLConfig):
    """:class:`SVSLConfig`, the task's option (the 5-link reacher's reward) and the
    entropy probe of Figs. A.1 / A.2."""

    reward: str | None = None  #: "3.8", "3.9" or "3.10" on the 5-link reacher, else None

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.reward is not None:
            _check_reward(self.reward, "reacher5-ch3", required=True)


@dataclass(frozen=True)
class HiREPSRun(EntropyProbe, HiREPSConfig):
    """:class:`HiREPSConfig`, the test protocol (every ``test_every`` iterations) and the
    entropy probe."""

    test_every: int = 50
    test_contexts: int = 200


@dataclass(frozen=True)
class LaDiPSRun(EntropyProbe, LaDiPSConfig):
    """:class:`LaDiPSConfig`, the test protocol (every ``test_every`` iterations) and the
    entropy probe."""

    test_every: int = 50
    test_contexts: int = 200


@dataclass(frozen=True)
class PPORun(PPOConfig):
    """:class:`PPOConfig` (Table A.5), the reward and the evaluation schedule."""

    reward: str = "3.10"
    eval_every: int = 5 * 16384  #: environment steps between evaluations
    eval_episodes: int = 20  #: fixed evaluation goals


def _as(cls: type, config: Any, **extra: Any) -> Any:
    """``config``'s fields as a ``cls`` (its own class or one of the run classes above)."""
    names = {f.name for f in dataclasses.fields(cls)}
    fields = {k: v for k, v in dataclasses.asdict(config).items() if k in names}
    return cls(**(fields | extra))


def env_of(task: str) -> str:
    """The one-step env id of a task SVSL runs on (``beer-pong`` → ``vslbook/BeerPong-v0``)."""
    for env, name in SVSL_ENVS.items():
        if name == task:
            return env
    raise ValueError(f"task {task!r} has no Chapter 3 preset; expected one of "
                     f"{sorted(SVSL_ENVS.values())}")  # fmt: skip


def task_of(env: str, table: dict[str, str]) -> str:
    """The task name of ``env``, or a clear error listing the ids ``table`` knows."""
    if env not in table:
        raise ValueError(f"env {env!r} has no Chapter 3 preset; expected one of {sorted(table)}")
    return table[env]


# --------------------------------------------------------------------------------------
# the configuration of each env at a budget (the Chapter 3 notebook's)
# --------------------------------------------------------------------------------------
def task_counts(task: str, budget: Budget) -> dict[str, Any]:
    """The counts of beer pong, Chapter 3 table tennis or (SVSL only) Chapter 4's table
    tennis at ``budget`` (their ``*_counts``)."""
    from vslbook.experiments import svsl_beer_pong, svsl_table_tennis, svsl_table_tennis_4d

    if task == "beer-pong":
        return svsl_beer_pong.beer_pong_counts(budget)
    if task == "table-tennis-4d":
        return svsl_table_tennis_4d.svsl_counts(budget)
    if task == "table-tennis-ch3":
        return svsl_table_tennis.table_tennis_counts(budget)
    raise ValueError(f"no counts for task {task!r}; expected beer-pong, table-tennis-ch3 or "
                     "table-tennis-4d")  # fmt: skip


def svsl_defaults(env: str, budget: Budget, overrides: dict[str, Any]) -> SVSLRun:
    """SVSL's configuration of ``env`` at ``budget`` (Tables A.1, A.4 or B.1 with its counts)."""
    from vslbook.experiments import svsl_mixtures, svsl_planar, svsl_reacher

    task = task_of(env, SVSL_ENVS)
    reward = _check_reward(overrides.get("reward"), env, required=task == "reacher5-ch3")
    if task == "planar-reacher":
        return _as(SVSLRun, svsl_planar.variant_config("SVSL", budget))
    if task == "reacher5-ch3":
        return _as(SVSLRun, svsl_reacher.reacher_configs(reward, budget)[0], reward=reward)
    if reward is not None:
        raise ValueError(f"reward= only applies to vslbook/Reacher5Ch3-v0, not {env}")
    counts = task_counts(task, budget)
    return _as(SVSLRun, svsl_mixtures.method_config(task, "SVSL", counts),
               **_entropy_fields(counts))  # fmt: skip


def _baseline_defaults(method: str, cls: type, envs: dict[str, str]):
    def defaults(env: str, budget: Budget, overrides: dict[str, Any]) -> Any:
        from vslbook.experiments import svsl_mixtures, svsl_planar

        task = task_of(env, envs)
        if task == "planar-reacher":  # Fig. 3.1: HiREPS only, SVSL's test protocol
            config = svsl_planar.variant_config("HiREPS", budget)
            svsl = svsl_planar.variant_config("SVSL", budget)
            probe: dict[str, Any] = {}
        else:
            counts = task_counts(task, budget)
            config = svsl_mixtures.method_config(task, method, counts)
            svsl = svsl_mixtures.method_config(task, "SVSL", counts)
            probe = _entropy_fields(counts)
        points = max(1, svsl.total_iterations // svsl.test_every)  # as many tests as SVSL
        every = max(1, config.iterations // points)
        return _as(cls, config, test_every=every, test_contexts=svsl.test_contexts, **probe)

    defaults.__doc__ = f"{method}'s configuration of an env at a budget (its task preset)."
    return defaults


def ppo_defaults(env: str, budget: Budget, overrides: dict[str, Any]) -> PPORun:
    """PPO's configuration (Table A.5) on the step-based 5-link reacher at ``budget``."""
    from vslbook.experiments import svsl_reacher

    task_of(env, PPO_ENVS)
    reward = _check_reward(overrides.get("reward", "3.10"), env, required=True)
    counts = svsl_reacher.reacher_counts(budget)
    ppo = svsl_reacher.reacher_configs(reward, budget)[1]
    return _as(
        PPORun, ppo, reward=reward, eval_every=counts["ppo_eval_every"],
        eval_episodes=counts["eval_goals"],
    )  # fmt: skip


# --------------------------------------------------------------------------------------
# training inside the run directory of vslbook.training.run
# --------------------------------------------------------------------------------------
def final_metrics(task_name: str, budget: Budget) -> Callable[[Any], dict[str, float]] | None:
    """What a Chapter 3 run adds to its last row, as ``final(model) -> metrics``; None
    where nothing. On beer pong: Fig. 3.2e/f's success over the cup box, each cell's
    success of the means of experts drawn from π(o | c)
    (:func:`vslbook.experiments.svsl_beer_pong.success_grid`, with the budget's grid and
    draws: 13 × 20 cells of 100 draws at ``full``, as the thesis describes) and their mean
    ``grid_success``, the number the thesis reports as 92 % (SVSL) and 75 % (HiREPS)
    (:func:`vslbook.experiments.svsl_beer_pong.grid_metrics`)."""
    if task_name != "beer-pong":
        return None
    from vslbook.experiments import svsl_beer_pong as BP

    counts = BP.beer_pong_counts(budget)

    def final(model: Any) -> dict[str, float]:
        grid = BP.success_grid(model, counts["grid"], n_draws=counts["grid_draws"])
        return BP.grid_metrics(grid)

    return final


def train_svsl(
    rd: RunDir, record: dict, budget: Budget, *, progress: bool = True,
    stop_after: int | None = None,
) -> dict | None:  # fmt: skip
    """Algorithm 1 for ``record`` in ``rd``; None if stopped by ``stop_after`` iterations."""
    from vslbook.envs.robot import make_task
    from vslbook.erl.ppo import evaluation_goals
    from vslbook.erl.svsl import SVSL
    from vslbook.erl.svsl import train as train_loop
    from vslbook.experiments.svsl_context import entropy_contexts, entropy_due, svsl_entropy

    config = config_from_record(SVSLRun, record)
    probe = config.entropy_spec()
    task_name = task_of(record["env"], SVSL_ENVS)
    seed = int(record["seed"])
    task = make_task(task_name, **({} if config.reward is None else {"reward": config.reward}))
    try:
        s = SVSL(task, config, seed)
        if task_name == "reacher5-ch3":  # tested on PPO's evaluation goals (Fig. 3.5)
            s.test_contexts = evaluation_goals(config.test_contexts)
        saved = rd.load_checkpoint()
        if saved is not None:
            s.load_state_dict(saved["svsl"])
        until = None if stop_after is None else s.iteration + int(stop_after)
        from vslbook.progress import progress_bar

        with progress_bar(total=config.total_iterations, initial=s.iteration,
                          disable=not progress, desc=f"svsl {task_name} s{seed}") as bar:

            contexts = None if probe is None else entropy_contexts(task_name, probe)

            final = final_metrics(task_name, budget)

            def log(it: int, metrics: dict[str, float]) -> None:
                if contexts is not None and "test_return" in metrics and entropy_due(
                    it, config.test_every, config.total_iterations, probe
                ):  # Figs. A.1, A.2
                    metrics["expected_entropy"] = svsl_entropy(s, contexts, probe["entropy_draws"])
                if final is not None and it == config.total_iterations:  # Fig. 3.2e
                    metrics |= final(s)
                rd.log(it, **metrics)
                bar.update(1)

            train_loop(
                task, config, seed, state=s, until=until, callback=log,
                checkpoint=lambda st: rd.save_checkpoint({"svsl": st.state_dict()}),
                checkpoint_due=rd.checkpoint_due,
            )  # fmt: skip
    finally:
        task.close()
    if s.iteration < config.total_iterations:
        return None
    return {"samples": s.samples, "experts": s.model.n_experts}


def _train_baseline(method: str, cls: type, base: type, envs: dict[str, str]):
    def train(
        rd: RunDir, record: dict, budget: Budget, *, progress: bool = True,
        stop_after: int | None = None,
    ) -> dict | None:  # fmt: skip
        from vslbook.envs.robot import make_task
        from vslbook.experiments.svsl_mixtures import train_baseline

        config = config_from_record(cls, record)
        task_name = task_of(record["env"], envs)
        task = make_task(task_name)
        seed = int(record["seed"])
        tests = {"test_every": config.test_every, "test_contexts": config.test_contexts}
        tests |= config.entropy_spec() or {}
        try:
            algo = train_baseline(
                rd, task, method, _as(base, config), seed, tests, stop_after=stop_after,
                progress=progress, final=final_metrics(task_name, budget),
            )  # fmt: skip
        finally:
            task.close()
        if algo.iterations_done < config.iterations:
            return None
        return {"samples": algo.total_samples, "iterations": config.iterations}

    train.__doc__ = f"{method} for ``record`` in ``rd``; None if stopped by ``stop_after``."
    return train


def train_ppo(
    rd: RunDir, record: dict, budget: Budget, *, progress: bool = True,
    stop_after: int | None = None,
) -> dict | None:  # fmt: skip
    """PPO for ``record`` in ``rd`` (checkpointed at every evaluation); ``stop_after``
    counts evaluations. Returns None if stopped before ``total_steps``."""
    from vslbook.erl import ppo

    config = config_from_record(PPORun, record)
    rows = ppo.train_ppo(
        config.reward, _as(PPOConfig, config), int(record["seed"]), run_dir=rd.path,
        eval_every=config.eval_every, eval_episodes=config.eval_episodes, progress=progress,
        stop_after_evals=stop_after,
    )  # fmt: skip
    logged = len(rd.metrics())  # rows of earlier calls are logged already
    for i, row in enumerate(rows[logged:], start=logged):
        rd.log(i, **row)
    if rows[-1]["env_steps"] < config.total_steps:
        return None
    return {"env_steps": rows[-1]["env_steps"], "episodes": rows[-1]["episodes"]}


_SCOPE = ("srl/",)  # no Chapter 3 run imports DIME's code

register_algorithm(
    "svsl", train=train_svsl, config=SVSLRun, envs=tuple(SVSL_ENVS), defaults=svsl_defaults,
    independent_of=_SCOPE,
    doc="SVSL (Ch. 3, Algorithm 1): mixture of linear-Gaussian experts with per-expert context "
    "distributions; Tables A.1, A.4 (and B.1: Chapter 4's table tennis, Fig. 4.3b)",
)  # fmt: skip
register_algorithm(
    "hireps", train=_train_baseline("HiREPS", HiREPSRun, HiREPSConfig, HIREPS_ENVS),
    config=HiREPSRun, envs=tuple(HIREPS_ENVS),
    defaults=_baseline_defaults("HiREPS", HiREPSRun, HIREPS_ENVS), independent_of=_SCOPE,
    doc="HiREPS (Daniel et al., 2012), the Chapter 3 baseline; Table A.2",
)  # fmt: skip
register_algorithm(
    "ladips", train=_train_baseline("LaDiPS", LaDiPSRun, LaDiPSConfig, LADIPS_ENVS),
    config=LaDiPSRun, envs=tuple(LADIPS_ENVS),
    defaults=_baseline_defaults("LaDiPS", LaDiPSRun, LADIPS_ENVS), independent_of=_SCOPE,
    doc="LaDiPS (End et al., 2017), the Chapter 3 baseline; Table A.3",
)  # fmt: skip
register_algorithm(
    "ppo", train=train_ppo, config=PPORun, envs=tuple(PPO_ENVS), defaults=ppo_defaults,
    independent_of=_SCOPE,
    doc="PPO (stable-baselines3) on the step-based 5-link reacher, Fig. 3.5; Table A.5",
)  # fmt: skip
