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

**Another machine.** The float32 network updates of Chapter 4 round differently on another
CPU (1e-7 to 4e-6 relative by a run's second row, measured between two x86-64 machines with
the same packages), more than the replay's tolerance. So where today's replay differs from
the record, :func:`verify_recorded` replays the run a second time, here, with the code that
made it (its ``git_sha``, taken from the repository with ``git archive`` and accepted only
if its fingerprint is the run's ``code_hash``), in a separate process: if the two replays
agree, the edit since changed no number, and where the record is within
:data:`MACHINE_RTOL` of them the difference is this machine's rounding: the run is
``verified`` (the detail says so). If the replays differ, the edit changed the numbers and
the run stays stale, as it does where the record is further off. Where the recording code
cannot be had (no git, a commit the clone lacks, a run made by uncommitted code), the run
stays stale and the detail says why.
"""

from __future__ import annotations

import io
import json
import math
import os
import subprocess
import sys
import tarfile
import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pandas as pd

from vslbook.budget import BUDGETS, get_budget
from vslbook.experiments.record import entry_stale, read_set, recorded_dir, write_provenance
from vslbook.experiments.run_plan import FIGURE_MODULES
from vslbook.provenance import code_fingerprint
from vslbook.replay import REPLAY_ROWS, numeric_row, rows_match

__all__ = ["MACHINE_RTOL", "VerifyRow", "recorded_rows", "replay_rows",
           "replay_with_recording_code", "verify_recorded", "verify_text"]  # fmt: skip

#: How far a recorded row may be from today's replay on another machine, where the code
#: that made the run replays the same as today's: rounding, not a change. Measured: 1e-7 to
#: 4e-6 relative by the second row of the Chapter 4 runs (float32 networks), 3e-10 for
#: HiREPS on beer pong (float64).
MACHINE_RTOL = 1e-4

#: trains a run's first rows in a fresh folder with whichever ``vslbook`` is importable,
#: and prints them as JSON: ``config`` on stdin, the row count as ``argv[1]``. It uses only
#: what every recorded run's code has (``RunDir.create``, ``Algorithm.train``).
_REPLAY_SCRIPT = """
import json, sys, tempfile
from vslbook.budget import get_budget
from vslbook.registry import get_algorithm, load_plugins
from vslbook.results import RunDir
config, n = json.load(sys.stdin), int(sys.argv[1])
load_plugins()
spec = get_algorithm(str(config["algo"]))
budget = get_budget(config["budget"])
rows = []
with tempfile.TemporaryDirectory(prefix="vslbook-replay-") as tmp:
    rd = RunDir.create(tmp, config, code_exclude=spec.independent_of)
    for _ in range(10_000):
        done = spec.train(rd, dict(config), budget, progress=False, stop_after=1)
        rows = rd.metrics()
        if done is not None or len(rows) >= n:
            break
print(json.dumps(rows[:n]))
"""


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


def replay_rows(config: dict[str, Any], code: str | os.PathLike[str] | None = None,
                rows: int = REPLAY_ROWS) -> list[dict[str, Any]]:
    """The first ``rows`` numeric rows (:func:`vslbook.replay.numeric_row`) of the run
    ``config`` trained afresh in a separate process, with the ``vslbook`` package in the
    folder ``code`` (default: the one imported here).

    Raises:
        RuntimeError: the process failed (its last lines of stderr are in the message).
    """
    out = _run_code(_REPLAY_SCRIPT, code, [str(rows)], json.dumps(config))
    return [numeric_row(r) for r in json.loads(out.strip().splitlines()[-1])]


def _run_code(script: str, code: str | os.PathLike[str] | None, args: list[str] = (),
              stdin: str = "") -> str:  # fmt: skip
    """stdout of ``python -c script *args`` with the ``vslbook`` in the folder ``code``
    (default: the one imported here) first on the path; RuntimeError if it fails."""
    where = Path(code) if code is not None else Path(__file__).resolve().parents[2]
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(
        [str(where), os.environ.get("PYTHONPATH", "")]))
    with tempfile.TemporaryDirectory(prefix="vslbook-replay-cwd-") as cwd:
        done = subprocess.run([sys.executable, "-c", script, *args], input=stdin,
                              capture_output=True, text=True, env=env, cwd=cwd,
                              check=False)  # fmt: skip
    if done.returncode != 0:
        tail = " | ".join(done.stderr.strip().splitlines()[-3:])
        raise RuntimeError(f"running the code in {where} failed ({tail})")
    return done.stdout


def _git_package(sha: str, repo: Path, into: Path) -> Path:
    """``vslbook/`` as commit ``sha`` of ``repo`` held it, extracted into ``into``."""
    done = subprocess.run(["git", "-C", str(repo), "archive", "--format=tar", sha, "vslbook"],
                          capture_output=True, check=False)  # fmt: skip
    if done.returncode != 0:
        why = done.stderr.decode(errors="replace").strip().splitlines()
        raise ValueError(f"git cannot give commit {sha[:12]} ({why[-1] if why else 'no git'})")
    with tarfile.open(fileobj=io.BytesIO(done.stdout)) as tar:
        tar.extractall(into, filter="data")
    return into / "vslbook"


def replay_with_recording_code(entry: dict[str, Any], rows: list[dict[str, Any]],
                               repo: str | os.PathLike[str] | None = None) -> str | None:
    """Replay a recorded run (its provenance ``entry``, its recorded ``rows``) here twice,
    with today's code and with the code that made it (commit ``git_sha`` of ``repo``,
    default the repository this package sits in). None when the two replays agree (to
    :data:`vslbook.replay.RTOL`) and the record is within :data:`MACHINE_RTOL` of them, else
    why not (see the module's docstring)."""
    config = dict(entry.get("config") or {})
    sha, want = entry.get("git_sha"), entry.get("code_hash")
    if not sha or entry.get("git_dirty") or not want:
        return "made by uncommitted code, which cannot be replayed"
    repo = Path(repo) if repo is not None else Path(__file__).resolve().parents[2]
    with tempfile.TemporaryDirectory(prefix="vslbook-recording-code-") as tmp:
        try:
            package = _git_package(str(sha), repo, Path(tmp))
        except ValueError as err:
            return str(err)
        excluded = sorted(set(entry.get("code_excluded") or ()))
        try:
            held = _run_code(f"from vslbook.provenance import code_fingerprint; "
                             f"print(code_fingerprint({excluded!r}))", package.parent)
        except RuntimeError as err:
            return str(err)
        if held.strip() != want:
            return f"commit {sha[:12]} does not hold the code that made the run"
        try:
            then = replay_rows(config, package.parent)
            now = replay_rows(config)
        except RuntimeError as err:
            return str(err)
    why = rows_match(then, now)
    if why is not None:
        return f"today's code computes other numbers than the code that made the run: {why}"
    why = rows_match(rows[:REPLAY_ROWS], now, MACHINE_RTOL)
    return None if why is None else f"the record differs by more than rounding: {why}"


def verify_recorded(figures: list[str] | None = None, budgets: list[str] | None = None,
                    progress: bool = True,
                    repo: str | os.PathLike[str] | None = None) -> list[VerifyRow]:  # fmt: skip
    """Check every recorded run of ``figures`` at ``budgets`` (all when None) against
    today's code (see the module's docstring); rewrites a set's ``provenance.json`` when a
    run was verified. ``repo``: the git repository that holds the commits the runs were
    made at (default: the one this package sits in)."""
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
                note = ""
                if why is not None:
                    other = replay_with_recording_code(entry, recorded_rows(evals, run), repo)
                    if other is not None:
                        out.append(VerifyRow(figure, name, run, "stale", f"{why}; {other}"))
                        continue
                    note = (f"this machine rounds differently from the record ({why}); "
                            "the code that made the run replays the same here")
                now = code_fingerprint(tuple(entry.get("code_excluded") or ()))
                entry["code_hashes_verified"] = [*entry.get("code_hashes_verified", ()), now]
                changed = True
                out.append(VerifyRow(figure, name, run, "verified", note))
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
