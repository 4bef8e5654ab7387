"""Run directories: one training run's configuration, metrics, checkpoints and status.

A *run directory* holds everything one training run leaves behind::

    <root>/<name>/
        config.json       the configuration (sorted keys); its sha256 names the run
        env.json          python, platform, host, package versions, git sha, start time
        metrics.jsonl     one JSON object per ``log`` call, appended, flushed and fsync'ed
        checkpoint/       state.pt, written to state.pt.tmp first and then renamed
        DONE              written last, a JSON summary; its presence marks the run complete
        FAILED            written instead of DONE when a run diverged: step and quantity

Code identity: ``env.json`` records :func:`code_fingerprint` (sha256 of the package's
Python sources that the run can reach) beside the git sha and a dirty flag.
:attr:`RunDir.code_matches` compares it with the running code, so a finished run is
reused only by the code that produced it (:func:`vslbook.training.run`).

Resuming: :meth:`RunDir.save_checkpoint` records how many lines ``metrics.jsonl`` had at
that moment and :meth:`RunDir.load_checkpoint` truncates the file back to that count, so
rows logged between the checkpoint and an interruption are not duplicated when the run
continues from the checkpoint. Together with :func:`rng_state` / :func:`restore_rng_state`
stored in the checkpoint, a resumed run reproduces the numbers of an uninterrupted one.

The ``data/`` tables are :mod:`vslbook.data`; code identity is :mod:`vslbook.provenance`.
"""

from __future__ import annotations

import hashlib
import json
import math
import numbers
import os
import random
import re
from collections.abc import Mapping
from dataclasses import asdict, is_dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from vslbook.provenance import NOT_RUN_CODE, code_fingerprint
from vslbook.provenance import environment as _environment

__all__ = [
    "NOT_RUN_CODE",
    "DivergenceError",
    "RunDir",
    "code_fingerprint",
    "config_hash",
    "restore_rng_state",
    "rng_state",
]

_NAME_OK = re.compile(r"[^A-Za-z0-9._-]+")


class DivergenceError(RuntimeError):
    """A training run produced a non-finite loss, value or parameter.

    Attributes:
        step: the environment step (or iteration) at which it was detected.
        quantity: what was non-finite, e.g. ``"critic_loss"`` or ``"parameter policy.x"``.
        value: the offending value as a float (nan or ±inf) where there is one.
    """

    def __init__(self, step: int, quantity: str, value: float | None = None) -> None:
        self.step, self.quantity, self.value = int(step), str(quantity), value
        shown = "" if value is None else f" ({value})"
        super().__init__(f"diverged at step {self.step}: non-finite {self.quantity}{shown}")


# --------------------------------------------------------------------------- JSON helpers


def _plain(value: Any, where: str = "config") -> Any:
    """Convert ``value`` into plain JSON types (dataclasses, numpy, tuples, paths included)."""
    if is_dataclass(value) and not isinstance(value, type):
        return _plain(asdict(value), where)
    if isinstance(value, Mapping):
        out = {}
        for key, item in value.items():
            if not isinstance(key, str):
                raise TypeError(f"{where}: keys must be strings, got {key!r}")
            out[key] = _plain(item, f"{where}.{key}")
        return out
    if isinstance(value, (list, tuple)):
        return [_plain(item, f"{where}[{i}]") for i, item in enumerate(value)]
    if isinstance(value, np.ndarray):
        return _plain(value.tolist(), where)
    if isinstance(value, np.generic):
        return _plain(value.item(), where)
    if isinstance(value, Path):
        return str(value)
    if value is None or isinstance(value, (bool, int, str)):
        return value
    if isinstance(value, float):
        if not math.isfinite(value):
            raise ValueError(f"{where}: expected a finite number, got {value!r}")
        return value
    raise TypeError(
        f"{where}: cannot store {value!r} of type {type(value).__name__} as JSON; "
        "expected str, int, float, bool, None, list, dict, numpy value or dataclass"
    )


def _canonical_json(config: Mapping[str, Any]) -> str:
    return json.dumps(_plain(config), sort_keys=True, separators=(",", ":"), allow_nan=False)


def config_hash(config: Mapping[str, Any]) -> str:
    """The sha256 (hex) of the canonical JSON form of ``config`` (sorted keys, no spaces)."""
    if not isinstance(config, Mapping) and not is_dataclass(config):
        raise TypeError(f"config must be a dict or a dataclass, got {type(config).__name__}")
    return hashlib.sha256(_canonical_json(config).encode("utf-8")).hexdigest()


def _atomic_write(path: Path, data: bytes) -> None:
    """Write ``data`` to ``path`` through a temporary file, fsync, then rename."""
    tmp = path.with_name(path.name + ".tmp")
    with open(tmp, "wb") as fh:
        fh.write(data)
        fh.flush()
        os.fsync(fh.fileno())
    os.replace(tmp, path)


def _json_bytes(obj: Any) -> bytes:
    return (json.dumps(obj, sort_keys=True, indent=2, allow_nan=False) + "\n").encode("utf-8")


def _metric_value(key: str, value: Any) -> Any:
    """A metric value as stored in ``metrics.jsonl``; non-finite floats become ``None``."""
    if isinstance(value, np.generic):
        value = value.item()
    elif hasattr(value, "item") and callable(value.item) and getattr(value, "ndim", None) == 0:
        value = value.item()  # zero-dimensional numpy arrays and torch tensors
    if value is None or isinstance(value, (bool, str)):
        return value
    if isinstance(value, numbers.Integral):
        return int(value)
    if isinstance(value, numbers.Real):
        value = float(value)
        return value if math.isfinite(value) else None
    raise TypeError(
        f"metric {key!r}: expected an int, float, str, bool or None, "
        f"got {value!r} of type {type(value).__name__}"
    )


# --------------------------------------------------------------------------- run directory


def _default_name(config: Mapping[str, Any]) -> str:
    parts = [str(config[key]) for key in ("algo", "env") if key in config]
    if "seed" in config:
        parts.append(f"s{config['seed']}")
    parts.append(config_hash(config)[:8])
    return _NAME_OK.sub("_", "-".join(parts))


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


class RunDir:
    """One run's directory: config, environment, metrics, checkpoint and completion mark.

    Create a new one (or reopen a matching one to resume) with :meth:`create`; open an
    existing one for reading with :meth:`open`.
    """

    CONFIG = "config.json"
    ENV = "env.json"
    METRICS = "metrics.jsonl"
    CHECKPOINT_DIR = "checkpoint"
    CHECKPOINT = "state.pt"
    DONE = "DONE"
    FAILED = "FAILED"

    def __init__(self, path: str | os.PathLike[str]) -> None:
        self.path = Path(path)

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
        plain = _plain(config)
        if not isinstance(plain, dict):
            raise TypeError(f"config must be a dict or a dataclass, got {type(config).__name__}")
        if name is None:
            name = _default_name(plain)
        elif not name or name in (".", "..") or _NAME_OK.search(name):
            raise ValueError(
                f"run name {name!r} is not a plain directory name; "
                "expected letters, digits, '.', '_' or '-'"
            )
        run = cls(Path(root) / name)
        config_file = run.path / cls.CONFIG
        if config_file.exists():
            existing = json.loads(config_file.read_text(encoding="utf-8"))
            if _canonical_json(existing) != _canonical_json(plain):
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
        _atomic_write(run.path / cls.ENV, _json_bytes(_environment(tuple(code_exclude))))
        _atomic_write(config_file, _json_bytes(plain))
        return run

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
        return json.loads((self.path / self.CONFIG).read_text(encoding="utf-8"))

    @property
    def env(self) -> dict[str, Any]:
        """The stored ``env.json``."""
        return json.loads((self.path / self.ENV).read_text(encoding="utf-8"))

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
        row.update({key: _metric_value(key, value) for key, value in metrics.items()})
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
        _atomic_write(path, data[: data.rfind(b"\n") + 1])

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

    def save_checkpoint(self, state: Mapping[str, Any]) -> Path:
        """Atomically save ``state`` (torch.save) to ``checkpoint/state.pt``.

        The saved state also carries ``"_metrics_lines"``: the number of lines in
        ``metrics.jsonl`` at this moment (the caller's dict is not modified).
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
        os.replace(tmp, target)
        return target

    def load_checkpoint(self) -> dict[str, Any] | None:
        """Load the checkpoint, or return None if there is none.

        ``metrics.jsonl`` is truncated back to the number of lines it had when the
        checkpoint was saved, so a resumed run does not log those steps twice.

        Raises:
            ValueError: ``metrics.jsonl`` has fewer lines than the checkpoint recorded.
        """
        import torch

        if not self.checkpoint_path.exists():
            return None
        state = torch.load(self.checkpoint_path, map_location="cpu", weights_only=False)
        keep = int(state.get("_metrics_lines", 0))
        lines = self._metric_lines()
        if len(lines) < keep:
            raise ValueError(
                f"{self.metrics_path} has {len(lines)} lines but the checkpoint "
                f"{self.checkpoint_path} was saved after {keep}; the metrics file was altered"
            )
        raw = self.metrics_path.read_bytes() if self.metrics_path.exists() else b""
        kept = "".join(line + "\n" for line in lines[:keep]).encode("utf-8")
        if raw != kept:
            _atomic_write(self.metrics_path, kept)
        return state

    # -- completion ---------------------------------------------------------------------

    def mark_done(self, summary: Mapping[str, Any] | None = None) -> None:
        """Write ``DONE`` (a JSON summary); call it as the run's very last step.

        Raises:
            RuntimeError: the run is marked FAILED (a diverged run is never DONE).
        """
        if self.failed:
            raise RuntimeError(f"{self.path} is marked FAILED ({self.failure}); it cannot be DONE")
        _atomic_write(self.path / self.DONE, _json_bytes(_plain(dict(summary or {}), "summary")))

    @property
    def done(self) -> bool:
        """True once :meth:`mark_done` has been called."""
        return (self.path / self.DONE).is_file()

    def mark_failed(self, error: DivergenceError | Mapping[str, Any]) -> None:
        """Write ``FAILED`` (JSON: step, quantity, value, message) for a diverged run."""
        if isinstance(error, DivergenceError):
            info = {"step": error.step, "quantity": error.quantity, "message": str(error),
                    "value": None if error.value is None else repr(error.value)}  # fmt: skip
        else:
            info = dict(error)
        _atomic_write(self.path / self.FAILED, _json_bytes(_plain(info, "failure")))

    @property
    def failed(self) -> bool:
        """True when the run diverged and was marked FAILED."""
        return (self.path / self.FAILED).is_file()

    @property
    def failure(self) -> dict[str, Any] | None:
        """The FAILED record (step, quantity, value, message), or None."""
        if not self.failed:
            return None
        return json.loads((self.path / self.FAILED).read_text(encoding="utf-8"))

    @property
    def status(self) -> str:
        """``"done"``, ``"failed"`` or ``"incomplete"``."""
        return "failed" if self.failed else "done" if self.done else "incomplete"

    @property
    def code_hash(self) -> str | None:
        """The :func:`code_fingerprint` recorded when the run was created (None if older)."""
        try:
            return self.env.get("code_hash")
        except FileNotFoundError:
            return None

    @property
    def code_matches(self) -> bool:
        """True when the run was created by the code that is running now.

        Compared over the same files as when the run was created: ``env.json`` records
        which package paths its fingerprint left out.
        """
        try:
            exclude = tuple(self.env.get("code_excluded", ()))
        except FileNotFoundError:
            exclude = ()
        return self.code_hash == code_fingerprint(exclude)


# --------------------------------------------------------------------------- RNG state


def rng_state(generator: np.random.Generator | None = None) -> dict[str, Any]:
    """Capture python's ``random``, numpy's global RNG, ``generator`` and torch's RNGs.

    The result is picklable and meant to be stored in a checkpoint; pass it and the same
    generator to :func:`restore_rng_state` to continue the exact same random stream.
    """
    import torch

    if generator is not None and not isinstance(generator, np.random.Generator):
        raise TypeError(
            f"generator must be a numpy.random.Generator or None, got {type(generator).__name__}"
        )
    return {
        "python": random.getstate(),
        "numpy_global": np.random.get_state(),  # noqa: NPY002 - the legacy global state itself
        "generator": None if generator is None else generator.bit_generator.state,
        "torch": torch.get_rng_state(),
        "torch_cuda": torch.cuda.get_rng_state_all() if torch.cuda.is_available() else None,
    }


def restore_rng_state(
    state: Mapping[str, Any], generator: np.random.Generator | None = None
) -> None:
    """Restore the RNG states captured by :func:`rng_state` (into ``generator`` as well).

    Raises:
        ValueError: ``state`` is not from :func:`rng_state`, or a generator state is
            present but no generator given (or the other way round).
    """
    import torch

    missing = {"python", "numpy_global", "generator", "torch"} - set(state)
    if missing:
        raise ValueError(
            f"not an rng_state() dict: missing keys {sorted(missing)}; got {sorted(state)}"
        )
    if (state["generator"] is None) != (generator is None):
        raise ValueError(
            "the captured state and the call disagree on the numpy Generator: captured "
            f"{'none' if state['generator'] is None else 'one'}, given "
            f"{'none' if generator is None else type(generator).__name__}"
        )
    random.setstate(state["python"])
    np.random.set_state(state["numpy_global"])  # noqa: NPY002 - restoring the global state
    if generator is not None:
        generator.bit_generator.state = state["generator"]
    torch.set_rng_state(state["torch"])
    if state.get("torch_cuda") is not None and torch.cuda.is_available():
        torch.cuda.set_rng_state_all(state["torch_cuda"])
