"""Aggregate statistics as the thesis reports them: IQM with stratified-bootstrap CIs.

Scores are arranged as rliable expects them: a matrix of shape ``(runs, tasks)`` per
method, runs being independent seeds. The interquartile mean (IQM) is the mean of the
middle 50 % of the scores (``scipy.stats.trim_mean(..., 0.25)``, rliable's definition).
Confidence intervals are percentile intervals of a *stratified* bootstrap: runs are
resampled with replacement within each task, tasks are kept.

Every function takes a ``seed`` and gives the same numbers twice. rliable 1.2 draws its
bootstrap indices from numpy's *global* RNG (``np.random.choice``) even when a
``RandomState`` is passed, so the rliable calls here run inside
:func:`seeded_numpy_global`, which seeds the global RNG and restores its previous state
afterwards; callers' own use of ``np.random`` is left undisturbed.
"""

from __future__ import annotations

import contextlib
import warnings
import zlib
from collections.abc import Callable, Iterator, Mapping, Sequence
from typing import Any

import numpy as np
import pandas as pd
from rliable import library as rly
from rliable import metrics
from scipy.stats import trim_mean

from vslbook.budget import get_budget

__all__ = [
    "aggregate_iqm",
    "final_scores",
    "interval_estimates",
    "iqm",
    "iqm_curve",
    "performance_profile",
    "seeded_numpy_global",
]

#: fraction cut from each end for the interquartile mean (rliable's ``aggregate_iqm``)
IQM_CUT = 0.25
#: upper bound on array elements materialised at once by :func:`iqm_curve`
_CHUNK_ELEMENTS = 4_000_000


# --------------------------------------------------------------------------- helpers


def _check_seed(seed: int) -> int:
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise ValueError(f"seed must be a non-negative integer, got {seed!r}")
    return int(seed)


def _reps(reps: int | None) -> int:
    if reps is None:
        return get_budget().bootstrap_reps
    if isinstance(reps, bool) or not isinstance(reps, (int, np.integer)) or reps < 1:
        raise ValueError(f"reps must be a positive integer, got {reps!r}")
    return int(reps)


def _check_confidence(confidence: float) -> float:
    if not 0.0 < confidence < 1.0:
        raise ValueError(f"confidence must lie strictly between 0 and 1, got {confidence!r}")
    return float(confidence)


def _as_scores(name: str, scores: Any) -> np.ndarray:
    """A finite float matrix of shape (runs, tasks, ...) with at least one run."""
    arr = np.asarray(scores, dtype=float)
    if arr.ndim < 2 or arr.shape[0] < 1 or arr.shape[1] < 1:
        raise ValueError(
            f"scores for {name!r}: expected an array of shape (runs, tasks), got shape "
            f"{arr.shape}; reshape a single task's runs with scores.reshape(-1, 1)"
        )
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"scores for {name!r} contain NaN or infinite values")
    return arr


@contextlib.contextmanager
def seeded_numpy_global(seed: int) -> Iterator[None]:
    """Seed numpy's global RNG for the duration of a ``with`` block, then restore it."""
    seed = _check_seed(seed)
    saved = np.random.get_state()  # noqa: NPY002 - rliable draws from the global RNG
    np.random.seed(seed % 2**32)  # noqa: NPY002
    try:
        yield
    finally:
        np.random.set_state(saved)  # noqa: NPY002


# --------------------------------------------------------------------------- IQM


def iqm(scores: Any) -> float | np.ndarray:
    """Interquartile mean over runs (axis 0).

    A 1-D array of runs gives a float; a ``(runs, tasks)`` array gives one IQM per task.
    Uses ``scipy.stats.trim_mean(scores, 0.25, axis=0)``: ``floor(0.25 n)`` values are
    cut from each end before averaging.
    """
    arr = np.asarray(scores, dtype=float)
    if arr.ndim == 0 or arr.shape[0] == 0:
        raise ValueError(f"iqm needs at least one run along axis 0, got shape {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError("iqm: scores contain NaN or infinite values")
    out = trim_mean(arr, IQM_CUT, axis=0)
    return float(out) if np.ndim(out) == 0 else np.asarray(out)


def aggregate_iqm(scores: np.ndarray) -> np.ndarray:
    """IQM over all runs and tasks together, as a length-1 array (rliable's aggregate)."""
    return np.array([metrics.aggregate_iqm(scores)])


def interval_estimates(
    score_dict: Mapping[str, Any],
    func: Callable[[np.ndarray], Any] = aggregate_iqm,
    reps: int | None = None,
    confidence: float = 0.95,
    seed: int = 0,
    *,
    method: str = "percentile",
) -> tuple[dict[str, np.ndarray], dict[str, np.ndarray]]:
    """Point estimates and stratified-bootstrap CIs of ``func`` for each method.

    Args:
        score_dict: method name -> scores of shape ``(runs, tasks)`` (arrays or frames).
        func: aggregate of a score matrix returning a 1-D array (a scalar is wrapped);
            default :func:`aggregate_iqm`.
        reps: bootstrap resamples; default the active budget's ``bootstrap_reps``.
        confidence: coverage of the interval.
        seed: seeds the bootstrap; the same seed gives the same intervals.
        method: rliable/arch interval method (``percentile``, ``basic``, ``bc``, ``bca``).

    Returns:
        ``(point, ci)``: ``point[name]`` has shape ``(k,)``, ``ci[name]`` shape ``(2, k)``
        with lower bounds in row 0 and upper bounds in row 1.
    """
    if not score_dict:
        raise ValueError("score_dict is empty; expected {method name: (runs, tasks) scores}")
    arrays = {str(name): _as_scores(str(name), scores) for name, scores in score_dict.items()}
    reps = _reps(reps)
    confidence = _check_confidence(confidence)
    seed = _check_seed(seed)

    def aggregate(scores: np.ndarray) -> np.ndarray:
        return np.atleast_1d(np.asarray(func(scores), dtype=float))

    with seeded_numpy_global(seed), warnings.catch_warnings():
        # arch deprecates ``random_state`` in favour of ``seed``; rliable still passes it.
        warnings.filterwarnings("ignore", category=FutureWarning, module=r"arch\.")
        point, ci = rly.get_interval_estimates(
            arrays,
            aggregate,
            method=method,
            reps=reps,
            confidence_interval_size=confidence,
            random_state=np.random.RandomState(seed),
        )
    return dict(point), dict(ci)


# --------------------------------------------------------------------------- IQM curves


def _group_seed(seed: int, key: Any) -> np.random.Generator:
    """One generator per group, independent of which other groups are present."""
    return np.random.default_rng([seed, zlib.crc32(repr(key).encode("utf-8"))])


def _bootstrap_iqm_rows(
    values: np.ndarray, reps: int, confidence: float, rng: np.random.Generator
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """IQM and percentile CI per row of ``values`` (rows: x points, columns: runs).

    One resample of the runs (an index vector of length ``n_runs``) is drawn per bootstrap
    replicate and applied to every row, i.e. whole curves are resampled.
    """
    n_x, n_runs = values.shape
    point = trim_mean(values, IQM_CUT, axis=1)
    idx = rng.integers(0, n_runs, size=(reps, n_runs))
    alpha = 100 * (1.0 - confidence) / 2
    lo = np.empty(n_x)
    hi = np.empty(n_x)
    step = max(1, _CHUNK_ELEMENTS // (reps * n_runs))
    for start in range(0, n_x, step):
        block = values[start : start + step]  # (b, n_runs)
        stats = trim_mean(block[:, idx], IQM_CUT, axis=2)  # (b, reps)
        lo[start : start + step], hi[start : start + step] = np.percentile(
            stats, [alpha, 100 - alpha], axis=1
        )
    return point, lo, hi


def _curve_one_group(
    frame: pd.DataFrame, x: str, y: str, run: str, reps: int, confidence: float,
    rng: np.random.Generator,
) -> pd.DataFrame:
    table = frame.pivot(index=x, columns=run, values=y).sort_index()
    values = table.to_numpy(dtype=float)
    present = np.isfinite(values)
    point = np.empty(len(table))
    lo = np.empty(len(table))
    hi = np.empty(len(table))
    # x points are bootstrapped together when the same runs are present at them.
    patterns: dict[bytes, list[int]] = {}
    for i, mask in enumerate(present):
        patterns.setdefault(mask.tobytes(), []).append(i)
    for rows in patterns.values():
        cols = present[rows[0]]
        if not cols.any():
            continue
        sub = values[np.ix_(rows, np.flatnonzero(cols))]
        point[rows], lo[rows], hi[rows] = _bootstrap_iqm_rows(sub, reps, confidence, rng)
    out = pd.DataFrame(
        {x: table.index.to_numpy(), "iqm": point, "lo": lo, "hi": hi,
         "n_runs": present.sum(axis=1)}
    )
    return out[out["n_runs"] > 0].reset_index(drop=True)


def iqm_curve(
    df: pd.DataFrame,
    x: str = "env_steps",
    y: str = "mean_return",
    run: str = "seed",
    group: str | None = None,
    reps: int | None = None,
    seed: int = 0,
    confidence: float = 0.95,
) -> pd.DataFrame:
    """IQM over runs at each ``x`` with a stratified-bootstrap CI (one task per group).

    For each ``x`` the runs' ``y`` values form a ``(runs, 1)`` score matrix; its IQM is
    rliable's (``trim_mean`` 25 %). The bootstrap is vectorised over ``x``: each of the
    ``reps`` replicates draws ``n_runs`` run indices with replacement (from
    ``numpy.random.default_rng([seed, crc32(group)])``) and applies them to all ``x``
    points of the group, so the band is the bootstrap distribution of whole curves;
    ``lo``/``hi`` are its percentiles (``percentile`` method, as rliable's default).
    Points where only some runs were evaluated are bootstrapped over the runs present.
    Runs with non-finite ``y`` values (a diverged run logs ``null``, read as NaN) are not
    dropped silently: a warning names them and how many points of theirs were unusable,
    and the returned frame's ``attrs["unused_runs"]`` maps each such run to that count.

    Args:
        df: long-format frame with columns ``x``, ``y``, ``run`` (and ``group``).
        group: optional column (e.g. ``"env"`` or ``"method"``); one curve per value.
        reps: bootstrap resamples; default the active budget's ``bootstrap_reps``.

    Returns:
        Columns ``[group,] x, iqm, lo, hi, n_runs``, sorted by group and ``x``.
    """
    needed = [c for c in (x, y, run, group) if c is not None]
    missing = [c for c in needed if c not in df.columns]
    if missing:
        raise ValueError(
            f"iqm_curve: column(s) {missing} not in the frame; available: {list(df.columns)}"
        )
    keys = [c for c in (group, x, run) if c is not None]
    dup = df.duplicated(subset=keys)
    if dup.any():
        first = df.loc[dup, keys].iloc[0].to_dict()
        raise ValueError(f"iqm_curve: more than one {y!r} value for {first}; expected one")
    reps = _reps(reps)
    confidence = _check_confidence(confidence)
    seed = _check_seed(seed)
    bad = df[~np.isfinite(pd.to_numeric(df[y], errors="coerce").to_numpy(dtype=float))]
    unused = {str(k): int(v) for k, v in bad.groupby(run).size().items()}
    if unused:
        listed = ", ".join(f"{k} ({v} point{'s' if v > 1 else ''})" for k, v in unused.items())
        warnings.warn(
            f"iqm_curve: {len(unused)} run(s) have non-finite {y!r} values that could not be "
            f"used: {listed}",
            stacklevel=2,
        )
    if group is None:
        out = _curve_one_group(df, x, y, run, reps, confidence, _group_seed(seed, None))
        out.attrs["unused_runs"] = unused
        return out
    parts = []
    for key, frame in df.groupby(group, sort=True):
        curve = _curve_one_group(frame, x, y, run, reps, confidence, _group_seed(seed, key))
        curve.insert(0, group, key)
        parts.append(curve)
    columns = [group, x, "iqm", "lo", "hi", "n_runs"]
    out = pd.concat(parts, ignore_index=True) if parts else pd.DataFrame(columns=columns)
    out.attrs["unused_runs"] = unused
    return out


# --------------------------------------------------------------------------- profiles


def performance_profile(
    score_dict: Mapping[str, Any],
    taus: Sequence[float] | np.ndarray,
    reps: int | None = None,
    seed: int = 0,
    *,
    use_score_distribution: bool = True,
    confidence: float = 0.95,
) -> tuple[dict[str, np.ndarray], dict[str, np.ndarray]]:
    """Performance profiles (fraction of runs with score > tau) with bootstrap CIs.

    Thin wrapper around ``rly.create_performance_profile``; it has no random-state
    argument, so the call runs inside :func:`seeded_numpy_global` (numpy's global RNG
    is restored afterwards).

    Returns:
        ``(profiles, cis)``: ``profiles[name]`` shape ``(len(taus),)``, ``cis[name]``
        shape ``(2, len(taus))``.
    """
    if not score_dict:
        raise ValueError("score_dict is empty; expected {method name: (runs, tasks) scores}")
    arrays = {str(name): _as_scores(str(name), scores) for name, scores in score_dict.items()}
    tau_arr = np.asarray(taus, dtype=float)
    if tau_arr.ndim != 1 or tau_arr.size == 0:
        raise ValueError(f"taus must be a non-empty 1-D sequence, got shape {tau_arr.shape}")
    with seeded_numpy_global(seed):
        profiles, cis = rly.create_performance_profile(
            arrays,
            tau_arr,
            use_score_distribution=use_score_distribution,
            reps=_reps(reps),
            confidence_interval_size=_check_confidence(confidence),
        )
    return dict(profiles), dict(cis)


# --------------------------------------------------------------------------- final scores


def final_scores(
    df: pd.DataFrame,
    task: str = "env",
    x: str = "env_steps",
    y: str = "mean_return",
    run: str = "seed",
    tasks: Sequence[str] | None = None,
) -> pd.DataFrame:
    """Scores at each task's last evaluation point as a ``(runs, tasks)`` table.

    Rows are runs (index ``run``), columns tasks in the order of ``tasks`` (default:
    sorted). ``final_scores(df).to_numpy()`` is a score matrix for
    :func:`interval_estimates`; normalise the columns first when tasks have
    different return scales.

    Raises:
        ValueError: a missing column, an unknown task, or a run without a value at its
            task's last evaluation point.
    """
    missing = [c for c in (task, x, y, run) if c not in df.columns]
    if missing:
        raise ValueError(
            f"final_scores: column(s) {missing} not in the frame; available: {list(df.columns)}"
        )
    available = sorted(df[task].unique().tolist())
    if tasks is None:
        tasks = available
    unknown = [t for t in tasks if t not in available]
    if unknown:
        raise ValueError(f"unknown task(s) {unknown}; expected some of: {', '.join(available)}")
    columns = {}
    for name in tasks:
        frame = df[df[task] == name]
        last = frame[x].max()
        at_last = frame[frame[x] == last].set_index(run)[y]
        if at_last.index.duplicated().any():
            raise ValueError(
                f"task {name!r}: more than one {y!r} value per run at {x}={last}; expected one"
            )
        absent = sorted(set(frame[run]) - set(at_last.index))
        if absent:
            raise ValueError(
                f"task {name!r}: run(s) {absent} have no value at the last evaluation point "
                f"{x}={last}"
            )
        columns[name] = at_last
    out = pd.DataFrame(columns)
    out.index.name = run
    return out.sort_index()
