"""One entry point to train any registered algorithm into a run directory.

``run(algo, env, seed, budget)`` is what ``vslbook run`` and :mod:`vslbook.sweep` call.
The run directory's name is derived from (algo, env, seed, budget, config); calling
``run`` again with the same arguments resumes an interrupted run from its checkpoint,
or returns immediately if the run is DONE.

Two guards:

* **Stale runs.** A run directory is reused (finished) or resumed (interrupted) only when
  it was made by the same code: ``env.json``'s code hash (:func:`vslbook.results.code_fingerprint`)
  must equal the running package's. Otherwise the old directory is moved to
  ``<root>/_stale/`` and the run starts afresh; with ``reuse_stale=True`` (or
  ``$VSLBOOK_REUSE_STALE=1``, or ``vslbook run --reuse-stale``) it is used anyway, with a
  printed warning.
* **Divergence.** A training loop raises :class:`vslbook.results.DivergenceError` on a
  non-finite loss, value or parameter; the run is then marked FAILED (step and quantity in
  ``FAILED``), never DONE, and is not re-run by later calls with the same code.
"""

from __future__ import annotations

import dataclasses
import os
import shutil
import time
import warnings
from pathlib import Path
from typing import Any

from vslbook.budget import Budget, get_budget
from vslbook.registry import check_run_request, config_from_overrides, get_algorithm
from vslbook.results import DivergenceError, RunDir, code_fingerprint

REUSE_STALE_ENV = "VSLBOOK_REUSE_STALE"


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
) -> RunDir:
    """Train ``algo`` on ``env`` with ``seed`` at ``budget`` and return its run directory.

    Args:
        overrides: hyper-parameters that differ from the algorithm's config defaults (for
            an algorithm with task presets, from the preset of ``env`` at ``budget``).
        stop_after: stop (without marking DONE) after this many iterations of *this call*;
            used to test that an interrupted run resumes exactly.
        reuse_stale: use an existing run directory made by other code (see the module
            docstring); None reads ``$VSLBOOK_REUSE_STALE`` (``1``/``true`` to allow).

    Returns:
        The run directory; check ``rd.status`` (``done``, ``failed`` or, after
        ``stop_after``, ``incomplete``).
    """
    spec = get_algorithm(algo)
    check_run_request(spec, env, seed)  # env id, algorithm support, seed: before any directory
    bud = get_budget(budget)
    config = _config(spec, env, bud, overrides)
    rd, record = _open(spec, algo, env, seed, bud, config, root, reuse_stale)
    if rd.failed:
        warnings.warn(
            f"run {rd.name} diverged before ({rd.failure.get('message')}); not re-run. "
            f"Delete {rd.path} to try again.",
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
) -> list[RunDir]:
    """Train ``seeds`` of ``algo`` on ``env`` in one process; one run directory per seed.

    The directories are those :func:`run` makes for each seed (same names and format):
    finished ones are reused, failed ones left alone, the others trained together (for
    DIME and its variants a seed axis on every tensor, :mod:`vslbook.srl.dime_seeds`),
    resuming from their checkpoints (the algorithm's ``train_seeds`` groups seeds whose
    checkpoints are at different steps).
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
    for seed in seeds:
        rd, record = _open(spec, algo, env, seed, bud, config, root, reuse_stale)
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
        results = spec.train_seeds(runs, records, bud, progress=progress, stop_after=stop_after)
    finally:
        torch.set_num_threads(threads)
    for rd, result in zip(runs, results, strict=True):
        if isinstance(result, DivergenceError):
            warnings.warn(f"run {rd.name} {result}; marked FAILED", stacklevel=2)
        elif result is not None:
            rd.mark_done(result)
    return out


def _config(spec: Any, env: str, bud: Budget, overrides: dict[str, Any] | None) -> Any:
    """The run's config: the algorithm's preset for ``env`` at ``bud`` (or ``config()``)
    with ``overrides``."""
    return config_from_overrides(spec.config, overrides, spec.default_config(env, bud, overrides))


def _open(
    spec: Any, algo: str, env: str, seed: int, bud: Budget, config: Any, root: str | Path,
    reuse_stale: bool | None,
) -> tuple[RunDir, dict]:  # fmt: skip
    """The run directory of (algo, env, seed, budget, config) and its record; one made by
    other code is moved aside or reused (:func:`_stale`)."""
    record = {"algo": algo, "env": env, "seed": int(seed), "budget": bud.name,
              **dataclasses.asdict(config)}  # fmt: skip
    rd = RunDir.create(root, record, code_exclude=spec.independent_of)
    if not rd.code_matches:  # only an existing directory can have been made by other code
        rd = _stale(rd, root, record, reuse_stale, spec.independent_of)
    return rd, record


def _reuse_from_env() -> bool:
    return os.environ.get(REUSE_STALE_ENV, "").strip().lower() in ("1", "true", "yes")


def _stale(
    rd: RunDir, root: str | Path, record: dict, reuse_stale: bool | None, exclude: tuple[str, ...]
) -> RunDir:
    """Handle a run directory made by other code: reuse it (warning) or move it aside and
    start afresh (recording the algorithm's code scope ``exclude``, as a new run does)."""
    old = (rd.code_hash or "unknown")[:12]
    new = code_fingerprint(tuple(rd.env.get("code_excluded", ())))[:12]
    what = f"run {rd.name} ({rd.status}) was made by other code (code hash {old}, now {new})"
    if reuse_stale if reuse_stale is not None else _reuse_from_env():
        print(f"WARNING: {what}; reusing it because reuse_stale / ${REUSE_STALE_ENV} is set")
        return rd
    target = Path(root) / "_stale" / f"{rd.name}-{old}-{int(time.time())}"
    target.parent.mkdir(parents=True, exist_ok=True)
    shutil.move(str(rd.path), str(target))
    print(f"{what}; moved to {target} and starting afresh")
    return RunDir.create(root, record, code_exclude=exclude)
