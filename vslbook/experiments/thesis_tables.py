"""The thesis's hyper-parameter tables beside the values our runs use.

Tables A.1-A.5 (Chapter 3), B.1-B.7 (Chapter 4) and C.1-C.3 (Chapter 5). Each table's
cells are typed in a chapter module (:mod:`~vslbook.experiments.thesis_tables_ch3`,
:mod:`~vslbook.experiments.thesis_tables_ch4`, :mod:`~vslbook.experiments.thesis_tables_ch5`)
row by row as the thesis prints them; those are *the thesis's* values. The ``ours`` value
of a cell is read when the table is built from the configuration object a run uses:
``vslbook run ALGO --env ENV --budget full`` (:meth:`vslbook.registry.Algorithm.default_config`,
the same object the notebooks' run sets train), or, for Table C.1, the environment that
:func:`vslbook.envs.step_based.make_step_env` builds. The full budget is the reference:
a budget scales counts only (experts N and iterations K of SVSL, seeds, steps), so at
``reduced`` or ``smoke`` those counts are smaller and everything else is as printed here.

A few cells are not configuration fields but facts of the code (tanh layers, Adam, full
covariances): those say ``fixed: <where>`` in the ``ours from`` column. Columns of the
thesis's tables that this package does not run (the Chapter 5 diffusion baselines, BRO,
SVSL on Chapter 4's table tennis) keep the thesis's values with ``ours`` = "not run here".

Where ours differs from the thesis on purpose (mostly: the authors' code, which made the
figure, has another value; see :mod:`vslbook.experiments.audit`), the ``why`` column says
so, taking the audit's reason where the audit has the row.

    thesis_table("A.1")        # a DataFrame, one row per cell
    show_thesis_table("B.5")   # the thesis's layout, ours beside each value, ≠ highlighted
    thesis_summary()           # cells compared / agreeing / differing per table
"""

from __future__ import annotations

import functools
import importlib
import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np
import pandas as pd

if TYPE_CHECKING:
    from pandas.io.formats.style import Styler

__all__ = [
    "COLUMNS",
    "NOT_RUN",
    "TABLES",
    "differs",
    "fmt",
    "show_thesis_table",
    "thesis_summary",
    "thesis_table",
]

#: The tables, in the thesis's order.
TABLES = (
    "A.1", "A.2", "A.3", "A.4", "A.5",
    "B.1", "B.2", "B.3", "B.4", "B.5", "B.6", "B.7",
    "C.1", "C.2", "C.3",
)  # fmt: skip
#: What ``ours`` says for a task or method of the thesis's table that this package does not run.
NOT_RUN = "not run here"
#: The columns of :func:`thesis_table`, in order.
COLUMNS = ("table", "row", "parameter", "thesis", "ours", "differs", "ours from", "why")

_MODULES = {"A": "thesis_tables_ch3", "B": "thesis_tables_ch4", "C": "thesis_tables_ch5"}


# ----------------------------------------------------------------------------------------
# how a table is typed (used by the chapter modules)
# ----------------------------------------------------------------------------------------
class Prose(str):
    """A thesis cell that is words, not a value ("varies (see section 3.4.1)"): not compared."""


@dataclass(frozen=True)
class Shown:
    """A number with the thesis's way of writing it (``log 30``, ``4·dim(A)``, ``N(0, 2.5)``)."""

    value: float
    text: str


@dataclass(frozen=True)
class Fixed:
    """A value fixed in the code rather than a configuration field (tanh layers, Adam)."""

    value: Any
    where: str


@dataclass(frozen=True)
class Via:
    """A value computed from the configuration object; ``where`` says from which field
    (``".alpha (…)"``: the config's class name is put in front) or from what."""

    fn: Callable[[Any], Any]
    where: str


#: How ``ours`` is read for one parameter: a field name of the configuration object, a
#: :class:`Via`, a :class:`Fixed`, or None where the parameter does not apply (thesis "–").
Reader = str | Via | Fixed | None


@dataclass(frozen=True)
class Unavailable:
    """What a source's ``config()`` returns when the object cannot be built here."""

    reason: str


@dataclass(frozen=True)
class Source:
    """One task or method of a table and where its ``ours`` values come from.

    Attributes:
        label: the task or method as the thesis's table names it.
        config: builds the configuration object (or :class:`Unavailable`); None: the
            package does not run it.
        how: the run (or object) it is, or why there is none.
        readers: parameter → :data:`Reader`.
    """

    label: str
    config: Callable[[], Any] | None
    how: str
    readers: Mapping[str, Reader] = field(default_factory=dict)


@dataclass(frozen=True)
class FromAudit:
    """The reason :func:`vslbook.experiments.audit.algorithm_audit` gives ("choice and why")
    for (``subject``, ``field``), or ``text`` where the audit has no such row."""

    chapter: int
    subject: str
    field: str
    text: str


@dataclass(frozen=True)
class Spec:
    """One of the thesis's tables.

    ``rows`` are the thesis's rows as printed: a label, then one cell per ``header`` label.
    With ``params_are_columns`` (Tables A.x, C.1) the row labels are the sources' labels and
    the header the parameters; otherwise (B.x, C.2, C.3) the rows are parameters and the
    header the sources (tasks or methods). ``why``: (source label, parameter) → the reason
    ours differs (a string or :class:`FromAudit`).
    """

    name: str
    caption: str
    header: tuple[str, ...]
    rows: tuple[tuple[Any, ...], ...]
    sources: tuple[Source, ...]
    params_are_columns: bool
    why: Mapping[tuple[str, str], str | FromAudit] = field(default_factory=dict)
    note: str = ""

    @property
    def params(self) -> tuple[str, ...]:
        return self.header if self.params_are_columns else tuple(r[0] for r in self.rows)

    def cells(self) -> list[tuple[Source, str, Any]]:
        """(source, parameter, thesis value) in the thesis's reading order (row by row)."""
        by_label = {s.label: s for s in self.sources}
        out = []
        for row in self.rows:
            label, values = row[0], row[1:]
            if len(values) != len(self.header):
                raise ValueError(f"Table {self.name}: row {label!r} has {len(values)} cells, "
                                 f"the header {len(self.header)}")  # fmt: skip
            for col, value in zip(self.header, values, strict=True):
                src, param = (label, col) if self.params_are_columns else (col, label)
                out.append((by_label[src], param, value))
        return out


def run_source(label: str, algo: str, env: str, readers: Mapping[str, Reader],
               **overrides: Any) -> Source:  # fmt: skip
    """The source whose configuration is ``vslbook run ALGO --env ENV [--set ...] --budget
    full``'s (:meth:`vslbook.registry.Algorithm.default_config`)."""
    sets = "".join(f" --set {k}={v}" for k, v in overrides.items())

    def config() -> Any:
        from vslbook.budget import get_budget
        from vslbook.registry import get_algorithm

        return get_algorithm(algo).default_config(env, get_budget("full"), overrides)

    return Source(label, config, f"vslbook run {algo} --env {env}{sets} --budget full", readers)


# ----------------------------------------------------------------------------------------
# reading, comparing, showing
# ----------------------------------------------------------------------------------------
def _spec(name: Any) -> Spec:
    if not isinstance(name, str) or name not in TABLES:
        raise ValueError(f"unknown thesis table {name!r}; expected one of {', '.join(TABLES)}")
    module = importlib.import_module(f"vslbook.experiments.{_MODULES[name[0]]}")
    return module.SPECS[name]


def _read(config: Any, reader: Reader) -> tuple[Any, str]:
    """(ours, where it was read) for one reader."""
    if reader is None:
        return None, "does not apply"
    if isinstance(reader, Fixed):
        return reader.value, f"fixed: {reader.where}"
    if isinstance(reader, Via):  # a where starting with "." names a field of the config
        where = reader.where
        return reader.fn(config), type(config).__name__ + where if where[:1] == "." else where
    return getattr(config, reader), f"{type(config).__name__}.{reader}"


def _plain(value: Any) -> Any:
    return value.value if isinstance(value, Shown) else value


def differs(thesis: Any, ours: Any) -> bool | None:
    """Whether ours differs from the thesis's cell: numbers (and sequences of numbers) to a
    relative 1e-9, anything else by ``==``; "–" (None) only equals "–". None where the two
    cannot be compared (prose in the thesis, a source not run here or unavailable)."""
    from vslbook.experiments.audit import same_value

    if isinstance(thesis, Prose) or isinstance(ours, Unavailable) or (
        isinstance(ours, str) and ours == NOT_RUN
    ):
        return None
    thesis, ours = _plain(thesis), _plain(ours)
    if isinstance(thesis, list):
        thesis = tuple(thesis)
    if isinstance(ours, list):
        ours = tuple(ours)
    if isinstance(thesis, str) and isinstance(ours, str):
        return thesis.strip().lower() != ours.strip().lower()
    return not same_value(thesis, ours)


def fmt(value: Any) -> str:
    """A cell as text: "–" for None, ``[64, 64]`` for sizes, numbers with up to 6 digits."""
    if value is None:
        return "–"
    if isinstance(value, Shown):
        return value.text
    if isinstance(value, Unavailable):
        return "unavailable"
    if isinstance(value, (bool, np.bool_, str)):
        return str(value)
    if isinstance(value, (tuple, list)):
        return "[" + ", ".join(fmt(v) for v in value) + "]"
    if isinstance(value, (int, np.integer)):
        return str(int(value))
    if isinstance(value, (float, np.floating)):
        v = float(value)
        if math.isfinite(v) and v.is_integer() and abs(v) < 1e7:
            return str(int(v))
        return f"{v:.6g}"
    return str(value)


@functools.lru_cache(maxsize=2)
def _audit_reasons(chapter: int) -> dict[tuple[str, str], str]:
    from vslbook.experiments.audit import algorithm_audit

    frame = algorithm_audit(chapter)
    keys = zip(frame["subject"], frame["field"], strict=True)
    return dict(zip(keys, frame["choice and why"], strict=True))


def _reason(reason: str | FromAudit) -> str:
    if isinstance(reason, FromAudit):
        found = _audit_reasons(reason.chapter).get((reason.subject, reason.field))
        return f"{found} [audit: {reason.subject}]" if found else reason.text
    return reason


def thesis_table(name: str) -> pd.DataFrame:
    """Table ``name`` (one of :data:`TABLES`) as a DataFrame, one row per cell.

    Columns (:data:`COLUMNS`): ``table``; ``row``, the task or method; ``parameter``;
    ``thesis`` and ``ours`` as text ("–": does not apply); ``differs`` (True, False, or None
    where they cannot be compared); ``ours from``, the configuration field (or the code)
    it was read from; ``why``: the reason where ours differs or is not compared.
    ``frame.attrs`` holds ``caption``, ``note`` and ``sources`` (label → run or object).

    Raises:
        ValueError: for an unknown table name; the message lists the names.
    """
    spec = _spec(name)
    objects = {s.label: NOT_RUN if s.config is None else s.config() for s in spec.sources}
    rows = []
    for src, param, thesis in spec.cells():
        obj = objects[src.label]
        if obj is NOT_RUN or isinstance(obj, Unavailable):
            ours, where = obj, src.how if obj is NOT_RUN else obj.reason
        else:
            if param not in src.readers:
                raise KeyError(f"Table {name}: {src.label} has no reader for {param!r}")
            ours, where = _read(obj, src.readers[param])
        d = differs(thesis, ours)
        why = ""
        if (src.label, param) in spec.why:
            why = _reason(spec.why[src.label, param])
        elif d is None:
            why = where if obj is NOT_RUN or isinstance(obj, Unavailable) else "not compared"
        elif d:
            why = "no reason recorded"
        rows.append({
            "table": spec.name, "row": src.label, "parameter": param, "thesis": fmt(thesis),
            "ours": NOT_RUN if obj is NOT_RUN else fmt(ours), "differs": d,
            "ours from": "" if obj is NOT_RUN else where, "why": why,
        })  # fmt: skip
    frame = pd.DataFrame(rows, columns=list(COLUMNS))
    # True / False / None as Python objects (a column without None would become numpy bools)
    frame["differs"] = pd.Series([r["differs"] for r in rows], dtype=object, index=frame.index)
    frame.attrs["caption"] = f"Table {spec.name}: {spec.caption}"
    frame.attrs["note"] = spec.note
    frame.attrs["sources"] = {s.label: s.how for s in spec.sources}
    return frame


def thesis_summary(names: tuple[str, ...] | list[str] = TABLES) -> pd.DataFrame:
    """Per table: cells, how many are compared, agree and differ, and the differing cells."""
    out = []
    for name in names:
        t = thesis_table(name)
        diff = t[t["differs"].map(lambda v: v is True)]
        out.append({
            "table": name, "caption": t.attrs["caption"].split(": ", 1)[1], "cells": len(t),
            "compared": int(t["differs"].map(lambda v: v is not None).sum()),
            "agree": int(t["differs"].map(lambda v: v is False).sum()), "differ": len(diff),
            "differences": "; ".join(f"{r.row} {r.parameter}: {r.thesis} → {r.ours}"
                                     for r in diff.itertuples()),
        })  # fmt: skip
    return pd.DataFrame(out)


_DIFF = "background-color: #ffd7d7"
_NA = "color: #888888"
_CAPTION = [{"selector": "caption",
             "props": "caption-side: top; text-align: left; font-size: 0.9em"}]  # fmt: skip


def show_thesis_table(name: str, *, layout: str = "thesis") -> Styler:
    """Table ``name`` styled for a notebook, differing cells highlighted.

    Args:
        name: one of :data:`TABLES`.
        layout: ``"thesis"`` (default): the thesis's rows and columns, each column split
            into ``thesis`` and ``ours``; ``"long"``: :func:`thesis_table`'s one row per
            cell with its ``why`` and ``ours from``.

    The caption gives the table, where ``ours`` comes from, and why each ≠ cell differs.
    """
    if layout not in ("thesis", "long"):
        raise ValueError(f"unknown layout {layout!r}; expected 'thesis' or 'long'")
    t = thesis_table(name)
    spec = _spec(name)
    notes = [t.attrs["caption"]]
    if spec.note:
        notes.append(spec.note)
    skipped = t[t["ours"] == NOT_RUN].drop_duplicates("row")
    notes += [f"{r.row}: {r.why}" for r in skipped.itertuples()]
    diff = t[t["differs"].map(lambda v: v is True)]
    notes += [f"≠ {r.row}, {r.parameter}: {r.why}" for r in diff.itertuples()]
    caption = "<br>".join(_escape(n) for n in notes)
    if layout == "long":
        view = t.drop(columns="table").assign(
            differs=t["differs"].map(lambda v: "≠" if v else "" if v is False else "n/a"))

        def style_row(row: pd.Series) -> list[str]:
            d = t.loc[row.name, "differs"]
            return [_DIFF if d is True else _NA if d is None else ""] * len(row)

        styler = view.style.apply(style_row, axis=1).hide(axis="index")
        return styler.set_caption(caption).set_table_styles(_CAPTION)
    index = [r[0] for r in spec.rows]
    columns = pd.MultiIndex.from_product([spec.header, ["thesis", "ours"]])
    wide = pd.DataFrame("", index=pd.Index(index, name=""), columns=columns)
    marks = pd.DataFrame("", index=wide.index, columns=columns)
    for r in t.itertuples():
        rlabel, clabel = (r.row, r.parameter) if spec.params_are_columns else (r.parameter, r.row)
        wide.loc[rlabel, (clabel, "thesis")] = r.thesis
        wide.loc[rlabel, (clabel, "ours")] = r.ours
        style = _DIFF if r.differs is True else _NA if r.differs is None else ""
        marks.loc[rlabel, (clabel, "thesis")] = marks.loc[rlabel, (clabel, "ours")] = style
    styler = wide.style.apply(lambda _: marks, axis=None)
    return styler.set_caption(caption).set_table_styles(_CAPTION)


def _escape(text: str) -> str:
    return text.replace("&", "&amp;").replace("<", "&lt;").replace(">", "&gt;")
