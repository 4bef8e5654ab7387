"""Recorded results: a figure's finished runs as registered tables in ``data/results/``.

``vslbook record FIGURE --budget B --root DIR`` (:func:`record`) exports the runs of
``FIGURE`` at ``B`` (:func:`vslbook.experiments.run_plan.figure_runs`) that are finished in
``DIR`` into ``data/results/<figure>/<budget>/``:

``runs.csv``
    one row per run: run, figure, method, algo, env, seed, budget, config_hash, status;
``evals.csv.gz``
    every numeric row of each ``metrics.jsonl`` in long format: run, step, metric, value;
``provenance.json``
    per run its config, seed, budget, code fingerprint (and the paths it left out), git
    sha and dirty flag, package versions, host, python and platform, start time, wall time
    and the date it was recorded;
``checkpoints/<run>.pt.gz``
    the final checkpoint of the first seed of each method and task
    (:func:`vslbook.experiments.recorded_runs.record_checkpoints`), registered in
    ``checkpoints/registry.json``;
``registry.json``
    the sha256 and row count of the three files (:func:`vslbook.data.register_file`), so
    a damaged or hand-edited table is an error, never a silently wrong plot.

Only runs that are ``DONE``, whose metrics match what ``DONE`` recorded
(:meth:`~vslbook.results.RunDir.check_done`) and that the current code made or reproduces
(:attr:`~vslbook.results.RunDir.code_matches`; a run made by other code is replayed first,
:mod:`vslbook.replay`) are recorded; with ``--partial`` a run still training is recorded
too, up to its last checkpoint, as a *probe* (``runs.csv`` status ``incomplete``), which the
figures draw and never score. A set grows across machines
and sessions: recording again merges with what the folder holds (the root's copy of a run
wins) and rewrites the tables deterministically; recording the same runs twice gives the
same bytes.

Reading: :func:`vslbook.experiments.recorded_runs.materialise` writes a set back as run
directories (what the figures read, :mod:`vslbook.experiments.figure_sources`),
:func:`load_recorded` gives a figure's per-run metric frames, :func:`recorded_names`
the names in a set (``vslbook plan`` marks them ``recorded``), and :func:`result_rows`
(``vslbook results``) the final IQM of every recorded (figure, method, budget) with a 95 %
stratified-bootstrap CI over seeds and whether the code that made the runs has changed.
"""

from __future__ import annotations

import importlib
import json
import math
import os
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import pandas as pd

from vslbook.budget import Budget, get_budget
from vslbook.data import (
    csv_bytes,
    evals_frame,
    gzip_bytes,
    register_file,
    results_dir,
    verify_file,
)
from vslbook.experiments.recorded_runs import record_checkpoints
from vslbook.experiments.run_plan import FIGURE_MODULES, FigureRun, figure_runs, saved_rows
from vslbook.jsonfiles import atomic_write, json_bytes
from vslbook.results import RunDir, RunDirError

__all__ = [
    "PROVENANCE", "RUNS_COLUMNS", "RecordReport", "entry_stale", "figure_metric",
    "load_recorded", "read_set", "record", "record_text", "recorded_dir", "recorded_names",
    "result_rows", "results_text", "write_provenance",
]  # fmt: skip

#: columns of a recorded set's ``runs.csv``
RUNS_COLUMNS = ["run", "figure", "method", "algo", "env", "seed", "budget", "config_hash",
                "status"]  # fmt: skip
PROVENANCE = "provenance.json"
_DESCRIPTIONS = {
    "runs.csv": "one row per recorded run: run, figure, method, algo, env, seed, budget, "
    "config_hash, status; written by vslbook record",
    "evals.csv.gz": "long-format evaluations: run, step, metric, value; every numeric row of "
    "each run's metrics.jsonl; written by vslbook record",
    PROVENANCE: "per run: config, seed, budget, code fingerprint, git sha and dirty flag, "
    "package versions, host, python, platform, start and wall time, date recorded; "
    "written by vslbook record",
}


# --------------------------------------------------------------------------- locations


def _check_figure(figure: str) -> str:
    if figure not in FIGURE_MODULES:
        raise ValueError(
            f"figure {figure!r} declares no runs; expected one of {', '.join(FIGURE_MODULES)}"
        )
    return figure


def recorded_dir(figure: str, budget: Budget | str | None = None) -> Path:
    """``data/results/<figure>/<budget>/`` (under :func:`vslbook.data.results_dir`)."""
    return results_dir() / _check_figure(figure) / get_budget(budget).name


def figure_metric(figure: str, algo: str | None = None) -> str:
    """The metric ``figure`` plots, from its chapter module's ``METRIC`` (keyed ``4.3c`` for
    ``fig4-3c`` in Chapter 4, by figure id in Chapter 3); where that names one metric per
    algorithm (Fig. 3.5: SVSL's ``test_return``, PPO's ``eval_return``), the one of ``algo``.
    """
    module = importlib.import_module(FIGURE_MODULES[_check_figure(figure)])
    key = figure.removeprefix("fig").replace("-", ".")
    metric = module.METRIC[key] if key in module.METRIC else module.METRIC[figure]
    if isinstance(metric, str):
        return metric
    if algo not in metric:
        raise ValueError(f"figure {figure} plots one metric per algorithm ({metric}); got "
                         f"algo={algo!r}")  # fmt: skip
    return metric[algo]


def task_of_env(env: str) -> str:
    """The task name of a Chapter 3 or 4 env id (the id itself for any other)."""
    from vslbook.experiments import ch3_algorithms, ch4_algorithms

    for table in (ch3_algorithms.SVSL_ENVS, ch3_algorithms.PPO_ENVS,
                  ch4_algorithms.DISKILL_ENVS, ch4_algorithms.PPO_ENVS):  # fmt: skip
        if env in table:
            return table[env]
    return env


# --------------------------------------------------------------------------- reading a set


def _read_csv(directory: Path, name: str, dtype: dict[str, Any]) -> pd.DataFrame:
    """A registered table of ``directory``, verified, floats read back exactly."""
    path = directory / name
    verify_file(path)
    return pd.read_csv(path, dtype=dtype, float_precision="round_trip", keep_default_na=False,
                       na_values=[""])  # fmt: skip


def read_set(directory: Path) -> tuple[pd.DataFrame, pd.DataFrame, dict[str, Any]]:
    """(runs, evals, provenance) of a recorded set; empty ones where nothing is recorded."""
    if not (directory / "runs.csv").exists():
        empty_runs = pd.DataFrame(columns=RUNS_COLUMNS)
        empty_evals = pd.DataFrame(columns=["run", "step", "metric", "value"])
        return empty_runs, empty_evals, {}
    runs = _read_csv(directory, "runs.csv", {c: str for c in RUNS_COLUMNS if c != "seed"})
    runs["seed"] = runs["seed"].astype("int64")
    evals = _read_csv(directory, "evals.csv.gz",
                      {"run": str, "step": "int64", "metric": str, "value": "float64"})  # fmt: skip
    verify_file(directory / PROVENANCE)
    provenance = json.loads((directory / PROVENANCE).read_text(encoding="utf-8"))
    return runs, evals, provenance.get("runs", {})


def recorded_names(figure: str, budget: Budget | str | None = None) -> set[str]:
    """The names of the runs recorded for ``figure`` at ``budget`` (empty if none)."""
    directory = recorded_dir(figure, budget)
    if not (directory / "runs.csv").exists():
        return set()
    return set(read_set(directory)[0]["run"])


def load_recorded(figure: str, budget: Budget | str | None = None) -> dict[str, list[pd.DataFrame]]:
    """The recorded runs of ``figure`` at ``budget``: method → one frame per run (seed order),
    as :meth:`vslbook.results.RunDir.metrics_frame` gives it (a ``step`` column and one
    column per metric, NaN where a row lacks it); ``frame.attrs`` holds ``run`` and ``seed``.

    Methods come in the figure's order. Raises ``ValueError`` when nothing is recorded.
    """
    directory = recorded_dir(figure, budget)
    runs, evals, _ = read_set(directory)
    if runs.empty:
        raise ValueError(f"no runs of {figure} recorded in {directory}; record them with "
                         f"vslbook record {figure} --budget {get_budget(budget).name}")  # fmt: skip
    order = list(dict.fromkeys(r.method for r in figure_runs(figure, budget)))
    methods = order + sorted(set(runs["method"]) - set(order))
    out: dict[str, list[pd.DataFrame]] = {}
    for method in methods:
        for row in runs[runs["method"] == method].sort_values(["seed", "run"]).itertuples():
            long = evals[evals["run"] == row.run]
            wide = long.pivot(index="step", columns="metric", values="value")
            frame = wide.reset_index().rename_axis(columns=None)
            frame.attrs.update(run=row.run, seed=int(row.seed))
            out.setdefault(method, []).append(frame)
    return out


# --------------------------------------------------------------------------- recording


@dataclass
class RecordReport:
    """What :func:`record` did: the set's folder, the runs recorded from the root, the runs
    kept from an earlier recording, and the needed runs not recorded (name, state, detail)."""

    figure: str
    budget: str
    root: Path
    out_dir: Path
    needed: list[str]
    recorded: list[str] = field(default_factory=list)
    kept: list[str] = field(default_factory=list)
    skipped: list[tuple[str, str, str]] = field(default_factory=list)
    in_set: set[str] = field(default_factory=set)
    probes: dict[str, str] = field(default_factory=dict)  # name -> progress, e.g. 900/4500


def _state(rd: RunDir, run: FigureRun, partial: bool = False) -> tuple[str, str]:
    """(state, detail) of a run directory; state ``ok`` means it can be recorded
    (``probe``: a partial run with a checkpoint, recorded up to it where ``partial``).

    A run made by other code is replayed (:mod:`vslbook.replay`, under its lock): equal
    first rows keep it current (today's fingerprint joins its ``env.json``), other numbers
    make it ``stale``.
    """
    if not (rd.path / RunDir.CONFIG).is_file():
        return "missing", ""
    if rd.failed:
        return "failed", str((rd.failure or {}).get("message", ""))
    if not rd.done:
        rows = saved_rows(rd.path)
        detail = run.progress(int(rows[-1].get(run.unit, 0) or 0) if rows else 0)
        if not partial or not rows:
            return "partial", detail
        if not rd.code_matches:
            why = _replay(rd)
            if why is not None:
                return "stale", f"made by other code; replay: {why}"
        return "probe", detail
    try:
        rd.check_done()
    except RunDirError:
        return "damaged", "its DONE does not match metrics.jsonl"
    if not rd.code_matches:
        why = _replay(rd)
        if why is not None:
            return "stale", f"made by other code; replay: {why}"
    return "ok", ""


class _SavedRows:
    """A partial run's rows up to its checkpoint (those a resume keeps,
    :func:`~vslbook.experiments.run_plan.saved_rows`), as :func:`vslbook.data.evals_frame`
    reads a run: ``name`` and ``metrics()``."""

    def __init__(self, rd: RunDir) -> None:
        self.rd, self.name = rd, rd.name

    def metrics(self) -> list[dict[str, Any]]:
        return saved_rows(self.rd.path)


def _replay(rd: RunDir) -> str | None:
    """None when today's code replays ``rd``'s first rows (and that is now recorded in
    its ``env.json``), else why not."""
    from vslbook.registry import get_algorithm, load_plugins
    from vslbook.replay import replay_matches
    from vslbook.run_lock import RunLock, RunLockedError

    load_plugins()
    config = rd.config
    try:
        lock = RunLock(rd.path).acquire()
    except RunLockedError as err:
        return f"not checked: {err}"
    try:
        why = replay_matches(get_algorithm(config["algo"]), config, rd.metrics(),
                             get_budget(config["budget"]))  # fmt: skip
        if why is None:
            rd.add_verified_code()
        return why
    finally:
        lock.release()


def _wall_time(rd: RunDir, rows: list[dict[str, Any]], env: dict[str, Any]) -> tuple[float, str]:
    """Seconds the run trained and how that was measured."""
    times = [r["iteration_seconds"] for r in rows if r.get("iteration_seconds") is not None]
    if times:
        return float(sum(times)), "sum of iteration_seconds"
    try:
        started = datetime.fromisoformat(env["timestamp"]).timestamp()
    except (KeyError, TypeError, ValueError):
        return math.nan, "unknown"
    end = rd.path / RunDir.DONE
    if not end.is_file():
        end = rd.checkpoint_path
    return (max(0.0, round(end.stat().st_mtime - started, 3)),
            f"{end.name} mtime minus env.json timestamp")  # fmt: skip


def _provenance(rd: RunDir, run: Any, earlier: dict[str, Any] | None) -> dict[str, Any]:
    env, config = rd.env, rd.config
    rows = rd.metrics()
    wall, wall_from = _wall_time(rd, rows, env)
    done_path = rd.path / RunDir.DONE
    done = json.loads(done_path.read_text(encoding="utf-8")) if done_path.is_file() else {}
    entry = {
        "method": run.method, "algo": run.algo, "env": run.env,
        "seed": config.get("seed"), "budget": config.get("budget"), "config": config,
        "config_hash": rd.config_hash, "code_hash": env.get("code_hash"),
        "code_hashes_verified": list(env.get("code_hashes_verified", ())),
        "code_excluded": env.get("code_excluded", []), "git_sha": env.get("git_sha"),
        "git_dirty": env.get("git_dirty"), "packages": env.get("packages"),
        "hostname": env.get("hostname"), "python": env.get("python"),
        "platform": env.get("platform"), "started": env.get("timestamp"),
        "wall_seconds": None if math.isnan(wall) else wall, "wall_from": wall_from,
        "metrics": done.get("metrics"),
    }  # fmt: skip
    if env.get("cpu") is not None:  # runs made before env.json named the CPU have no entry
        entry["cpu"] = env["cpu"]
    same = earlier is not None and all(earlier.get(k) == entry[k] for k in entry)
    now = datetime.now(UTC).isoformat(timespec="seconds")
    entry["recorded"] = earlier["recorded"] if same else now
    return entry


def record(figure: str, budget: Budget | str | None = None, root: str | os.PathLike[str] = "runs",
           *, partial: bool = False) -> RecordReport:  # fmt: skip
    """Record the finished runs of ``figure`` at ``budget`` from ``root`` into
    :func:`recorded_dir` (see the module's docstring for the files).

    A run is recorded when it is ``DONE``, passes ``check_done()`` and was made by the
    running code; with ``partial``, a run still training is recorded too (a *probe*, status
    ``incomplete``), up to its last checkpoint. Runs recorded earlier and not recordable
    from ``root`` now are kept. A run unchanged since its earlier recording keeps its
    date, so recording twice writes the same bytes. Nothing is written when no run is
    recordable and none was recorded.

    Raises:
        ValueError: an unknown figure or budget, or ``root`` is not a folder.
        vslbook.data.DataIntegrityError: the set's earlier tables fail their registry.
    """
    runs = figure_runs(figure, budget)
    b = get_budget(budget)
    root = Path(root)
    if not root.is_dir():
        raise ValueError(f"root {str(root)!r} is not a folder; expected the folder that holds "
                         "the run directories (vslbook run --root)")  # fmt: skip
    out = recorded_dir(figure, b)
    old_runs, old_evals, old_prov = read_set(out)
    report = RecordReport(figure, b.name, root, out, [r.name for r in runs])
    fresh: dict[str, tuple[RunDir, Any]] = {}
    for run in runs:
        rd = RunDir(root / run.name)
        state, detail = _state(rd, run, partial)
        if state in ("ok", "probe"):
            fresh[run.name] = (rd, run)
            report.recorded.append(run.name)
            if state == "probe":
                report.probes[run.name] = detail
        else:
            report.skipped.append((run.name, state, detail))
    kept = sorted(set(old_runs["run"]) - set(fresh))
    report.kept = kept
    report.in_set = set(fresh) | set(kept)
    if not report.in_set:
        return report
    run_rows = {name: row for name, row in zip(old_runs["run"], old_runs.to_dict("records"),
                                               strict=True) if name in kept}  # fmt: skip
    provenance = {name: old_prov[name] for name in kept if name in old_prov}
    for name, (rd, run) in fresh.items():
        config = rd.config
        run_rows[name] = {"run": name, "figure": figure, "method": run.method, "algo": run.algo,
                          "env": run.env, "seed": int(config.get("seed", run.seed)),
                          "budget": str(config.get("budget", b.name)),
                          "config_hash": rd.config_hash, "status": rd.status}  # fmt: skip
        provenance[name] = _provenance(rd, run, old_prov.get(name))
    names = sorted(run_rows)
    runs_frame = pd.DataFrame([run_rows[n] for n in names], columns=RUNS_COLUMNS)
    runs_frame["seed"] = runs_frame["seed"].astype("int64")
    def rows_of(rd: RunDir) -> Any:  # a probe's rows up to its checkpoint
        return rd if rd.done else _SavedRows(rd)

    parts = [evals_frame([rows_of(fresh[n][0])]) if n in fresh
             else old_evals[old_evals["run"] == n] for n in names]  # fmt: skip
    evals = pd.concat(parts, ignore_index=True).astype(
        {"run": str, "step": "int64", "metric": str, "value": "float64"})  # fmt: skip
    out.mkdir(parents=True, exist_ok=True)
    body = {"figure": figure, "budget": b.name, "runs": {n: provenance[n] for n in names}}
    files = {"runs.csv": csv_bytes(runs_frame), "evals.csv.gz": gzip_bytes(csv_bytes(evals))}
    for name, data in files.items():
        atomic_write(out / name, data)
        register_file(out / name, _DESCRIPTIONS[name])
    write_provenance(out, body)
    record_checkpoints(out, fresh, runs_frame)
    return report


def write_provenance(directory: Path, body: dict[str, Any]) -> None:
    """Write a set's ``provenance.json`` and register its sha256."""
    atomic_write(directory / PROVENANCE, json_bytes(body))
    register_file(directory / PROVENANCE, _DESCRIPTIONS[PROVENANCE])


def record_text(report: RecordReport) -> str:
    """One line per run of the figure (recorded, or not recorded with its state), then a
    summary: how many of the runs the figure needs are recorded, and where."""
    lines = []
    skipped = {name: (state, detail) for name, state, detail in report.skipped}
    for name in report.needed:
        if name not in skipped:
            probe = f"  (probe: {report.probes[name]})" if name in report.probes else ""
            lines.append(f"recorded      {name}{probe}")
            continue
        state, detail = skipped[name]
        notes = [detail] if detail else []
        if name in report.kept:
            notes.append("recorded earlier: kept")
        extra = f"  ({'; '.join(notes)})" if notes else ""
        lines.append(f"not recorded  {state:8s} {name}{extra}")
    have = len(set(report.needed) & report.in_set)
    where = (f"in {report.out_dir} ({len(report.recorded)} from {report.root}, "
             f"{len(report.kept)} kept)" if report.in_set else "(nothing written)")  # fmt: skip
    lines.append(f"{have} of {len(report.needed)} runs of {report.figure} at {report.budget} "
                 f"recorded {where}")  # fmt: skip
    return "\n".join(lines)


# the results table: vslbook.experiments.record_results (re-exported here)
from vslbook.experiments.record_results import (  # noqa: E402
    entry_stale,
    result_rows,
    results_text,
)
