"""Chapter 4's algorithms as ``vslbook run`` / ``vslbook sweep`` entries.

    vslbook run diskill    --env vslbook/Reacher5-v0 --seed 0 --budget reduced
    vslbook run bbrl       --env vslbook/BoxPushingObstacle-v0 --budget full
    vslbook run lindiskill --env vslbook/MiniGolf-v0 --set n_experts=5
    vslbook run diskill-v2 --env vslbook/TableTennis4D-v0
    vslbook run ppo-ch4    --env vslbook/Reacher5SparseStep-v0 --budget reduced

Registered here: ``diskill`` (Algorithm 2), ``lindiskill`` (linear experts), ``bbrl`` (one
deep Gaussian with the same trust-region projection) and ``diskill-v2`` / ``diskill-v3``
(the curriculum ablation of Fig. 4.3b, table tennis only), and ``ppo-ch4``, the
step-based PPO of Tables B.3 and B.6 on the 5-link reacher and box pushing (Figs. 4.3c,
4.4b), as long as Di-SkilL's run at the same budget in episodes
(:func:`vslbook.experiments.diskill_runs.ppo_steps`). A Di-SkilL run's configuration is
:func:`vslbook.erl.diskill_config.diskill_config` of the env's task with the counts its
figure uses at the budget (:func:`vslbook.experiments.diskill_runs.counts`), so ``vslbook
run`` trains exactly the run the figure draws, in the same run directory; like Chapter 3's,
these configs hold the counts themselves, so ``--set iterations=10`` means ten iterations at
any budget.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, fields

from vslbook.budget import Budget
from vslbook.erl.diskill_config import DiSkillConfig, diskill_config
from vslbook.erl.ppo_ch4 import PPOCh4Config
from vslbook.registry import config_from_record, register_algorithm
from vslbook.results import RunDir

__all__ = ["DISKILL_ENVS", "PPO_ENVS", "DiSkillRun", "PPOCh4Run", "task_of"]

#: one-step env id → task name, for every Chapter 4 task with a Di-SkilL preset.
DISKILL_ENVS = {
    "vslbook/TableTennis4D-v0": "table-tennis-4d",
    "vslbook/Reacher5-v0": "reacher5",
    "vslbook/TableTennisHard-v0": "table-tennis-hard",
    "vslbook/HopperJump-v0": "hopper-jump",
    "vslbook/BoxPushingObstacle-v0": "box-pushing-obstacle",
    "vslbook/MiniGolf-v0": "mini-golf",
}
LINDI_ENVS = {k: v for k, v in DISKILL_ENVS.items() if v != "table-tennis-4d"}
ABLATION_ENVS = {"vslbook/TableTennis4D-v0": "table-tennis-4d"}
#: step-based env id → task of Chapter 4's PPO (Tables B.3, B.6).
PPO_ENVS = {
    "vslbook/Reacher5SparseStep-v0": "reacher5",
    "vslbook/BoxPushingObstacleStep-v0": "box-pushing-obstacle",
}


@dataclass(frozen=True)
class DiSkillRun(DiSkillConfig):
    """:class:`DiSkillConfig` as a run records it (the method is the algorithm's name)."""


@dataclass(frozen=True)
class PPOCh4Run(PPOCh4Config):
    """:class:`PPOCh4Config` (Table B.3 / B.6) and the evaluation schedule."""

    eval_every: int = 10 * 16384  #: environment steps between evaluations
    eval_episodes: int = 75  #: fixed evaluation contexts


def task_of(env: str, table: dict[str, str]) -> str:
    """The task name of ``env``, or a clear error listing the ids ``table`` knows."""
    if env not in table:
        raise ValueError(f"env {env!r} has no Chapter 4 preset; expected one of {sorted(table)}")
    return table[env]


def _defaults(method: str, envs: dict[str, str]):
    def defaults(env: str, budget: Budget, overrides: dict) -> DiSkillRun:
        from vslbook.experiments.diskill_runs import counts

        task = task_of(env, envs)
        c = {k: v for k, v in counts(task, method, budget).items() if k != "seeds"}
        return DiSkillRun(**asdict(diskill_config(task, method, **c)))

    defaults.__doc__ = f"{method}'s configuration of ``env`` at ``budget`` (Tables B.2-B.7)."
    return defaults


def _train(method: str, envs: dict[str, str]):
    def train(
        rd: RunDir, record: dict, budget: Budget, *, progress: bool = True,
        stop_after: int | None = None,
    ) -> dict | None:  # fmt: skip
        from vslbook.envs.robot import make_task
        from vslbook.erl.diskill import DiSkill
        from vslbook.erl.diskill import train as train_loop
        from vslbook.progress import progress_bar

        config = config_from_record(DiSkillRun, record)
        task_name = task_of(record["env"], envs)
        seed = int(record["seed"])
        task = make_task(task_name)
        try:
            s = DiSkill(task, config, seed)
            saved = rd.load_checkpoint()
            if saved is not None:
                s.load_state_dict(saved["diskill"])
            until = None if stop_after is None else s.iteration + int(stop_after)
            with progress_bar(total=config.iterations, initial=s.iteration, disable=not progress,
                              desc=f"{method} {task_name} s{seed}") as bar:  # fmt: skip

                def log(it: int, metrics: dict[str, float]) -> None:
                    rd.log(it, **metrics)
                    bar.update(1 if it > 0 else 0)

                train_loop(
                    task, config, seed, state=s, until=until, callback=log,
                    checkpoint=lambda st: rd.save_checkpoint({"diskill": st.state_dict()}),
                    checkpoint_due=rd.checkpoint_due,
                )  # fmt: skip
        finally:
            task.close()
        if s.iteration < config.iterations:
            return None
        return {"samples": s.samples, "episodes": s.episodes, "iterations": s.iteration}

    train.__doc__ = f"{method} (Algorithm 2) for ``record`` in ``rd``; None if stopped early."
    return train


def ppo_defaults(env: str, budget: Budget, overrides: dict) -> PPOCh4Run:
    """Chapter 4's PPO on ``env`` at ``budget``: the table, Di-SkilL's episode count, and
    Di-SkilL's evaluation contexts (every rollout below ``full``, every 10 at ``full``)."""
    from vslbook.erl.ppo_ch4 import N_ROLLOUT_STEPS, ppo_ch4_config
    from vslbook.experiments.diskill_runs import counts, ppo_steps

    task = task_of(env, PPO_ENVS)
    cfg = ppo_ch4_config(task, total_steps=ppo_steps(task, budget))
    every = budget.pick(smoke=1, reduced=1, full=10) * N_ROLLOUT_STEPS
    tests = counts(task, "diskill", budget)["test_contexts"]
    return PPOCh4Run(**asdict(cfg), eval_every=every, eval_episodes=tests)


def train_ppo(
    rd: RunDir, record: dict, budget: Budget, *, progress: bool = True,
    stop_after: int | None = None,
) -> dict | None:  # fmt: skip
    """Chapter 4's PPO for ``record`` in ``rd``; its rows carry ``samples`` = completed
    training episodes, as the episodic methods' rows do. ``stop_after`` counts evaluations."""
    from vslbook.erl.ppo_ch4 import train_ppo_ch4

    config = config_from_record(PPOCh4Run, record)
    names = {f.name for f in fields(PPOCh4Config)}
    rows = train_ppo_ch4(
        task_of(record["env"], PPO_ENVS), PPOCh4Config(**{k: v for k, v in asdict(config).items()
                                                          if k in names}),
        int(record["seed"]), run_dir=rd.path, eval_every=config.eval_every,
        eval_episodes=config.eval_episodes, progress=progress, stop_after_evals=stop_after,
    )  # fmt: skip
    logged = len(rd.metrics())  # rows of earlier calls are logged already
    for i, row in enumerate(rows[logged:], start=logged):
        rd.log(i, **(row | {"samples": row["episodes"]}))
    if rows[-1]["env_steps"] < config.total_steps:
        return None
    return {"env_steps": rows[-1]["env_steps"], "episodes": rows[-1]["episodes"]}


_SCOPE = ("srl/",)  # no Chapter 4 run imports DIME's code

for _name, _envs, _doc in (
    ("diskill", DISKILL_ENVS, "Di-SkilL (Ch. 4, Algorithm 2): deep experts with energy-based "
     "per-expert context distributions and trust-region projections; Tables B.2-B.7"),
    ("lindiskill", LINDI_ENVS, "LinDi-SkilL: Di-SkilL with linear experts; Tables B.3-B.7"),
    ("bbrl", DISKILL_ENVS, "BBRL (Otto et al., 2023): one deep Gaussian policy with the "
     "trust-region projection, contexts from p(c); Tables B.2-B.7"),
    ("diskill-v2", ABLATION_ENVS, "Di-SkilLV2 (Fig. 4.3b): no curriculum (log π̃(o|c) = 0, "
     "β = 2000), 5 experts"),
    ("diskill-v3", ABLATION_ENVS, "Di-SkilLV3 (Fig. 4.3b): as V2 with 260 samples per expert"),
):  # fmt: skip
    register_algorithm(
        _name, train=_train(_name, _envs), config=DiSkillRun, envs=tuple(_envs),
        defaults=_defaults(_name, _envs), independent_of=_SCOPE, doc=_doc,
    )  # fmt: skip
register_algorithm(
    "ppo-ch4", train=train_ppo, config=PPOCh4Run, envs=tuple(PPO_ENVS), defaults=ppo_defaults,
    independent_of=_SCOPE,
    doc="PPO (stable-baselines3) on Chapter 4's step-based 5-link reacher and box pushing, "
    "Figs. 4.3c, 4.4b; Tables B.3, B.6",
)  # fmt: skip
