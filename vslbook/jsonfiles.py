"""JSON and atomic files: how a run directory and ``data/`` store their records.

Configs are stored as plain JSON with sorted keys (:func:`plain_json` turns dataclasses,
numpy values, tuples and paths into JSON types); :func:`config_hash` is the sha256 of that
canonical form and names a run. Files are replaced atomically (:func:`atomic_write`: a
temporary file, fsync, rename), so a crash leaves either the old file or the new one.
"""

from __future__ import annotations

import hashlib
import json
import math
import numbers
import os
from collections.abc import Mapping
from dataclasses import asdict, is_dataclass
from pathlib import Path
from typing import Any

import numpy as np

from vslbook.run_errors import RunDirError

__all__ = [
    "atomic_write",
    "canonical_json",
    "config_hash",
    "json_bytes",
    "metric_value",
    "plain_json",
    "read_json",
]


def plain_json(value: Any, where: str = "config") -> Any:
    """Convert ``value`` into plain JSON types (dataclasses, numpy, tuples, paths included)."""
    if is_dataclass(value) and not isinstance(value, type):
        return plain_json(asdict(value), where)
    if isinstance(value, Mapping):
        out = {}
        for key, item in value.items():
            if not isinstance(key, str):
                raise TypeError(f"{where}: keys must be strings, got {key!r}")
            out[key] = plain_json(item, f"{where}.{key}")
        return out
    if isinstance(value, (list, tuple)):
        return [plain_json(item, f"{where}[{i}]") for i, item in enumerate(value)]
    if isinstance(value, np.ndarray):
        return plain_json(value.tolist(), where)
    if isinstance(value, np.generic):
        return plain_json(value.item(), where)
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


def canonical_json(config: Mapping[str, Any]) -> str:
    return json.dumps(plain_json(config), sort_keys=True, separators=(",", ":"), allow_nan=False)


def config_hash(config: Mapping[str, Any]) -> str:
    """The sha256 (hex) of the canonical JSON form of ``config`` (sorted keys, no spaces)."""
    if not isinstance(config, Mapping) and not is_dataclass(config):
        raise TypeError(f"config must be a dict or a dataclass, got {type(config).__name__}")
    return hashlib.sha256(canonical_json(config).encode("utf-8")).hexdigest()


def atomic_write(path: Path, data: bytes) -> None:
    """Write ``data`` to ``path`` through a temporary file, fsync, then rename."""
    tmp = path.with_name(path.name + ".tmp")
    with open(tmp, "wb") as fh:
        fh.write(data)
        fh.flush()
        os.fsync(fh.fileno())
    os.replace(tmp, path)


def json_bytes(obj: Any) -> bytes:
    return (json.dumps(obj, sort_keys=True, indent=2, allow_nan=False) + "\n").encode("utf-8")


def metric_value(key: str, value: Any) -> Any:
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


def read_json(path: Path) -> Any:
    """The JSON in ``path``; a file that is not JSON is a :class:`RunDirError` naming it."""
    try:
        return json.loads(path.read_text(encoding="utf-8"))
    except (json.JSONDecodeError, UnicodeDecodeError) as err:
        raise RunDirError(
            f"{path} is not valid JSON ({err}); repair it, or delete its run directory "
            f"{path.parent} (or rerun with --restart) to train the run afresh"
        ) from None
