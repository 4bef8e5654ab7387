"""``vslbook results``: the final IQM of every recorded (figure, method, budget), and
whether the code that made a recorded run has changed since (:func:`entry_stale`).

Split from :mod:`vslbook.experiments.record`, which writes the sets this module reads.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from vslbook.budget import BUDGETS
from vslbook.data import results_dir
from vslbook.experiments.run_plan import FIGURE_MODULES, figure_runs
from vslbook.provenance import code_fingerprint

__all__ = ["MAX_REPS", "entry_stale", "result_rows", "results_text"]

#: most bootstrap resamples :func:`result_rows` draws (``full`` asks for 50 000)
MAX_REPS = 2000


def entry_stale(entry: dict[str, Any]) -> bool:
    """True when the code the run can reach now is neither the code that made it nor code
    that replayed its first rows identically (``code_hashes_verified``, written by
    ``vslbook run`` on resume or by ``vslbook results --verify``)."""
    now = code_fingerprint(tuple(entry.get("code_excluded") or ()))
    return now != entry.get("code_hash") and now not in entry.get("code_hashes_verified", ())


def _number(value: float) -> float | None:
    return float(value) if math.isfinite(value) else None


def result_rows(figures: list[str] | None = None) -> list[dict[str, Any]]:
    """One row per recorded (figure, method, budget), in figure, budget and method order.

    Keys: ``figure``, ``method``, ``task``, ``budget``, ``seeds`` (finished runs with a
    final value), ``probes`` (runs recorded while still training: counted, never scored),
    ``metric`` (the one the figure plots for the method's algorithm), ``iqm``, ``ci_low``,
    ``ci_high`` (IQM of each run's final evaluation, i.e. its last row with the metric, with
    a 95 % stratified bootstrap over seeds: seed 0, the budget's ``bootstrap_reps`` but at
    most :data:`MAX_REPS`; None where no run has a value) and ``stale`` (a run's recorded code
    fingerprint differs from what the same files give now).
    """
    from vslbook import stats
    from vslbook.experiments.record import figure_metric, read_set, recorded_dir, task_of_env

    rows = []
    for figure in figures or list(FIGURE_MODULES):
        for b in BUDGETS.values():
            directory = recorded_dir(figure, b)
            if not (directory / "runs.csv").exists():
                continue
            runs, evals, provenance = read_set(directory)
            probes = runs[runs["status"] != "done"]  # drawn, never scored: only counted
            finals = evals[evals["value"].notna()].sort_values(["run", "step"], kind="stable")
            finals = finals.groupby(["run", "metric"]).last()  # each run's last value of each
            order = list(dict.fromkeys(r.method for r in figure_runs(figure, b)))
            methods = order + sorted(set(runs["method"]) - set(order))
            pairs = [(m, env) for m in methods
                     for env in dict.fromkeys(runs.loc[runs["method"] == m, "env"])]  # fmt: skip
            for method, env in pairs:  # one row per task of the figure (Fig. 3.2 has two)
                task = task_of_env(env)
                mine = runs[(runs["method"] == method) & (runs["env"] == env)]
                names = sorted(mine.loc[mine["status"] == "done", "run"])
                metric = figure_metric(figure, str(mine["algo"].iloc[0]))
                values = np.array([finals.loc[(n, metric), "value"] for n in names
                                   if (n, metric) in finals.index])  # fmt: skip
                iqm = low = high = math.nan
                if len(values):
                    point, ci = stats.interval_estimates(
                        {method: values[:, None]}, reps=min(b.bootstrap_reps, MAX_REPS), seed=0)
                    iqm, low, high = point[method][0], ci[method][0, 0], ci[method][1, 0]
                rows.append({
                    "figure": figure, "method": method, "task": task, "budget": b.name,
                    "seeds": len(values), "probes": int(mine["run"].isin(probes["run"]).sum()),
                    "metric": metric, "iqm": _number(iqm),
                    "ci_low": _number(low), "ci_high": _number(high),
                    "stale": any(entry_stale(provenance.get(n, {})) for n in mine["run"]),
                })  # fmt: skip
    return rows


def results_text(rows: list[dict[str, Any]]) -> str:
    """:func:`result_rows` as an aligned table (a note when nothing is recorded)."""
    if not rows:
        return (f"no recorded run sets in {results_dir()}; record one with "
                "vslbook record FIGURE --budget B --root DIR")  # fmt: skip

    def num(x: float | None) -> str:
        return "-" if x is None else f"{x:.4g}"

    head = ("figure", "method", "task", "budget", "seeds", "probes", "metric", "IQM [95% CI]",
            "stale")  # fmt: skip
    table = [head] + [
        (r["figure"], r["method"], r["task"], r["budget"], str(r["seeds"]), str(r["probes"]),
         r["metric"],
         f"{num(r['iqm'])} [{num(r['ci_low'])}, {num(r['ci_high'])}]",
         "stale" if r["stale"] else "")
        for r in rows
    ]  # fmt: skip
    widths = [max(len(row[i]) for row in table) for i in range(len(head))]
    return "\n".join("  ".join(c.ljust(w) for c, w in zip(row, widths, strict=True)).rstrip()
                     for row in table)  # fmt: skip
