"""Run directories: one training run's configuration, metrics, checkpoints and status.

A *run directory* holds everything one training run leaves behind::

    <root>/<name>/
        config.json       the configuration (sorted keys); its sha256 names the run
        env.json          python, platform, host, package versions, git sha, start time
        metrics.jsonl     one JSON object per ``log`` call, appended, flushed and fsync'ed
        checkpoint/       state.pt, written to state.pt.tmp first and then renamed
        LOCK              held (flock) by the process that trains the run: :mod:`vslbook.run_lock`
        DONE              written last, a JSON summary with the rows it covers (count, last
                          step, sha256 of metrics.jsonl); checked whenever the run is reused
        FAILED            written instead of DONE when a run diverged: step and quantity

Code identity: ``env.json`` records :func:`code_fingerprint` (sha256 of the package's
Python sources that the run can reach) beside the git sha and a dirty flag.
:attr:`RunDir.code_matches` compares it with the running code, so a finished run is
reused only by the code that produced it (:func:`vslbook.training.run`).

Resuming: :meth:`RunDir.save_checkpoint` records how many lines ``metrics.jsonl`` had at
that moment and :meth:`RunDir.load_checkpoint` truncates the file back to that count, so
rows logged between the checkpoint and an interruption are not duplicated when the run
continues from the checkpoint; :meth:`RunDir.rewind` drops every row of a run that has no
checkpoint yet (it starts again from its seed). Together with
:func:`vslbook.rng_state.rng_state` stored in the checkpoint, a resumed run reproduces the
numbers of an uninterrupted one. Opening a run for training (the lock, the stale-code rule,
the rewind) is :func:`vslbook.run_open.open_run`.

The ``data/`` tables are :mod:`vslbook.data`; code identity is :mod:`vslbook.provenance`.
"""

from __future__ import annotations

import json
import numbers
import os
import re
import time
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import pandas as pd

from vslbook.jsonfiles import (
    atomic_write,
    canonical_json,
    config_hash,
    json_bytes,
    metric_value,
    plain_json,
    read_json,
)
from vslbook.provenance import NOT_RUN_CODE, code_fingerprint
from vslbook.provenance import environment as _environment
from vslbook.run_errors import DivergenceError, RunDirError
from vslbook.run_status import RunStatus

__all__ = [
    "NOT_RUN_CODE",
    "DivergenceError",
    "RunDir",
    "RunDirError",
    "code_fingerprint",
    "config_hash",
]

_NAME_OK = re.compile(r"[^A-Za-z0-9._-]+")


#: The environment variable that caps the work a killed run can lose, in seconds.
CHECKPOINT_SECONDS_ENV = "VSLBOOK_CHECKPOINT_SECONDS"


def checkpoint_seconds() -> float:
    """Seconds of training between checkpoints at most: ``$VSLBOOK_CHECKPOINT_SECONDS``,
    default 300. A checkpoint changes no number of a run, so this is not part of its config.

    Raises:
        ValueError: the variable is not a number >= 0.
    """
    text = os.environ.get(CHECKPOINT_SECONDS_ENV, "300")
    try:
        value = float(text)
    except ValueError:
        value = -1.0
    if not value >= 0:
        raise ValueError(f"${CHECKPOINT_SECONDS_ENV} must be seconds >= 0, got {text!r}")
    return value


# --------------------------------------------------------------------------- run directory


def _config_diff(old: Mapping[str, Any], new: Mapping[str, Any]) -> str:
    lines = []
    for key in sorted(set(old) | set(new)):
        if key not in new:
            lines.append(f"  {key}: {old[key]!r} (existing) vs missing (new)")
        elif key not in old:
            lines.append(f"  {key}: missing (existing) vs {new[key]!r} (new)")
        elif old[key] != new[key]:
            lines.append(f"  {key}: {old[key]!r} (existing) vs {new[key]!r} (new)")
    return "\n".join(lines)


class RunDir(RunStatus):
    """One run's directory: config, environment, metrics, checkpoint and completion mark.

    Create a new one (or reopen a matching one to resume) with :meth:`create`; open an
    existing one for reading with :meth:`open`.
    """

    CONFIG = "config.json"  # ENV, METRICS, DONE and FAILED: RunStatus
    CHECKPOINT_DIR = "checkpoint"
    CHECKPOINT = "state.pt"

    def __init__(self, path: str | os.PathLike[str]) -> None:
        self.path = Path(path)
        self._saved_at = time.monotonic()
        #: the run's :class:`vslbook.run_lock.RunLock` while this process trains it
        self.lock: Any = None

    def release(self) -> None:
        """Let go of the run's lock, if this object holds it (idempotent)."""
        if self.lock is not None:
            self.lock.release()
            self.lock = None

    def __repr__(self) -> str:
        return f"RunDir({str(self.path)!r})"

    # -- construction -------------------------------------------------------------------

    @classmethod
    def create(
        cls,
        root: str | os.PathLike[str],
        config: Mapping[str, Any],
        *,
        name: str | None = None,
        exist_ok_resume: bool = True,
        code_exclude: tuple[str, ...] = (),
    ) -> RunDir:
        """Create ``root/name`` and write ``config.json`` and ``env.json``.

        Args:
            root: folder that holds run directories (created if needed).
            config: the run's configuration, a dict (or a dataclass) of JSON-able values.
            name: directory name; default ``{algo}-{env}-s{seed}-{hash8}`` from the config
                keys ``algo``, ``env`` and ``seed`` where present.
            exist_ok_resume: if the directory exists with the same config, return it so
                the run can resume; if False an existing directory is an error.
            code_exclude: package paths the run cannot depend on, left out of the recorded
                :func:`code_fingerprint` (and recorded beside it).

        Raises:
            ValueError: the directory exists with a different ``config.json`` (the message
                lists the keys that differ), or ``name`` is not a plain directory name.
            FileExistsError: the directory exists and ``exist_ok_resume`` is False.
        """
        plain = plain_json(config)
        if not isinstance(plain, dict):
            raise TypeError(f"config must be a dict or a dataclass, got {type(config).__name__}")
        if name is None:
            name = cls.name_for(plain)
        elif not name or name in (".", "..") or _NAME_OK.search(name):
            raise ValueError(
                f"run name {name!r} is not a plain directory name; "
                "expected letters, digits, '.', '_' or '-'"
            )
        run = cls(Path(root) / name)
        config_file = run.path / cls.CONFIG
        if config_file.exists():
            existing = read_json(config_file)
            if canonical_json(existing) != canonical_json(plain):
                raise ValueError(
                    f"run directory {run.path} already exists with a different config:\n"
                    f"{_config_diff(existing, plain)}\n"
                    "choose another name or root, or delete the old run"
                )
            if not exist_ok_resume:
                raise FileExistsError(
                    f"run directory {run.path} already exists (exist_ok_resume=False)"
                )
            return run
        run.path.mkdir(parents=True, exist_ok=True)
        atomic_write(run.path / cls.ENV, json_bytes(_environment(tuple(code_exclude))))
        atomic_write(config_file, json_bytes(plain))
        return run

    @staticmethod
    def name_for(config: Mapping[str, Any]) -> str:
        """The default directory name of ``config``: ``{algo}-{env}-s{seed}-{hash8}`` from
        the keys ``algo``, ``env`` and ``seed`` where present (what :meth:`create` uses)."""
        plain = plain_json(config)
        parts = [str(plain[key]) for key in ("algo", "env") if key in plain]
        if "seed" in plain:
            parts.append(f"s{plain['seed']}")
        parts.append(config_hash(plain)[:8])
        return _NAME_OK.sub("_", "-".join(parts))

    @classmethod
    def open(cls, path: str | os.PathLike[str]) -> RunDir:
        """Open an existing run directory (one with a ``config.json``)."""
        run = cls(path)
        if not (run.path / cls.CONFIG).is_file():
            raise FileNotFoundError(
                f"{run.path} is not a run directory: expected a {cls.CONFIG} in it"
            )
        return run

    # -- contents -----------------------------------------------------------------------

    @property
    def name(self) -> str:
        """The directory name, used as the run id in ``runs.csv``."""
        return self.path.name

    @property
    def config(self) -> dict[str, Any]:
        """The stored ``config.json``."""
        return read_json(self.path / self.CONFIG)

    @property
    def env(self) -> dict[str, Any]:
        """The stored ``env.json`` (``{}`` when it is missing: nothing then says which code
        made the run, so :attr:`code_matches` is False)."""
        path = self.path / self.ENV
        return read_json(path) if path.exists() else {}

    @property
    def config_hash(self) -> str:
        """sha256 of the stored config (see :func:`config_hash`)."""
        return config_hash(self.config)

    # -- metrics ------------------------------------------------------------------------

    @property
    def metrics_path(self) -> Path:
        return self.path / self.METRICS

    def log(self, step: int, **metrics: Any) -> None:
        """Append ``{"step": step, **metrics}`` as one line to ``metrics.jsonl``.

        The line is flushed and fsync'ed before returning. Values must be ints, floats,
        strings, bools or None (numpy scalars and 0-d tensors are converted). Non-finite
        floats (NaN, +-inf) are stored as ``null``, so the file stays strict JSON.
        """
        if isinstance(step, bool) or not isinstance(step, numbers.Integral) or step < 0:
            raise ValueError(f"step must be a non-negative integer, got {step!r}")
        row = {"step": int(step)}
        row.update({key: metric_value(key, value) for key, value in metrics.items()})
        line = json.dumps(row, allow_nan=False, separators=(",", ":")) + "\n"
        self._drop_torn_tail()
        with open(self.metrics_path, "a", encoding="utf-8") as fh:
            fh.write(line)
            fh.flush()
            os.fsync(fh.fileno())

    def _drop_torn_tail(self) -> None:
        """Cut a partial last line (left by a crash mid-write) so appends stay line-aligned."""
        path = self.metrics_path
        if not path.exists() or path.stat().st_size == 0:
            return
        with open(path, "rb") as fh:
            fh.seek(-1, os.SEEK_END)
            if fh.read(1) == b"\n":
                return
        data = path.read_bytes()
        atomic_write(path, data[: data.rfind(b"\n") + 1])

    def _metric_lines(self) -> list[str]:
        """Complete lines of ``metrics.jsonl`` (a torn last line from a crash is dropped)."""
        if not self.metrics_path.exists():
            return []
        text = self.metrics_path.read_text(encoding="utf-8")
        lines = text.split("\n")
        return [line for line in lines[:-1] if line.strip()]

    def metrics(self) -> list[dict[str, Any]]:
        """All logged rows, in order."""
        rows = []
        for i, line in enumerate(self._metric_lines(), start=1):
            try:
                rows.append(json.loads(line))
            except json.JSONDecodeError as err:
                raise ValueError(
                    f"{self.metrics_path}, line {i}: not valid JSON ({err.msg}): {line[:80]!r}"
                ) from err
        return rows

    def metrics_frame(self) -> pd.DataFrame:
        """The logged rows as a DataFrame (one column per metric, ``null`` -> NaN)."""
        rows = self.metrics()
        if not rows:
            return pd.DataFrame({"step": pd.Series([], dtype="int64")})
        return pd.DataFrame.from_records(rows)

    # -- checkpoint ---------------------------------------------------------------------

    @property
    def checkpoint_path(self) -> Path:
        return self.path / self.CHECKPOINT_DIR / self.CHECKPOINT

    def save_checkpoint(self, state: Mapping[str, Any], *, keep_previous: bool = False) -> Path:
        """Atomically save ``state`` (torch.save) to ``checkpoint/state.pt``.

        The saved state also carries ``"_metrics_lines"``: the number of lines in
        ``metrics.jsonl`` at this moment (the caller's dict is not modified).

        Args:
            keep_previous: keep the checkpoint this one replaces as ``state.pt.prev``
                (:meth:`load_checkpoint` with ``previous=True``): runs that checkpoint one
                after another (the seed axis) roll back to a common step after a crash
                between their writes. ``state.pt`` exists at every moment.
        """
        import torch

        if not isinstance(state, Mapping):
            raise TypeError(f"checkpoint state must be a dict, got {type(state).__name__}")
        payload = dict(state)
        payload["_metrics_lines"] = len(self._metric_lines())
        target = self.checkpoint_path
        target.parent.mkdir(parents=True, exist_ok=True)
        tmp = target.with_name(target.name + ".tmp")
        with open(tmp, "wb") as fh:
            torch.save(payload, fh)
            fh.flush()
            os.fsync(fh.fileno())
        if keep_previous and target.exists():  # a second name for the old file, then swap
            prev = target.with_name(target.name + ".prev")
            link = prev.with_name(prev.name + ".tmp")
            link.unlink(missing_ok=True)
            os.link(target, link)
            os.replace(link, prev)
        os.replace(tmp, target)
        self._saved_at = time.monotonic()
        return target

    def checkpoint_due(self) -> bool:
        """True when :func:`checkpoint_seconds` have passed since this object last saved a
        checkpoint (or was made): the training loops then checkpoint before their own
        schedule comes round, so a killed run loses at most that much work."""
        return time.monotonic() - self._saved_at >= checkpoint_seconds()

    def load_checkpoint(self, *, previous: bool = False) -> dict[str, Any] | None:
        """Load the checkpoint (with ``previous``, the one before it, kept by
        ``save_checkpoint(keep_previous=True)``), or return None if there is none.

        ``metrics.jsonl`` is truncated back to the number of lines it had when the
        checkpoint was saved, so a resumed run does not log those steps twice.

        Raises:
            ValueError: ``metrics.jsonl`` has fewer lines than the checkpoint recorded.
        """
        import torch

        path = self.checkpoint_path
        if previous:
            path = path.with_name(path.name + ".prev")
        if not path.exists():
            return None
        try:
            state = torch.load(path, map_location="cpu", weights_only=False)
        except Exception as err:  # noqa: BLE001 - torch raises many kinds for a bad file
            raise RunDirError(
                f"checkpoint {path} is unreadable ({type(err).__name__}: "
                f"{str(err)[:120]}); rerun with --restart to move run {self.name} aside and "
                "train it afresh"
            ) from None
        if not isinstance(state, dict) or "_metrics_lines" not in state:
            raise RunDirError(
                f"checkpoint {path} is not a run checkpoint (no metrics "
                f"count in it); rerun with --restart to move run {self.name} aside"
            )
        keep = int(state["_metrics_lines"])
        lines = self._metric_lines()
        if len(lines) < keep:
            raise RunDirError(
                f"{self.metrics_path} has {len(lines)} lines but the checkpoint "
                f"{path} was saved after {keep}; the metrics file was altered"
            )
        raw = self.metrics_path.read_bytes() if self.metrics_path.exists() else b""
        kept = "".join(line + "\n" for line in lines[:keep]).encode("utf-8")
        if raw != kept:
            atomic_write(self.metrics_path, kept)
        return state

    def rewind(self) -> int:
        """Drop the rows a resumed run will log again; returns how many were dropped.

        With a checkpoint, the rows after it (:meth:`load_checkpoint` does the same when it
        loads); without one, every row: the run starts again from its seed. Only the
        process that holds the run's lock may call it (:func:`vslbook.run_open.open_run`).
        """
        if self.checkpoint_path.exists():
            return 0  # load_checkpoint truncates to the count saved in the checkpoint
        dropped = len(self._metric_lines())
        if self.metrics_path.exists() and self.metrics_path.stat().st_size:
            atomic_write(self.metrics_path, b"")
        return dropped
