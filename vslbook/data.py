"""The ``data/`` folder: registered tables, collected runs and the paper's published curves.

Tables in ``data/``: :func:`collect_runs` turns run directories into ``runs.csv`` (one row
per run) and ``evals.csv.gz`` (long format: run, step, metric, value). Every table sits
next to a ``registry.json`` that records its sha256, row count and a description;
:func:`load_table` refuses to read a file whose bytes do not match the registry.
:func:`paper_curves` reads DIME's published learning curves from ``data/paper/``.
"""

from __future__ import annotations

import gzip
import hashlib
import io
import json
import os
from collections.abc import Iterable
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from vslbook.jsonfiles import atomic_write, config_hash, json_bytes
from vslbook.results import RunDir

__all__ = [
    "DataIntegrityError",
    "collect_runs",
    "csv_bytes",
    "measurements",
    "data_dir",
    "evals_frame",
    "gzip_bytes",
    "load_table",
    "paper_curves",
    "paper_tasks",
    "register_file",
    "results_dir",
    "unregister_file",
    "verify_file",
]

DATA_ENV_VAR = "VSLBOOK_DATA"
REGISTRY = "registry.json"
PAPER_CURVES = "dime_learning_curves.csv"
_REPO_ROOT = Path(__file__).resolve().parents[1]


class DataIntegrityError(ValueError):
    """A data file does not match its entry in ``registry.json`` (or has none)."""


# --------------------------------------------------------------------------- paths


def data_dir() -> Path:
    """The data folder: ``$VSLBOOK_DATA`` if set, else the repository's ``data/``."""
    env = os.environ.get(DATA_ENV_VAR)
    if env:
        return Path(env).expanduser()
    return _REPO_ROOT / "data"


def results_dir() -> Path:
    """Where :func:`collect_runs` output is read from by default: ``data_dir()/results``."""
    return data_dir() / "results"


# --------------------------------------------------------------------------- registry


def _sha256(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


def _count_rows(path: Path, data: bytes) -> int | None:
    """Data rows of a CSV (plain or gzip), None for other files."""
    name = path.name.lower()
    if name.endswith(".csv"):
        return len(pd.read_csv(io.BytesIO(data)))
    if name.endswith(".csv.gz"):
        return len(pd.read_csv(io.BytesIO(data), compression="gzip"))
    return None


def _read_registry(directory: Path) -> dict[str, Any]:
    path = directory / REGISTRY
    if not path.exists():
        return {}
    try:
        registry = json.loads(path.read_text(encoding="utf-8"))
    except json.JSONDecodeError as err:
        raise DataIntegrityError(f"{path} is not valid JSON: {err.msg}") from err
    if not isinstance(registry, dict):
        raise DataIntegrityError(f"{path} must hold a JSON object, got {type(registry).__name__}")
    return registry


def register_file(path: str | os.PathLike[str], description: str) -> dict[str, Any]:
    """Record ``path``'s sha256, row count and ``description`` in its folder's registry.json.

    Returns the entry that was written.
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"cannot register {path}: no such file")
    if not description or not isinstance(description, str):
        raise ValueError(f"description must be a non-empty string, got {description!r}")
    data = path.read_bytes()
    entry = {"sha256": _sha256(data), "rows": _count_rows(path, data), "description": description}
    registry = _read_registry(path.parent)
    registry[path.name] = entry
    atomic_write(path.parent / REGISTRY, json_bytes(registry))
    return entry


def unregister_file(path: str | os.PathLike[str]) -> bool:
    """Drop ``path``'s entry from its folder's registry.json (the file itself is left as
    it is); False where it had none. A registry left empty is removed."""
    path = Path(path)
    registry_path = path.parent / REGISTRY
    if not registry_path.exists():
        return False
    registry = _read_registry(path.parent)
    if registry.pop(path.name, None) is None:
        return False
    if registry:
        atomic_write(registry_path, json_bytes(registry))
    else:
        registry_path.unlink()
    return True


def _verified_bytes(path: Path) -> bytes:
    registry_path = path.parent / REGISTRY
    if not registry_path.exists():
        raise DataIntegrityError(
            f"cannot verify {path}: no {REGISTRY} in {path.parent} (expected one that "
            f"records its sha256; create it with vslbook.data.register_file)"
        )
    registry = _read_registry(path.parent)
    if path.name not in registry:
        raise DataIntegrityError(
            f"{path.name} is not listed in {registry_path}; registered files: "
            f"{', '.join(sorted(registry)) or 'none'}"
        )
    if not path.is_file():
        raise FileNotFoundError(f"{path} is registered in {registry_path} but the file is missing")
    data = path.read_bytes()
    expected = registry[path.name].get("sha256")
    actual = _sha256(data)
    if actual != expected:
        raise DataIntegrityError(
            f"{path}: sha256 does not match the registry {registry_path} "
            f"(expected {expected}, got {actual}); the file is corrupted or was edited"
        )
    return data


def verify_file(path: str | os.PathLike[str]) -> str:
    """Check ``path`` against the registry.json next to it; return its sha256.

    Raises:
        DataIntegrityError: no registry, no entry for the file, or a different sha256.
        FileNotFoundError: the file itself is missing.
    """
    return _sha256(_verified_bytes(Path(path)))


def load_table(name: str, directory: str | os.PathLike[str] | None = None) -> pd.DataFrame:
    """Read a registered CSV table (``.csv`` or ``.csv.gz``) after verifying its sha256.

    Args:
        name: file name inside ``directory``, e.g. ``"runs.csv"`` or ``"evals.csv.gz"``.
        directory: folder holding the file and its ``registry.json``; default
            :func:`results_dir`.

    Raises:
        DataIntegrityError: see :func:`verify_file`.
    """
    path = Path(directory) / name if directory is not None else results_dir() / name
    if not path.name.lower().endswith((".csv", ".csv.gz")):
        raise ValueError(f"load_table reads .csv or .csv.gz files, got {name!r}")
    data = _verified_bytes(path)
    compression = "gzip" if path.name.lower().endswith(".gz") else None
    return pd.read_csv(io.BytesIO(data), compression=compression)


# --------------------------------------------------------------------------- collecting runs


RUNS_COLUMNS = ["run", "algo", "env", "seed", "budget", "config_hash", "status"]
EVALS_COLUMNS = ["run", "step", "metric", "value"]


def _is_numeric(value: Any) -> bool:
    return value is None or (isinstance(value, (int, float)) and not isinstance(value, bool))


def csv_bytes(frame: pd.DataFrame) -> bytes:
    """``frame`` as CSV bytes without its index, ``\\n`` line ends: the tables' format."""
    return frame.to_csv(index=False, lineterminator="\n").encode("utf-8")


def gzip_bytes(data: bytes) -> bytes:
    """gzip with a fixed header (no file name, mtime 0): same input, same bytes."""
    buffer = io.BytesIO()
    with gzip.GzipFile(filename="", mode="wb", fileobj=buffer, mtime=0, compresslevel=9) as gz:
        gz.write(data)
    return buffer.getvalue()


def evals_frame(runs: Iterable[RunDir]) -> pd.DataFrame:
    """The long-format evaluations of ``runs`` (columns run, step, metric, value), in the
    order given: one row per (run, step, numeric metric) of each ``metrics.jsonl``, metrics
    sorted by name within a row, ``null`` values as NaN."""
    rows = []
    for run in runs:
        for row in run.metrics():
            for metric in sorted(k for k in row if k != "step"):
                if _is_numeric(row[metric]):
                    value = np.nan if row[metric] is None else row[metric]
                    rows.append((run.name, row["step"], metric, value))
    return pd.DataFrame(rows, columns=EVALS_COLUMNS).astype({"value": "float64"})


def collect_runs(
    run_dirs: Iterable[str | os.PathLike[str] | RunDir], out_dir: str | os.PathLike[str]
) -> dict[str, Path]:
    """Write ``runs.csv``, ``evals.csv.gz`` and ``registry.json`` into ``out_dir``.

    ``runs.csv`` has one row per run (columns run, algo, env, seed, budget, config_hash,
    status ``done``, ``failed`` or ``incomplete``), sorted by run name; ``evals.csv.gz``
    has one row per (run, step, metric) for every numeric metric in ``metrics.jsonl``
    (``null`` values, i.e. non-finite ones, become empty cells / NaN). The output is
    byte-for-byte deterministic for the same runs.

    Returns:
        The written paths keyed by file name.
    """
    runs = [r if isinstance(r, RunDir) else RunDir.open(r) for r in run_dirs]
    by_name: dict[str, RunDir] = {}
    for run in runs:
        if run.name in by_name:
            raise ValueError(
                f"two run directories share the name {run.name!r}: "
                f"{by_name[run.name].path} and {run.path}"
            )
        by_name[run.name] = run
    run_rows = []
    for name in sorted(by_name):
        run = by_name[name]
        config = run.config
        run_rows.append(
            {
                "run": name,
                "algo": config.get("algo"),
                "env": config.get("env"),
                "seed": config.get("seed"),
                "budget": config.get("budget"),
                "config_hash": config_hash(config),
                "status": run.status,
            }
        )
    runs_frame = pd.DataFrame(run_rows, columns=RUNS_COLUMNS)
    runs_frame["seed"] = runs_frame["seed"].astype("Int64")
    evals = evals_frame(by_name[name] for name in sorted(by_name))
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    written = {"runs.csv": out / "runs.csv", "evals.csv.gz": out / "evals.csv.gz"}
    atomic_write(written["runs.csv"], csv_bytes(runs_frame))
    atomic_write(written["evals.csv.gz"], gzip_bytes(csv_bytes(evals)))
    register_file(
        written["runs.csv"],
        "one row per run: run, algo, env, seed, budget, "
        "config_hash, status (done | failed | incomplete); written by vslbook.data",
    )
    register_file(
        written["evals.csv.gz"],
        "long-format evaluations: run, step, metric, "
        "value; from each run's metrics.jsonl; written by vslbook.data",
    )
    written[REGISTRY] = out / REGISTRY
    return written


# --------------------------------------------------------------------------- paper data


def paper_curves(task: str | None = None) -> pd.DataFrame:
    """DIME's published learning curves (``data/paper/dime_learning_curves.csv``).

    Columns ``env, seed, env_steps, mean_return``; 21 tasks with 10 seeds each (see
    ``data/paper/README.md`` for provenance). The file is checked against
    ``data/paper/registry.json`` before reading.

    Args:
        task: one task id (e.g. ``"dmc_dog_run"``) to keep, or None for all tasks.

    Raises:
        ValueError: ``task`` is not one of the published task ids (they are listed).
    """
    frame = load_table(PAPER_CURVES, data_dir() / "paper")
    if task is None:
        return frame
    valid = sorted(frame["env"].unique())
    if task not in valid:
        raise ValueError(f"unknown task {task!r}; expected one of: {', '.join(valid)}")
    return frame[frame["env"] == task].reset_index(drop=True)


def paper_tasks() -> list[str]:
    """The task ids in the published DIME curves, sorted."""
    return sorted(paper_curves()["env"].unique().tolist())


def measurements(name: str) -> pd.DataFrame:
    """A table of ``data/measurements/`` (numbers measured outside the book, with their
    provenance in that folder's README), verified against its registry.

    Raises:
        FileNotFoundError: no such table; the message lists the ones there are.
    """
    folder = data_dir() / "measurements"
    path = folder / name
    if not path.is_file():
        have = sorted(p.name for p in folder.glob("*.csv")) if folder.is_dir() else []
        raise FileNotFoundError(f"no measurements table {name!r} in {folder}; expected one of "
                                f"{have}")  # fmt: skip
    return load_table(name, folder)
