"""One entry point to train any registered algorithm into a run directory.

``run(algo, env, seed, budget)`` is what ``vslbook run`` and :mod:`vslbook.sweep` call.
The run directory's name is derived from (algo, env, seed, budget, config)
(:func:`run_name`, what ``vslbook run --dry-run`` prints); calling ``run`` again with the
same arguments resumes an interrupted run from its checkpoint, or returns at once if the
run is DONE. The directory is opened by :func:`vslbook.run_open.open_run`: locked against
a second process; when made by other code, kept if today's code replays its first rows
identically (:mod:`vslbook.replay`), else moved aside (``reuse_stale`` keeps it); its
``DONE`` checked against its metrics, and its rows after the last checkpoint dropped.

Divergence: a training loop raises :class:`vslbook.results.DivergenceError` on a
non-finite loss, value or parameter; the run is then marked FAILED (step and quantity in
``FAILED``), never DONE, and is not re-run by later calls with the same code.
"""

from __future__ import annotations

import dataclasses
import warnings
from pathlib import Path
from typing import Any

from vslbook.budget import Budget, get_budget
from vslbook.registry import check_run_request, config_from_overrides, get_algorithm
from vslbook.results import DivergenceError, RunDir
from vslbook.run_open import REUSE_STALE_ENV, open_run

__all__ = ["REUSE_STALE_ENV", "run", "run_name", "run_seeds"]


def run_name(
    algo: str,
    env: str,
    seed: int = 0,
    budget: str | Budget | None = None,
    *,
    overrides: dict[str, Any] | None = None,
) -> str:
    """The name of the run directory :func:`run` would train; validates the request and
    writes nothing (``vslbook run --dry-run``)."""
    spec = get_algorithm(algo)
    check_run_request(spec, env, seed)
    bud = get_budget(budget)
    return RunDir.name_for(_record(algo, env, seed, bud, _config(spec, env, bud, overrides)))


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
    reuse_stale: bool | None = None,
    wait: bool = False,
    restart: bool = False,
) -> RunDir:
    """Train ``algo`` on ``env`` with ``seed`` at ``budget`` and return its run directory.

    Args:
        overrides: hyper-parameters that differ from the algorithm's config defaults (for
            an algorithm with task presets, from the preset of ``env`` at ``budget``).
        stop_after: stop (without marking DONE) after this many iterations of *this call*;
            used to test that an interrupted run resumes exactly.
        reuse_stale: use an existing run directory made by other code (see
            :func:`vslbook.run_open.open_run`); None reads ``$VSLBOOK_REUSE_STALE``.
        wait: if another process trains this run, wait for it instead of raising
            :class:`vslbook.run_lock.RunLockedError`.
        restart: move an existing run directory aside and train afresh.

    Returns:
        The run directory; check ``rd.status`` (``done``, ``failed`` or, after
        ``stop_after``, ``incomplete``).
    """
    spec = get_algorithm(algo)
    check_run_request(spec, env, seed)  # env id, algorithm support, seed: before any directory
    bud = get_budget(budget)
    config = _config(spec, env, bud, overrides)
    record = _record(algo, env, seed, bud, config)
    rd = open_run(root, record, code_exclude=spec.independent_of, reuse_stale=reuse_stale,
                  wait=wait, restart=restart, verify=_verifier(spec, record, bud))  # fmt: skip
    try:
        if rd.failed:
            warnings.warn(
                f"run {rd.name} diverged before ({rd.failure.get('message')}); not re-run. "
                f"Rerun with --restart (restart=True) to try again.",
                stacklevel=2,
            )
            return rd
        if rd.done:
            return rd
        import torch  # not at module level: `vslbook budgets` and the like stay torch-free

        threads = torch.get_num_threads()  # a config's num_threads holds for this run only
        try:
            summary = spec.train(rd, record, bud, progress=progress, stop_after=stop_after)
        except DivergenceError as err:
            rd.mark_failed(err)
            warnings.warn(f"run {rd.name} {err}; marked FAILED in {rd.path}", stacklevel=2)
            return rd
        finally:
            torch.set_num_threads(threads)
        if summary is not None:
            rd.mark_done(summary)
        return rd
    finally:
        rd.release()


def run_seeds(
    algo: str,
    env: str,
    seeds: list[int],
    budget: str | Budget | None = None,
    *,
    root: str | Path = "runs",
    overrides: dict[str, Any] | None = None,
    progress: bool = True,
    stop_after: int | None = None,
    reuse_stale: bool | None = None,
    wait: bool = False,
    restart: bool = False,
) -> list[RunDir]:
    """Train ``seeds`` of ``algo`` on ``env`` in one process; one run directory per seed.

    The directories are those :func:`run` makes for each seed (same names and format):
    finished ones are reused, failed ones left alone, the others trained together (for
    DIME and its variants a seed axis on every tensor, :mod:`vslbook.srl.dime_seeds`),
    resuming from their checkpoints (the algorithm's ``train_seeds`` groups seeds whose
    checkpoints are at different steps). Each directory is locked while it trains.
    """
    spec = get_algorithm(algo)
    if spec.train_seeds is None:
        raise ValueError(
            f"algorithm {algo!r} trains one seed per process; use --seed (or vslbook sweep)"
        )
    seeds = list(seeds)
    if not seeds or len(set(seeds)) != len(seeds):
        raise ValueError(f"seeds must be distinct and at least one, got {seeds}")
    for seed in seeds:
        check_run_request(spec, env, seed)
    bud = get_budget(budget)
    config = _config(spec, env, bud, overrides)
    out: list[RunDir] = []
    todo: list[tuple[RunDir, dict]] = []
    try:
        for seed in seeds:
            record = _record(algo, env, seed, bud, config)
            rd = open_run(root, record, code_exclude=spec.independent_of,
                          reuse_stale=reuse_stale, wait=wait, restart=restart,
                          verify=_verifier(spec, record, bud, seed_axis=True))  # fmt: skip
            out.append(rd)
            if rd.failed:
                warnings.warn(f"run {rd.name} diverged before; not re-run", stacklevel=2)
            elif not rd.done:
                todo.append((rd, record))
        if not todo:
            return out
        import torch

        threads = torch.get_num_threads()
        runs, records = [t[0] for t in todo], [t[1] for t in todo]
        try:
            results = spec.train_seeds(runs, records, bud, progress=progress,
                                       stop_after=stop_after)  # fmt: skip
        finally:
            torch.set_num_threads(threads)
        for rd, result in zip(runs, results, strict=True):
            if isinstance(result, DivergenceError):
                warnings.warn(f"run {rd.name} {result}; marked FAILED", stacklevel=2)
            elif result is not None:
                rd.mark_done(result)
        return out
    finally:
        for rd in out:
            rd.release()


def _verifier(spec: Any, record: dict[str, Any], bud: Budget, seed_axis: bool = False):
    """``verify(rd)`` for :func:`vslbook.run_open.open_run`: today's code replays the run's
    first rows (:func:`vslbook.replay.replay_matches`), one seed alone; for runs the seed
    axis trains (``seed_axis``) to :data:`vslbook.replay.SEED_AXIS_RTOL`."""

    def verify(rd: RunDir) -> str | None:
        from vslbook.replay import RTOL, SEED_AXIS_RTOL, replay_matches

        rtol = SEED_AXIS_RTOL if seed_axis else RTOL
        return replay_matches(spec, record, rd.metrics(), bud, rtol=rtol)

    return verify


def _config(spec: Any, env: str, bud: Budget, overrides: dict[str, Any] | None) -> Any:
    """The run's config: the algorithm's preset for ``env`` at ``bud`` (or ``config()``)
    with ``overrides``."""
    return config_from_overrides(spec.config, overrides, spec.default_config(env, bud, overrides))


def _record(algo: str, env: str, seed: int, bud: Budget, config: Any) -> dict[str, Any]:
    """What ``config.json`` holds: the request and every field of the configuration."""
    return {"algo": algo, "env": env, "seed": int(seed), "budget": bud.name,
            **dataclasses.asdict(config)}  # fmt: skip
