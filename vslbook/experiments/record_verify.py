"""``vslbook results --verify``: is a recorded run set still what today's code computes?

A recorded run keeps the fingerprint of the code that made it (``provenance.json``). After
an edit the fingerprint differs, but most edits change no number. :func:`verify_recorded`
settles it the way ``vslbook run`` does before it resumes a partial run
(:mod:`vslbook.replay`): it replays the first rows of each run whose fingerprint differs,
from the run's own configuration and seed, and compares them with the recorded rows,
numeric metrics only (the tables keep no others), floats to
:data:`vslbook.replay.RTOL` / :data:`vslbook.replay.ATOL`.

* equal: the run is current; today's fingerprint is added to its provenance
  (``code_hashes_verified``), so ``vslbook results`` no longer calls it stale;
* different: the run stays stale, and the first difference is printed.

Runs whose fingerprint equals today's are ``current`` without a replay.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import pandas as pd

from vslbook.budget import BUDGETS, get_budget
from vslbook.experiments.record import entry_stale, read_set, recorded_dir, write_provenance
from vslbook.experiments.run_plan import FIGURE_MODULES
from vslbook.provenance import code_fingerprint

__all__ = ["VerifyRow", "recorded_rows", "verify_recorded", "verify_text"]


@dataclass(frozen=True)
class VerifyRow:
    """One recorded run checked: its figure, budget and name, ``state`` (``current``:
    made or verified by today's code; ``verified``: replayed equal just now; ``stale``:
    replayed different, or could not be replayed) and the reason for a stale one."""

    figure: str
    budget: str
    run: str
    state: str
    detail: str = ""


def recorded_rows(evals: pd.DataFrame, run: str) -> list[dict[str, Any]]:
    """The metrics rows of ``run`` in a recorded ``evals`` table, in step order, as
    ``metrics.jsonl`` held them (numeric metrics only; NaN read back as ``None``)."""
    long = evals[evals["run"] == run]
    rows: dict[int, dict[str, Any]] = {}
    for step, metric, value in zip(long["step"], long["metric"], long["value"], strict=True):
        row = rows.setdefault(int(step), {"step": int(step)})
        row[metric] = None if math.isnan(value) else float(value)
    return [rows[s] for s in sorted(rows)]


def _replay(entry: dict[str, Any], rows: list[dict[str, Any]]) -> str | None:
    from vslbook.registry import get_algorithm, load_plugins
    from vslbook.replay import replay_matches

    load_plugins()
    config = dict(entry.get("config") or {})
    try:
        spec = get_algorithm(str(config["algo"]))
        budget = get_budget(config["budget"])
    except (KeyError, ValueError) as err:
        return f"its provenance names no trainable run ({err})"
    return replay_matches(spec, config, rows, budget, numeric_only=True)


def verify_recorded(figures: list[str] | None = None, budgets: list[str] | None = None,
                    progress: bool = True) -> list[VerifyRow]:  # fmt: skip
    """Check every recorded run of ``figures`` at ``budgets`` (all when None) against
    today's code (see the module's docstring); rewrites a set's ``provenance.json`` when a
    run was verified."""
    from vslbook.progress import progress_bar

    out: list[VerifyRow] = []
    for figure in figures or list(FIGURE_MODULES):
        for name in budgets or list(BUDGETS):
            directory = recorded_dir(figure, name)
            if not (directory / "runs.csv").exists():
                continue
            runs, evals, provenance = read_set(directory)
            changed = False
            for run in progress_bar(list(runs["run"]), desc=f"verify {figure} {name}",
                                    unit="runs", disable=not progress, leave=False):  # fmt: skip
                entry = provenance.get(run, {})
                if not entry_stale(entry):
                    out.append(VerifyRow(figure, name, run, "current"))
                    continue
                why = _replay(entry, recorded_rows(evals, run))
                if why is not None:
                    out.append(VerifyRow(figure, name, run, "stale", why))
                    continue
                now = code_fingerprint(tuple(entry.get("code_excluded") or ()))
                entry["code_hashes_verified"] = [*entry.get("code_hashes_verified", ()), now]
                changed = True
                out.append(VerifyRow(figure, name, run, "verified"))
            if changed:
                write_provenance(directory, {"figure": figure, "budget": name,
                                             "runs": provenance})  # fmt: skip
    return out


def verify_text(rows: list[VerifyRow]) -> str:
    """One line per checked run, then the counts."""
    if not rows:
        return "no recorded run sets to verify"
    lines = [f"{r.state:9s} {r.figure} {r.budget} {r.run}" + (f"  ({r.detail})" if r.detail
             else "") for r in rows]  # fmt: skip
    counts = {s: sum(r.state == s for r in rows) for s in ("current", "verified", "stale")}
    lines.append(", ".join(f"{n} {s}" for s, n in counts.items()))
    return "\n".join(lines)
