"""One entry point to train any registered algorithm into a run directory.

``run(algo, env, seed, budget)`` is what ``vslbook run`` and :mod:`vslbook.sweep` call.
The run directory's name is derived from (algo, env, seed, budget, config); calling
``run`` again with the same arguments resumes an interrupted run from its checkpoint,
or returns immediately if the run is DONE.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Any

from vslbook.budget import Budget, get_budget
from vslbook.registry import config_from_overrides, get_algorithm
from vslbook.results import RunDir


def run(
    algo: str,
    env: str,
    seed: int = 0,
    budget: str | Budget | None = None,
    *,
    root: str | Path = "runs",
    overrides: dict[str, Any] | None = None,
    progress: bool = True,
    stop_after: int | None = None,
) -> RunDir:
    """Train ``algo`` on ``env`` with ``seed`` at ``budget`` and return its run directory.

    Args:
        overrides: hyper-parameters that differ from the algorithm's config defaults.
        stop_after: stop (without marking DONE) after this many iterations of *this call*;
            used to test that an interrupted run resumes exactly.
    """
    spec = get_algorithm(algo)
    spec.check_env(env)
    bud = get_budget(budget)
    config = config_from_overrides(spec.config, overrides)
    record = {
        "algo": algo,
        "env": env,
        "seed": int(seed),
        "budget": bud.name,
        **dataclasses.asdict(config),
    }
    rd = RunDir.create(root, record)
    if rd.done:
        return rd
    summary = spec.train(rd, record, bud, progress=progress, stop_after=stop_after)
    if summary is not None:
        rd.mark_done(summary)
    return rd
