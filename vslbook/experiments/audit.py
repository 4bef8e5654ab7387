"""Every Chapter 3 and 4 setting against the thesis's text and the code that made its figure.

The project's rule: the authors' code drew the thesis's figures (Di-SkilL,
``github:ALRhub/di-skill``, for Chapter 4; SVSL, ``github:Onur4229/SVSL_LMOE``, for
Chapter 3; fancy-gym and mp_pytorch for the primitives). Where code and text differ, a run
that reproduces a figure uses the code's choice by default and keeps the text's as a named
option. This module lays the three side by side, one row per setting:

* ``thesis`` and ``authors' code``: values typed into :mod:`vslbook.experiments.audit_tasks`
  and :mod:`vslbook.experiments.audit_algorithms_ch3` / :mod:`~.audit_algorithms_ch4`, each
  with where it was read (table, section, equation; repository, path, line), or
  ``"not found"`` / ``"not stated"``;
* ``ours``: read at run time from the package's objects (task instances of
  :func:`vslbook.envs.robot.make_task`, :func:`vslbook.erl.diskill_config.diskill_config`,
  :func:`vslbook.erl.svsl_config.svsl_config`, the HiREPS / LaDiPS presets, the PPO
  configurations), never typed;
* ``ours = code`` and ``ours = thesis``: computed (None where the other side is not known).

:func:`task_audit` and :func:`algorithm_audit` build the tables, :func:`show_audit` gives a
compact view with a ``≠`` marker for the notebooks.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
import pandas as pd

__all__ = [
    "COLUMNS",
    "NOT_FOUND",
    "NOT_STATED",
    "Setting",
    "algorithm_audit",
    "audit_frame",
    "same_value",
    "show_audit",
    "task_audit",
]

#: What the code column says where the authors' code has no such value (or it is not public).
NOT_FOUND = "not found"
#: What the thesis column says where the thesis gives no value.
NOT_STATED = "not stated"

#: The columns of an audit table, in order.
COLUMNS = (
    "subject",
    "field",
    "thesis",
    "thesis source",
    "authors' code",
    "code source",
    "ours",
    "ours read from",
    "figures affected",
    "choice and why",
    "ours = code",
    "ours = thesis",
)


@dataclass(frozen=True)
class Setting:
    """One audited setting: typed thesis and code values with their sources, and how to
    read ours from the subject object.

    Attributes:
        subject: the key of the object the row is about (a task name, or
            ``"method/task"`` for an algorithm configuration).
        field: what the setting is.
        thesis, thesis_where: the thesis's value and where it stands (or :data:`NOT_STATED`).
        code, code_where: the authors' code's value and where (or :data:`NOT_FOUND` twice).
        ours: an attribute path on the subject (``"spec.tau_bounds"``) or a function of it.
        figures: the figures the setting affects.
        choice: which side ours follows and why.
    """

    subject: str
    field: str
    thesis: Any
    thesis_where: str
    code: Any
    code_where: str
    ours: str | Callable[[Any], Any]
    figures: str
    choice: str


def _known(value: Any) -> bool:
    return not (isinstance(value, str) and value in (NOT_FOUND, NOT_STATED))


def _flat(value: Any) -> np.ndarray | None:
    """Numbers (and nested sequences of numbers) as a flat float array, else None."""
    if isinstance(value, (bool, np.bool_, str)) or value is None:
        return None
    try:
        arr = np.asarray(value, dtype=np.float64).reshape(-1)
    except (TypeError, ValueError):
        return None
    return arr


def same_value(a: Any, b: Any) -> bool | None:
    """Whether two audited values agree: numbers (and number sequences of the same length)
    to a relative 1e-9, anything else by ``==``; None if either is "not found"/"not stated"."""
    if not (_known(a) and _known(b)):
        return None
    ba, bb = isinstance(a, (bool, np.bool_)), isinstance(b, (bool, np.bool_))
    if ba or bb:
        return ba and bb and bool(a) == bool(b)
    if a is None or b is None:
        return a is None and b is None
    fa, fb = _flat(a), _flat(b)
    if fa is not None and fb is not None:
        return fa.shape == fb.shape and bool(np.allclose(fa, fb, rtol=1e-9, atol=1e-12))
    if (fa is None) != (fb is None):
        return False
    return bool(a == b)


def _read(subject: Any, ours: str | Callable[[Any], Any]) -> Any:
    if callable(ours):
        return ours(subject)
    value = subject
    for part in ours.split("."):
        try:
            value = getattr(value, part)
        except AttributeError as err:
            raise AttributeError(
                f"audit: {type(subject).__name__} has no {ours!r} (failed at {part!r})"
            ) from err
    return value


def _show(value: Any) -> str:
    """A short text for a value: numbers with up to 6 significant digits."""
    if isinstance(value, str):
        return value
    if isinstance(value, (bool, np.bool_)) or value is None:
        return str(value)
    flat = _flat(value)
    if flat is not None:
        fmt = [f"{v:.6g}" for v in flat]
        if np.ndim(value) == 0:
            return fmt[0]
        shape = np.shape(value)
        if len(shape) == 2:
            rows = [", ".join(fmt[i * shape[1] : (i + 1) * shape[1]]) for i in range(shape[0])]
            return "; ".join(f"[{r}]" for r in rows)
        return "[" + ", ".join(fmt) + "]"
    return str(value)


def _where(ours: str | Callable[[Any], Any]) -> str:
    if callable(ours):
        doc = (ours.__doc__ or "").strip()
        return doc or getattr(ours, "__name__", "function")
    return ours


def audit_frame(settings: list[Setting], subjects: Mapping[str, Any]) -> pd.DataFrame:
    """The audit table of ``settings`` with ours read from ``subjects[setting.subject]``."""
    rows = []
    for s in settings:
        if s.subject not in subjects:
            raise KeyError(f"audit: no object for subject {s.subject!r}")
        ours = _read(subjects[s.subject], s.ours)
        rows.append(
            {
                "subject": s.subject,
                "field": s.field,
                "thesis": _show(s.thesis),
                "thesis source": s.thesis_where,
                "authors' code": _show(s.code),
                "code source": s.code_where,
                "ours": _show(ours),
                "ours read from": _where(s.ours),
                "figures affected": s.figures,
                "choice and why": s.choice,
                "ours = code": same_value(ours, s.code),
                "ours = thesis": same_value(ours, s.thesis),
            }
        )
    return pd.DataFrame(rows, columns=list(COLUMNS))


def task_audit(task_options: Mapping[str, Mapping[str, Any]] | None = None) -> pd.DataFrame:
    """The robot tasks of Chapters 3 and 4 against thesis and authors' code.

    Args:
        task_options: task name → keyword arguments of :func:`vslbook.envs.robot.make_task`
            (default: every task with its default options, the ones the figures use).
    """
    from vslbook.envs.robot import make_task
    from vslbook.experiments.audit_tasks import TASK_SETTINGS

    options = dict(task_options or {})
    names = sorted({s.subject for s in TASK_SETTINGS})
    unknown = sorted(set(options) - set(names))
    if unknown:
        raise ValueError(f"task_audit: no audited task {unknown}; audited: {names}")
    tasks = {n: make_task(n, **options.get(n, {})) for n in names}
    try:
        return audit_frame(TASK_SETTINGS, tasks)
    finally:
        for t in tasks.values():
            t.close()


def algorithm_audit(chapter: int, configs: Mapping[str, Any] | None = None) -> pd.DataFrame:
    """Chapter 3's (SVSL, HiREPS, LaDiPS, PPO) or Chapter 4's (Di-SkilL, LinDi-SkilL, BBRL,
    Di-SkilLV2/V3, PPO) hyper-parameters against thesis and authors' code.

    Args:
        chapter: 3 or 4.
        configs: subject (``"method/task"``, see the table's ``subject`` column) → a
            configuration object to audit instead of the package's preset.
    """
    from vslbook.experiments import audit_algorithms_ch3 as ch3
    from vslbook.experiments import audit_algorithms_ch4 as ch4

    if chapter not in (3, 4):
        raise ValueError(f"chapter must be 3 or 4, got {chapter!r}")
    settings, objects = (
        (ch3.ch3_settings(), ch3.ch3_configs())
        if chapter == 3
        else (ch4.ch4_settings(), ch4.ch4_configs())
    )
    extra = dict(configs or {})
    unknown = sorted(set(extra) - set(objects))
    if unknown:
        raise ValueError(f"algorithm_audit: no subject {unknown}; known: {sorted(objects)}")
    return audit_frame(settings, {**objects, **extra})


def show_audit(frame: pd.DataFrame, *, only_differences: bool = False) -> pd.DataFrame:
    """A compact view of an audit table for a notebook: a ``≠`` column (``"≠ code"`` where
    ours differs from the authors' code, ``"≠ thesis"`` where it differs from the text,
    both where both), then subject, field, the three values and the choice.

    Args:
        frame: a table of :func:`task_audit` or :func:`algorithm_audit`.
        only_differences: keep only the rows where ours differs from the code.
    """
    missing = [c for c in COLUMNS if c not in frame.columns]
    if missing:
        raise ValueError(f"show_audit: not an audit table (missing columns {missing})")

    def mark(row: pd.Series) -> str:
        marks = [
            label
            for col, label in (("ours = code", "≠ code"), ("ours = thesis", "≠ thesis"))
            if row[col] is False
        ]
        return ", ".join(marks)

    view = frame.assign(**{"≠": frame.apply(mark, axis=1)})
    if only_differences:
        view = view[view["ours = code"].map(lambda v: v is False)]
    cols = ["≠", "subject", "field", "thesis", "authors' code", "ours", "choice and why"]
    return view[cols].reset_index(drop=True)
