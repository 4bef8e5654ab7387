"""What each expert of a trained SVSL model does: the diagnostics behind Fig. 4.3b's SVSL curve.

SVSL (Algorithm 1) adds its experts one at a time and trains the newest. Each expert o
explores with its own Gaussian context distribution π(c | o) (Eq. 3.6), whose update sees
the task's reward, the guiding punishment R_c(c) of a context outside the valid region
(B.4.1.1) and the term (β − α) log π̃(o | c) that pushes a new expert away from the
contexts the others already hold (Eq. 3.4). :func:`expert_table` puts, for every expert,
where π(c | o) sits next to what its linear expert π(θ | c, o) (Eq. 3.5) achieves there:

* ``pi_o``: the weight π(o) (uniform until the weight phase, Eq. A.7);
* ``context_entropy``: H[π(c | o)]; ``context_valid``: the share of draws c ~ π(c | o)
  inside the valid contexts (the rest are punished, never simulated);
* ``expert_entropy``: H[π(θ | c, o)] (independent of c), and ``expert_entropy_start``, the
  entropy of the initial covariance, for scale;
* ``executed``, ``success``, ``return``: over ``draws`` pairs (c, θ) ~ π(c | o) π(θ | c, o),
  as the expert explores: the share the task executed (a context outside the valid
  region or a θ outside the joint limits is rejected), the share that succeeded and the
  mean return, punishments included;
* ``test_contexts``: how many of the run's fixed test contexts pick this expert as the most
  probable one (argmax π(o | c), Eq. 3.1), and ``test_success``, the success rate of the
  expert's mean θ on them.

:func:`load_svsl` restores the model of a run directory from its last checkpoint.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

__all__ = ["COLUMNS", "expert_table", "load_svsl"]

#: the columns of :func:`expert_table`, in order
COLUMNS = (
    "expert", "pi_o", "context_entropy", "context_valid", "expert_entropy",
    "expert_entropy_start", "executed", "success", "return", "test_contexts", "test_success",
)  # fmt: skip


def load_svsl(path: str | Path) -> Any:
    """The :class:`~vslbook.erl.svsl.SVSL` state of a run directory (its last checkpoint),
    with the test contexts its run evaluated on (PPO's evaluation goals for the Chapter 3
    5-link reacher, Fig. 3.5, as :func:`~vslbook.experiments.ch3_algorithms.train_svsl`
    sets them)."""
    from vslbook.envs.robot import make_task
    from vslbook.erl.ppo import evaluation_goals
    from vslbook.erl.svsl import SVSL
    from vslbook.experiments.ch3_algorithms import SVSL_ENVS, SVSLRun, task_of
    from vslbook.registry import config_from_record
    from vslbook.results import RunDir

    rd = RunDir.open(path)
    record = rd.config
    if record.get("algo") != "svsl":
        raise ValueError(f"{rd.path} is a {record.get('algo')!r} run, expected an 'svsl' run")
    config = config_from_record(SVSLRun, record)
    kwargs = {} if config.reward is None else {"reward": config.reward}
    task_name = task_of(record["env"], SVSL_ENVS)
    task = make_task(task_name, **kwargs)
    svsl = SVSL(task, config, int(record["seed"]))
    if task_name == "reacher5-ch3":
        svsl.test_contexts = evaluation_goals(config.test_contexts)
    saved = rd.load_checkpoint()
    if saved is None:
        raise FileNotFoundError(f"{rd.path} has no checkpoint to load")
    svsl.load_state_dict(saved["svsl"])
    return svsl


def expert_table(
    svsl: Any, draws: int = 40, seed: int = 0, workers: int | None = None
) -> pd.DataFrame:
    """One row per expert of ``svsl`` (an :class:`~vslbook.erl.svsl.SVSL`): the columns of
    :data:`COLUMNS` (see the module docstring). ``draws`` episodes per expert are simulated
    from ``seed``'s stream, the test contexts once with the experts' means (Algorithm 3's
    inference, as Fig. 3.2e/f evaluates); ``workers`` as in
    :meth:`~vslbook.envs.robot.task.EpisodicTask.evaluate`."""
    if isinstance(draws, bool) or not isinstance(draws, (int, np.integer)) or draws < 1:
        raise ValueError(f"draws must be a positive integer, got {draws!r}")
    m, task = svsl.model, svsl.task
    if m.n_experts == 0:
        raise ValueError("the model has no experts yet (train at least one iteration)")
    rng = np.random.default_rng(seed)
    start_cov = np.diag(np.asarray(svsl.config.expert_init_cov, dtype=np.float64))
    start = 0.5 * (m.param_dim * np.log(2 * np.pi * np.e) + np.linalg.slogdet(start_cov)[1])
    log_w = m.log_w - np.logaddexp.reduce(m.log_w)
    tc = svsl.test_contexts
    best = np.argmax(m.log_gating(tc), axis=1)
    test_out = task.evaluate(m.expert_means(tc, best), tc, workers=workers)
    context_entropy, expert_entropy = m.context_entropy(), m.expert_entropy()
    rows = []
    for o in range(m.n_experts):
        c, th = m.sample_curriculum(o, draws, rng)
        out = task.evaluate(th, c, workers=workers, out_of_range="penalise")
        mine = best == o
        rows.append({
            "expert": o,
            "pi_o": float(np.exp(log_w[o])),
            "context_entropy": float(context_entropy[o]),
            "context_valid": float(np.mean(task.context_valid(c))),
            "expert_entropy": float(expert_entropy[o]),
            "expert_entropy_start": float(start),
            "executed": out.n_executed / draws,
            "success": float(np.mean(out.success)) if task.has_success else np.nan,
            "return": float(np.mean(out.returns)),
            "test_contexts": int(mine.sum()),
            "test_success": (float(np.mean(np.asarray(test_out.success)[mine]))
                             if mine.any() and task.has_success else np.nan),
        })  # fmt: skip
    return pd.DataFrame(rows, columns=list(COLUMNS))
