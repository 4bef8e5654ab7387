"""Methods compared at equal executed episodes (Fig. 4.3b's "needs more samples").

The thesis says of table tennis that Di-SkilLV3 "needs more samples" to reach Di-SkilL and
that SVSL "needs more samples to reach about 80 %". A run that stops early (a probe, or a
method with a cheap budget) is therefore compared with the others at the executed episodes
*it* reached, not at the others' end. :func:`at_samples` reads each run's test value there:
the last test at or before that count, exactly as logged (no interpolation, so every number
is one test of 75 contexts that a reader can find in the run's ``metrics.jsonl``).
:func:`reached` gives each run's last executed-episode count, the counts to compare at;
:func:`compare_lines` puts the two together for the runs that stop short.

Executed episodes are the ``samples`` column of ``metrics.jsonl``: θ rejected before
simulation are not counted (:mod:`vslbook.experiments.svsl_mixtures`).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from vslbook.results import RunDir

__all__ = ["at_samples", "compare_lines", "reached"]


def _tests(path: str | Path, y: str) -> pd.DataFrame:
    """A run's test rows (``step``, ``samples``, ``y``), in logged order."""
    df = RunDir.open(path).metrics_frame()
    if y not in df.columns or "samples" not in df.columns:
        raise ValueError(f"{path}: metrics.jsonl has no {y!r} or no 'samples' column")
    value = pd.to_numeric(df[y], errors="coerce")
    return df.loc[np.isfinite(value), ["step", "samples", y]].reset_index(drop=True)


def reached(runs: dict[str, list[str | Path]], y: str = "test_success") -> pd.DataFrame:
    """Each run's last test: columns ``method``, ``seed`` (its place in the list), ``step``,
    ``samples`` (executed episodes by then) and ``y``."""
    rows = []
    for method, paths in runs.items():
        for seed, path in enumerate(paths):
            t = _tests(path, y)
            if t.empty:
                raise ValueError(f"{path}: no test row with {y!r} yet")
            rows.append({"method": method, "seed": seed, **t.iloc[-1].to_dict()})
    return pd.DataFrame(rows, columns=["method", "seed", "step", "samples", y]).astype(
        {"step": int}
    )


def at_samples(
    runs: dict[str, list[str | Path]], samples: float, y: str = "test_success"
) -> pd.DataFrame:
    """Each run's last test at or before ``samples`` executed episodes: columns ``method``,
    ``seed``, ``step``, ``samples`` (the count at that test) and ``y``.

    A run that had not tested by ``samples``, or stopped short of it (it would say where it
    stopped, not where it was at ``samples``), gets ``step`` −1 and NaN.
    """
    if not np.isfinite(samples) or samples < 0:
        raise ValueError(f"samples must be a finite count >= 0, got {samples!r}")
    if not runs:
        raise ValueError("runs is empty; expected {method: [run directories]}")
    rows = []
    for method, paths in runs.items():
        for seed, path in enumerate(paths):
            t = _tests(path, y)
            before = t[t["samples"] <= samples]
            if before.empty or t["samples"].iloc[-1] < samples:
                rows.append({"method": method, "seed": seed, "step": -1,
                             "samples": np.nan, y: np.nan})  # fmt: skip
            else:
                rows.append({"method": method, "seed": seed, **before.iloc[-1].to_dict()})
    out = pd.DataFrame(rows, columns=["method", "seed", "step", "samples", y])
    return out.astype({"step": int})


def compare_lines(
    runs: dict[str, list[str | Path]],
    reference: str = "diskill",
    *,
    full: tuple[str, ...] = ("diskill", "bbrl"),
    labels: dict[str, str] | None = None,
    y: str = "test_success",
) -> list[str]:
    """One line per run of a method not in ``full`` (those that stop short: probes, SVSL):
    its last test and the executed episodes by then, followed by the ``reference`` method's
    seeds at :func:`at_samples` of that count. ``labels`` names the methods."""
    if reference not in runs or not runs[reference]:
        raise ValueError(f"reference {reference!r} has no runs; expected one of {sorted(runs)}")
    name = (labels or {}).get
    ends = reached(runs, y)
    lines = []
    for run in ends[~ends["method"].isin(full)].itertuples():
        lines.append(f"{name(run.method, run.method)} seed {run.seed}: {getattr(run, y):.1%} "
                     f"at iteration {run.step}, after {run.samples / 1e6:.3f} M executed "
                     "episodes")  # fmt: skip
        ref = at_samples({reference: runs[reference]}, run.samples, y)
        lines.append(f"    {name(reference, reference)} then: " + ", ".join(
            f"seed {r.seed}: {getattr(r, y):.1%} (iteration {r.step})" if r.step >= 0
            else f"seed {r.seed}: not there yet" for r in ref.itertuples()))  # fmt: skip
    return lines
