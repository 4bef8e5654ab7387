"""The training loops' progress bars: live where someone watches, one line on the site.

Every bar of the package comes from :func:`progress_bar`. What it shows depends on
``$VSLBOOK_PROGRESS``:

``live`` (default, also when unset or empty)
    tqdm.auto's bar, as in JupyterLab (a widget) or a terminal (a text bar, redrawn).
``summary``
    Nothing while the loop runs and one plain line when the bar closes, e.g.
    ``svsl beer-pong s0: 150/150 iterations in 12.3 s``. Inside :func:`run_set_progress`
    (the run-set functions the notebooks call) the bars of the set print nothing
    themselves: the set prints one line for all of them when it ends, and nothing when
    every run was already finished and merely reused. ``book/build.py`` selects this mode
    for the notebooks it executes: a static page cannot redraw a bar, so a live one stays
    on it frozen at ``0%| | 0/N``.
``off``
    Nothing at all.

A bar made with ``disable=True`` (``progress=False`` in the training functions) shows
nothing in every mode. :func:`progress_prefix` puts a label (e.g. an ablation's variant)
before the description of the bars opened inside it.

:func:`frozen_bars` finds tqdm's bar text or widget left in a page (the site's browser
test).
"""

from __future__ import annotations

import os
import re
import sys
import threading
import time
from collections.abc import Iterable, Iterator, Mapping
from contextlib import contextmanager
from typing import Any, TextIO

__all__ = ["MODES", "MODE_ENV", "WIDGET_MIME", "SummaryBar", "find_bar_text", "frozen_bars",
           "progress_bar", "progress_mode", "progress_prefix", "run_set_progress"]  # fmt: skip

#: The environment variable that selects the mode.
MODE_ENV = "VSLBOOK_PROGRESS"
#: Its values; the first is the default.
MODES = ("live", "summary", "off")


def progress_mode() -> str:
    """The mode ``$VSLBOOK_PROGRESS`` selects (``live`` when unset or empty).

    Raises:
        ValueError: a value that is not one of :data:`MODES`.
    """
    value = os.environ.get(MODE_ENV, "").strip()
    if not value:
        return MODES[0]
    if value.lower() not in MODES:
        raise ValueError(f"${MODE_ENV}={value!r} is not a progress mode; expected one of "
                         f"{', '.join(MODES)} (unset: live)")  # fmt: skip
    return value.lower()


def progress_bar(
    iterable: Iterable[Any] | None = None,
    *,
    total: float | None = None,
    initial: float = 0,
    desc: str | None = None,
    unit: str = "it",
    disable: bool = False,
    **tqdm_kwargs: Any,
) -> Any:
    """A progress bar over ``total`` units (or over ``iterable``), from ``initial``.

    Returns tqdm.auto's bar in ``live`` mode (``tqdm_kwargs`` such as ``leave`` go to it),
    else a :class:`SummaryBar` with the same ``update`` / ``set_postfix`` / ``close``
    interface (and iteration, and ``with``). See the module's docstring for the modes.
    """
    mode = progress_mode()
    with _LOCK:
        prefixes = list(_PREFIXES)
    if prefixes:
        desc = ": ".join([*prefixes, *([desc] if desc else [])])
    if mode == "live":
        from tqdm.auto import tqdm

        return tqdm(iterable, total=total, initial=initial, desc=desc, unit=unit,
                    disable=disable, **tqdm_kwargs)  # fmt: skip
    return SummaryBar(iterable, total=total, initial=initial, desc=desc, unit=unit,
                      disable=disable or mode == "off")  # fmt: skip


class SummaryBar:
    """A bar that prints nothing while it runs and one line when it closes (``summary``).

    Inside :func:`run_set_progress` it prints nothing itself: the set reports it. The
    line goes to ``file`` (default: ``sys.stdout`` at the time of printing).
    """

    def __init__(
        self,
        iterable: Iterable[Any] | None = None,
        *,
        total: float | None = None,
        initial: float = 0,
        desc: str | None = None,
        unit: str = "it",
        disable: bool = False,
        file: TextIO | None = None,
    ) -> None:
        if total is None and iterable is not None:
            try:
                total = len(iterable)  # type: ignore[arg-type]
            except (TypeError, AttributeError):
                total = None
        self.iterable = iterable
        self.total, self.initial, self.n = total, initial, initial
        self.desc, self.unit, self.disable, self.file = desc or "", unit, disable, file
        self.postfix: dict[str, Any] = {}
        self.closed = False
        self.start = time.perf_counter()
        self.seconds: float | None = None  # the wall time, once closed
        self._set = None if disable else _open_set()
        if self._set is not None:
            self._set.add(self)

    # -- tqdm's interface ------------------------------------------------------------------
    def update(self, n: float = 1) -> None:
        self.n += n

    def set_postfix(self, ordered_dict: Mapping[str, Any] | None = None, refresh: bool = True,
                    **kwargs: Any) -> None:  # fmt: skip
        self.postfix = {**(ordered_dict or {}), **kwargs}

    def set_postfix_str(self, s: str = "", refresh: bool = True) -> None:
        self.postfix = {"": s} if s else {}

    def set_description(self, desc: str | None = None, refresh: bool = True) -> None:
        self.desc = desc or ""

    def refresh(self, *args: Any, **kwargs: Any) -> None:
        pass

    def clear(self, *args: Any, **kwargs: Any) -> None:
        pass

    def close(self) -> None:
        """Stop the clock; print the line (outside a run set). A second call does nothing."""
        if self.closed:
            return
        self.closed = True
        self.seconds = time.perf_counter() - self.start
        if not self.disable and self._set is None:
            print(self.line(), file=self.file or sys.stdout, flush=True)

    def __enter__(self) -> SummaryBar:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def __iter__(self) -> Iterator[Any]:
        if self.iterable is None:
            raise TypeError("this bar was made without an iterable")
        try:
            for item in self.iterable:
                yield item
                self.n += 1
        finally:
            self.close()

    def __len__(self) -> int:
        return int(self.total or 0)

    # -- the summary -----------------------------------------------------------------------
    def count(self) -> str:
        """``n/total unit`` (``n unit`` without a total), with where a resumed bar began."""
        n, unit = _num(self.n), _UNIT_WORDS.get(self.unit, self.unit)
        text = f"{n} {unit}" if self.total is None else f"{n}/{_num(self.total)} {unit}"
        if self.initial:
            text += f" (resumed at {_num(self.initial)})"
        return text

    def line(self) -> str:
        """The bar's line: description, count, wall time and the last postfix."""
        seconds = time.perf_counter() - self.start if self.seconds is None else self.seconds
        head = f"{self.desc}: " if self.desc else ""
        post = ", ".join(f"{k}={v}" if k else str(v) for k, v in self.postfix.items())
        return f"{head}{self.count()} in {seconds:.1f} s" + (f", {post}" if post else "")


#: Words for tqdm's short units in the summary line.
_UNIT_WORDS = {"it": "iterations"}


def _num(x: float) -> str:
    return str(int(x)) if float(x).is_integer() else f"{x:g}"


class _RunSet:
    """The bars opened while a :func:`run_set_progress` block runs."""

    def __init__(self, label: str) -> None:
        self.label = label
        self.bars: list[SummaryBar] = []
        self.start = time.perf_counter()

    def add(self, bar: SummaryBar) -> None:
        with _LOCK:
            self.bars.append(bar)

    def line(self, failed: bool) -> str | None:
        """One line for the set; None when no run trained in it (all reused)."""
        if not self.bars:
            return None
        for bar in self.bars:
            bar.close()  # the set is over: a bar left open (an early return) ends here
        seconds = time.perf_counter() - self.start
        runs = "; ".join(f"{b.desc} {b.count()}" if b.desc else b.count() for b in self.bars)
        end = " (stopped by an error)" if failed else ""
        return f"{self.label}: trained in {seconds:.1f} s{end}: {runs}"


_LOCK = threading.Lock()
_SETS: list[_RunSet] = []  # the open run sets, outermost first
_PREFIXES: list[str] = []  # the open progress_prefix labels, outermost first


@contextmanager
def progress_prefix(label: str) -> Iterator[None]:
    """Bars opened inside describe themselves as ``label: <their description>`` (all modes)."""
    with _LOCK:
        _PREFIXES.append(label)
    try:
        yield
    finally:
        with _LOCK:
            _PREFIXES.pop()


def _open_set() -> _RunSet | None:
    with _LOCK:
        return _SETS[0] if _SETS else None


@contextmanager
def run_set_progress(label: str) -> Iterator[None]:
    """The bars opened inside report as one line of the run set ``label`` (``summary``).

    In ``summary`` mode the line, printed when the block ends, names the set, its wall
    time and each trained run's count, e.g. ``Fig. 4.4a runs: trained in 8.1 s: diskill
    hopper-jump s0 2/2 iterations; bbrl hopper-jump s0 2/2 iterations``; nothing is printed
    when no bar was opened (every run reused). A set opened inside another adds to the
    outer one. In the other modes the block changes nothing.
    """
    if progress_mode() != "summary":
        yield
        return
    run_set = _RunSet(label)
    with _LOCK:
        nested = bool(_SETS)  # the outer set collects this one's bars (see SummaryBar)
        if not nested:
            _SETS.append(run_set)
    if nested:
        yield
        return
    failed = True
    try:
        yield
        failed = False
    finally:
        with _LOCK:
            _SETS.remove(run_set)
        line = run_set.line(failed)
        if line is not None:
            print(line, flush=True)


# tqdm's bar text: "  0%|          | 0/150 [00:00<?, ?it/s]", "100%|██████| 2/2 [00:01<...",
# with or without a description or postfix, also with unit scaling ("1.5k/10k").
_BAR = re.compile(r"\d{1,3}%\|[^|\n]*\|\s*[\d.]+[kMGTP]?/[\d.]+[kMGTP]?\s*\[")


#: The output type of a Jupyter widget (tqdm's bar in a notebook), which a static page
#: shows as an empty box or, with its text form, as a bar frozen where it was drawn.
WIDGET_MIME = "application/vnd.jupyter.widget-view+json"


def find_bar_text(text: str) -> list[str]:
    """The lines of ``text`` that hold a tqdm bar (a frozen one on a static page)."""
    return [line.strip() for line in text.splitlines() if _BAR.search(line)]


def frozen_bars(text: str, html: str = "") -> list[str]:
    """What a static page shows of progress bars: each line of its rendered ``text`` that
    holds a tqdm bar, and one entry per widget output left in its ``html``."""
    found = [f"bar text {line!r}" for line in find_bar_text(text)]
    n = html.count(WIDGET_MIME)
    return found + ([f"{n} widget output(s) ({WIDGET_MIME})"] if n else [])
