"""Recorded runs as run directories: what a figure reads when the runs are not in ``runs/``.

A recorded set (:mod:`vslbook.experiments.record`, ``data/results/<figure>/<budget>/``)
holds every run's numeric metrics in long format and its provenance. :func:`materialise`
writes the runs back as read-only run directories under
``build/recorded/<figure>/<budget>/<run>/``:

``config.json``, ``env.json``
    as the run wrote them (from ``provenance.json``; ``env.json`` gains ``"recorded"``:
    the set's folder and the date the run was recorded);
``metrics.jsonl``
    one line per row of the original file that held a numeric metric, the row boundaries
    rebuilt from the long table (a row's metrics are stored in name order, so a new row
    starts where the step changes or the names stop increasing); non-numeric fields are
    not recorded;
``DONE``
    covering those lines, so :meth:`vslbook.results.RunDir.check_done` holds; a probe (a
    run recorded while still training, ``vslbook record --partial``) gets none;
``checkpoint/state.pt``
    where the set records the run's final checkpoint (:func:`record_checkpoints`: the
    first seed of each method and task, the run a figure draws a trained policy of), so
    e.g. :func:`vslbook.experiments.diskill_runs.load_model` works on it.

Everything that reads a figure's runs (``RunDir.open(path).metrics()``, the learning
curves, the final scores) then reads a recorded run exactly as a trained one. The folder
is a cache: it is rewritten whenever the set's tables change (their sha256 is kept in
``build/recorded/<figure>/<budget>/SOURCE.json``).
"""

from __future__ import annotations

import gzip
import io
import json
import shutil
from pathlib import Path
from typing import Any

import pandas as pd

from vslbook.budget import Budget, get_budget
from vslbook.data import data_dir, gzip_bytes, register_file, unregister_file, verify_file
from vslbook.jsonfiles import atomic_write, json_bytes
from vslbook.results import RunDir

__all__ = ["CHECKPOINTS", "materialise", "materialised_root", "metric_rows",
           "record_checkpoints"]  # fmt: skip

#: the folder of a recorded set that holds the final checkpoints it keeps
CHECKPOINTS = "checkpoints"
_SOURCE = "SOURCE.json"
_CHECKPOINT_DESCRIPTION = ("the run's final checkpoint (torch.save of its state dict), gzip; "
                           "written by vslbook record")  # fmt: skip


def materialised_root() -> Path:
    """``build/recorded/`` beside ``data/`` (the repository's build folder)."""
    return data_dir().resolve().parent / "build" / "recorded"


# --------------------------------------------------------------------------- checkpoints


def record_checkpoints(out: Path, fresh: dict[str, tuple[RunDir, Any]],
                       in_set: pd.DataFrame | None = None) -> list[str]:  # fmt: skip
    """Copy the final checkpoint of the first seed of each (method, env) into
    ``out/checkpoints/<run>.pt.gz``, registered, where that run is among ``fresh`` (run
    name → (run directory, :class:`~vslbook.experiments.run_plan.FigureRun`)); return the
    names copied.

    The first seed is taken over the whole set, ``in_set`` (its ``runs.csv`` frame: run,
    method, env, seed; default: ``fresh`` alone), so a seed recorded later from a folder
    that lacks seed 0 adds no checkpoint, and a checkpoint of any other run in the folder
    is removed. Only the first seed's: a figure that draws a trained policy (Fig. 3.2's
    coverage, the skills of Fig. 4.2) draws seed 0's, and keeping every seed's would
    multiply the repository's size by the seed count.
    """
    rows = [(run.method, run.env, run.seed, name) for name, (_rd, run) in fresh.items()]
    if in_set is not None:
        rows += [(r["method"], r["env"], int(r["seed"]), r["run"])
                 for r in in_set.to_dict("records")]  # fmt: skip
    first: dict[tuple[str, str], tuple[int, str]] = {}
    for method, env, seed, name in rows:
        if (method, env) not in first or (seed, name) < first[(method, env)]:
            first[(method, env)] = (seed, name)
    keep = {name for _, name in first.values()}
    folder = out / CHECKPOINTS
    for stale in sorted(folder.glob("*.pt.gz")) if folder.is_dir() else []:
        if stale.name[: -len(".pt.gz")] not in keep:
            stale.unlink()
            unregister_file(stale)
    written = []
    for name in sorted(keep & set(fresh)):
        rd = fresh[name][0]
        if not rd.checkpoint_path.is_file():
            continue
        target = folder / f"{name}.pt.gz"
        target.parent.mkdir(parents=True, exist_ok=True)
        atomic_write(target, gzip_bytes(rd.checkpoint_path.read_bytes()))
        register_file(target, _CHECKPOINT_DESCRIPTION)
        written.append(name)
    return written


# --------------------------------------------------------------------------- rows


def metric_rows(evals: pd.DataFrame) -> list[dict[str, Any]]:
    """The ``metrics.jsonl`` rows of one run from its long table (run, step, metric, value
    in recorded order): a new row starts where the step changes or the metric names stop
    increasing (:func:`vslbook.data.evals_frame` writes a row's metrics in name order).
    NaN values come back as ``None`` (``null``), as the run logged them."""
    rows: list[dict[str, Any]] = []
    last_step, last_metric = None, None
    for step, metric, value in zip(evals["step"], evals["metric"], evals["value"], strict=True):
        step = int(step)
        if not rows or step != last_step or metric <= last_metric:
            rows.append({"step": step})
        rows[-1][metric] = None if pd.isna(value) else float(value)
        last_step, last_metric = step, metric
    return rows


# --------------------------------------------------------------------------- materialising


def _tables_key(directory: Path) -> dict[str, str]:
    """sha256 of each registered file of a recorded set (verified)."""
    registry = json.loads((directory / "registry.json").read_text(encoding="utf-8"))
    key = {name: verify_file(directory / name) for name in sorted(registry)}
    checkpoints = directory / CHECKPOINTS
    if checkpoints.is_dir():
        key |= {f"{CHECKPOINTS}/{p.name}": verify_file(p) for p in sorted(checkpoints.glob("*.gz"))}
    return key


def _write_run(target: Path, entry: dict[str, Any], rows: list[dict[str, Any]],
               recorded: dict[str, Any], checkpoint: Path | None, done: bool) -> None:  # fmt: skip
    """One recorded run as a run directory in ``target`` (made afresh)."""
    import torch

    target.mkdir(parents=True)
    rd = RunDir(target)
    env = {k: entry.get(k) for k in ("code_hash", "code_hashes_verified", "code_excluded",
                                      "git_sha", "git_dirty", "packages", "python", "platform",
                                      "cpu")}
    env |= {"hostname": entry.get("hostname"), "timestamp": entry.get("started"),
            "recorded": recorded}  # fmt: skip
    atomic_write(target / RunDir.CONFIG, json_bytes(entry["config"]))
    atomic_write(target / RunDir.ENV, json_bytes(env))
    atomic_write(rd.metrics_path, "".join(json.dumps(r) + "\n" for r in rows).encode("utf-8"))
    if checkpoint is not None:
        state = torch.load(io.BytesIO(gzip.decompress(checkpoint.read_bytes())),
                           map_location="cpu", weights_only=False)  # fmt: skip
        state["_metrics_lines"] = len(rows)  # the rows of this copy, not of the original
        rd.save_checkpoint({k: v for k, v in state.items() if k != "_metrics_lines"})
    if done:
        rd.mark_done({"recorded": recorded})


def materialise(figure: str, budget: Budget | str | None = None,
                dest: str | Path | None = None) -> dict[str, Path]:  # fmt: skip
    """The recorded runs of ``figure`` at ``budget`` as run directories (see the module's
    docstring): run name → path, empty where nothing is recorded.

    Raises:
        vslbook.data.DataIntegrityError: a table of the set fails its registry.
    """
    from vslbook.experiments.record import read_set, recorded_dir

    b = get_budget(budget)
    directory = recorded_dir(figure, b)
    if not (directory / "runs.csv").is_file():
        return {}
    base = Path(dest) if dest is not None else materialised_root()
    folder = base / figure / b.name
    key = {"set": str(directory), "files": _tables_key(directory)}
    runs, evals, provenance = read_set(directory)
    paths = {name: folder / name for name in runs["run"]}
    source = folder / _SOURCE
    fresh = source.is_file() and json.loads(source.read_text(encoding="utf-8")) == key
    done = dict(zip(runs["run"], runs["status"] == "done", strict=True))
    if fresh and all((p / RunDir.CONFIG).is_file() and (p / RunDir.DONE).is_file() == done[n]
                     for n, p in paths.items()):  # fmt: skip
        return paths
    if folder.exists():
        shutil.rmtree(folder)
    folder.mkdir(parents=True)
    for name, part in evals.groupby("run", sort=False):
        entry = provenance[name]
        checkpoint = directory / CHECKPOINTS / f"{name}.pt.gz"
        recorded = {"set": str(directory), "date": entry.get("recorded")}
        _write_run(folder / name, entry, metric_rows(part), recorded,
                   checkpoint if checkpoint.is_file() else None, bool(done[name]))  # fmt: skip
    missing = sorted(set(paths) - {p.name for p in folder.iterdir()})
    if missing:
        raise ValueError(f"recorded set {directory} lists runs with no evaluations: {missing}")
    atomic_write(source, json_bytes(key))
    return paths
