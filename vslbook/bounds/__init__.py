"""Numerical checks of the thesis's derivations, shared by the notebooks and the tests.

Every check compares two numbers, a left-hand side and a right-hand side of an equation or
inequality of the thesis, and records the tolerance it was judged with. A notebook displays
them; a test calls :meth:`Check.require` or :meth:`CheckReport.require`.

``foundations``  Chapter 2: soft value iteration, self-paced curricula, mixture gating, the
                 Ornstein-Uhlenbeck forward process, KL chain rules, mutual information
``svsl``         Chapter 3: the decomposition of SVSL's objective and its per-part lower bounds
                 (experts, context distributions, weights), the REPS update of the weights
``diskill``      Chapter 4: the same bounds with energy-based context distributions, their
                 sample form (Eq. 4.8), the energy normaliser and the gating
``dime``         Chapter 5: denoising score matching, the entropy lower bound of a diffusion
                 policy and its gap, the soft Bellman contraction, soft policy iteration, general
                 bridges and DIME as their special case
"""

from __future__ import annotations

import math
from collections.abc import Iterator, Mapping
from dataclasses import dataclass, field

import numpy as np

__all__ = ["Check", "CheckReport", "relative_tol", "show"]

_RELATIONS = ("==", "<=")


@dataclass(frozen=True)
class Check:
    """One numerical comparison ``lhs <relation> rhs`` within ``tol``.

    Attributes:
        name: what is being compared, in words.
        equation: the thesis equation(s) it verifies, e.g. ``"Eq. 2.60"``.
        lhs: left-hand side.
        rhs: right-hand side.
        tol: absolute tolerance (non-negative).
        relation: ``"=="`` passes when ``|lhs - rhs| <= tol``; ``"<="`` when
            ``lhs <= rhs + tol``.
    """

    name: str
    equation: str
    lhs: float
    rhs: float
    tol: float
    relation: str = "=="

    def __post_init__(self) -> None:
        if self.relation not in _RELATIONS:
            raise ValueError(f"relation must be one of {_RELATIONS}, got {self.relation!r}")
        for attr in ("lhs", "rhs", "tol"):
            object.__setattr__(self, attr, float(getattr(self, attr)))
        if not self.tol >= 0:
            raise ValueError(f"tol must be a non-negative number, got {self.tol!r}")

    @property
    def gap(self) -> float:
        """``lhs - rhs``."""
        return self.lhs - self.rhs

    @property
    def passed(self) -> bool:
        """Whether the comparison holds within ``tol`` (NaNs never pass)."""
        if self.relation == "==":
            return abs(self.gap) <= self.tol
        return self.lhs <= self.rhs + self.tol

    def require(self) -> Check:
        """Return ``self`` if the check passed, otherwise raise ``AssertionError``."""
        if not self.passed:
            raise AssertionError(f"check failed: {self}")
        return self

    def _detail(self) -> str:
        if self.relation == "==":
            return f"|lhs - rhs| = {abs(self.gap):.2e}, tol {self.tol:.1e}"
        return f"lhs - rhs = {self.gap:.2e}, tol {self.tol:.1e}"

    def __str__(self) -> str:
        status = "PASS" if self.passed else "FAIL"
        return (
            f"[{status}] {self.name} ({self.equation}): {self.lhs:.6g} {self.relation} "
            f"{self.rhs:.6g} ({self._detail()})"
        )

    def _repr_markdown_(self) -> str:
        status = "✅" if self.passed else "❌"
        rel = "=" if self.relation == "==" else "≤"
        name = self.name.replace("*", r"\*").replace("_", r"\_")
        return (
            f"{status} **{name}** ({self.equation}): `{self.lhs:.6g}` {rel} "
            f"`{self.rhs:.6g}` ({self._detail()})"
        )


@dataclass(frozen=True, eq=False)
class CheckReport:
    """The checks of one experiment plus the arrays a notebook needs to plot it.

    Attributes:
        title: what the experiment verifies.
        checks: the individual comparisons.
        data: named numpy arrays for plotting (documented by the function that builds it).
    """

    title: str
    checks: tuple[Check, ...]
    data: Mapping[str, np.ndarray] = field(default_factory=dict)

    @property
    def passed(self) -> bool:
        """Whether every check passed."""
        return all(check.passed for check in self.checks)

    @property
    def failed(self) -> list[Check]:
        """The checks that did not pass."""
        return [check for check in self.checks if not check.passed]

    def __getitem__(self, name: str) -> Check:
        for check in self.checks:
            if check.name == name:
                return check
        raise KeyError(f"no check named {name!r}; have {[c.name for c in self.checks]}")

    def __iter__(self) -> Iterator[Check]:
        return iter(self.checks)

    def __len__(self) -> int:
        return len(self.checks)

    def require(self) -> CheckReport:
        """Return ``self`` if every check passed, otherwise raise ``AssertionError``."""
        if not self.passed:
            lines = "\n  ".join(str(check) for check in self.failed)
            raise AssertionError(f"{self.title}: {len(self.failed)} check(s) failed:\n  {lines}")
        return self

    def __str__(self) -> str:
        return "\n".join([self.title, *(f"  {check}" for check in self.checks)])

    def _repr_markdown_(self) -> str:
        return "\n".join(
            [f"**{self.title}**", "", *(f"- {check._repr_markdown_()}" for check in self.checks)]
        )


def show(report: CheckReport) -> CheckReport:
    """Display ``report`` (as Markdown in a notebook, as text elsewhere) and stop if a check
    failed: what each notebook does with every report, so a failed check halts the book."""
    if not isinstance(report, CheckReport):
        raise TypeError(f"show expects a CheckReport, got {type(report).__name__}")
    try:
        from IPython import get_ipython
        from IPython.display import display
    except ImportError:  # a plain interpreter without IPython
        get_ipython = None
    if get_ipython is not None and get_ipython() is not None:
        display(report)
    else:
        print(report)
    return report.require()


def relative_tol(*values: float, rtol: float = 1e-9) -> float:
    """A tolerance ``rtol * max(1, |values|)`` for comparing numbers of the given scale."""
    return rtol * max([1.0, *(abs(v) for v in values if math.isfinite(v))])
