"""SLURM jobs of a sweep: the request checked before submitting, the jobs recorded and
waited for.

:mod:`vslbook.sweep` builds the grid and submits the job array; this module holds what
it needs from the cluster around that submission:

* **The request, before submitting.** A SLURM config (a dict or a YAML file, see
  :mod:`vslbook.sweep`) may hold submitit's shared parameters (``timeout_min``,
  ``mem_gb``, ``cpus_per_task``, ``gpus_per_node``, ``nodes``, ``tasks_per_node``,
  ``name``, ``stderr_to_stdout``) and ``slurm_`` + any parameter of submitit's
  ``SlurmExecutor``; :func:`check_slurm_config` rejects other keys and values of the wrong
  type. :func:`require_slurm_commands` asks for SLURM's commands on PATH, and
  :func:`check_cluster` checks the request against the cluster: the partition must exist
  (``sinfo``), ``cpus_per_task``, ``mem_gb`` and ``gpus_per_node`` must fit one of its
  nodes, and ``sbatch --test-only`` must accept the job. Each problem is a one-line
  ValueError; nothing is queued.
* **The record of submitted jobs.** :func:`record_jobs` writes the job of each run to
  ``<log folder>/jobs.json``; :func:`live_jobs` gives back the recorded jobs still queued
  or running, so that a sweep started again waits for them instead of submitting the runs
  a second time.
* **Waiting.** :func:`wait_for_jobs` polls each job's state with ``squeue`` (``sacct``
  where the cluster keeps accounting) and prints every change on stderr. A job that ends
  without a result (cancelled, failed, timed out, or gone from the queue: a cluster
  without accounting forgets finished jobs) gives a line naming its log; a job pending for
  a reason that cannot change (:data:`HOPELESS_REASONS`) is cancelled and gives a line.
  Ctrl-C stops waiting, not the jobs: it prints how to cancel them (``scancel``).

:func:`error_line` and :func:`last_line` cut a traceback or a command's output to the one
line an error message shows (:mod:`vslbook.sweep` uses them for its local jobs and for
``sbatch``).
"""

from __future__ import annotations

import difflib
import json
import re
import shutil
import subprocess
import sys
import tempfile
import time
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import submitit
import yaml
from submitit.core import utils as submitit_utils

__all__ = [
    "HOPELESS_REASONS",
    "JOBS_FILE",
    "POLL_MAX_S",
    "RESULT_GRACE_S",
    "SHARED_PARAMETERS",
    "TERMINAL_STATES",
    "check_cluster",
    "check_slurm_config",
    "error_line",
    "last_line",
    "live_jobs",
    "load_slurm_config",
    "record_jobs",
    "require_slurm_commands",
    "slurm_parameter_names",
    "wait_for_jobs",
]
#: submitit's shared parameters and the types it accepts for them.
SHARED_PARAMETERS: dict[str, type | tuple[type, ...]] = {
    "name": str,
    "timeout_min": int,
    "mem_gb": (int, float),
    "nodes": int,
    "cpus_per_task": int,
    "gpus_per_node": int,
    "tasks_per_node": int,
    "stderr_to_stdout": bool,
}
#: seconds between two looks at the queue, at most (the first minutes look more often)
POLL_MAX_S = 30.0
#: seconds a job that left the queue may take to show its result file (slow file systems)
RESULT_GRACE_S = 10.0
#: SLURM job states after which a job does not run again
TERMINAL_STATES = frozenset({
    "BOOT_FAIL", "CANCELLED", "COMPLETED", "DEADLINE", "FAILED", "NODE_FAIL",
    "OUT_OF_MEMORY", "PREEMPTED", "REVOKED", "TIMEOUT",
})  # fmt: skip
#: reasons of a pending job that no wait resolves, with what they mean
HOPELESS_REASONS = {
    "PartitionConfig": "the request exceeds what the partition's nodes have "
    "(cpus_per_task, mem_gb, gpus_per_node)",
    "PartitionNodeLimit": "the number of nodes is outside the partition's limits",
    "PartitionTimeLimit": "timeout_min exceeds the partition's time limit",
    "BadConstraints": "its constraints cannot be satisfied",
    "InvalidAccount": "the account is invalid",
    "InvalidQOS": "the QOS is invalid",
    "AccountNotAllowed": "the account may not use the partition",
    "QOSNotAllowed": "the QOS may not use the partition",
    "DependencyNeverSatisfied": "its dependency can never be satisfied",
}
JOBS_FILE = "jobs.json"


# --------------------------------------------------------------------------- the request


def load_slurm_config(slurm: Mapping[str, Any] | str | Path | None) -> dict[str, Any]:
    """SLURM parameters from a dict or a YAML file (see the module docstring)."""
    if slurm is None:
        return {}
    if isinstance(slurm, (str, Path)):
        path = Path(slurm)
        if not path.is_file():
            raise ValueError(f"SLURM config file {str(path)!r} does not exist")
        try:
            loaded = yaml.safe_load(path.read_text()) or {}
        except yaml.YAMLError as err:
            where = getattr(err, "problem_mark", None)
            line = f" line {where.line + 1}" if where is not None else ""
            raise ValueError(f"SLURM config {str(path)!r} is not valid YAML{line}") from None
        if not isinstance(loaded, dict):
            raise ValueError(
                f"SLURM config {str(path)!r} must hold a mapping, got {type(loaded).__name__}"
            )
        return loaded
    return dict(slurm)


def slurm_parameter_names() -> list[str]:
    """The keys a SLURM config may hold: submitit's shared parameters and ``slurm_`` + a
    parameter of submitit's ``SlurmExecutor``."""
    specific = submitit.SlurmExecutor._valid_parameters() | set(SHARED_PARAMETERS)
    return [*SHARED_PARAMETERS, *sorted(f"slurm_{name}" for name in specific)]


def check_slurm_config(params: Mapping[str, Any], source: str = "SLURM config") -> None:
    """Raise a one-line ValueError for a key submitit does not know or a value of the
    wrong type (before anything is submitted)."""
    valid = slurm_parameter_names()
    for key, value in params.items():
        if key not in valid:
            close = difflib.get_close_matches(str(key), valid, n=1)
            hint = f" (did you mean {close[0]!r}?)" if close else ""
            raise ValueError(
                f"unknown key {key!r} in {source}{hint}; expected one of {', '.join(valid)}"
            )
        expected = SHARED_PARAMETERS.get(key.removeprefix("slurm_"))
        bad_bool = isinstance(value, bool) and expected is not bool
        if expected is not None and (bad_bool or not isinstance(value, expected)):
            names = expected if isinstance(expected, tuple) else (expected,)
            raise ValueError(
                f"{key} in {source} must be {' or '.join(t.__name__ for t in names)}, got {value!r}"
            )


def require_slurm_commands() -> None:
    """A one-line ValueError when SLURM's commands are not on PATH."""
    missing = [cmd for cmd in ("sbatch", "squeue", "sinfo", "srun") if shutil.which(cmd) is None]
    if missing:
        raise ValueError(
            f"executor 'slurm' needs SLURM's commands on PATH; {', '.join(missing)} not found "
            "(run the sweep on a SLURM login node, or use --executor local)"
        )


def _partitions() -> list[dict[str, Any]] | None:
    """One entry per (partition, node): name, default, CPUs, memory (MB), GPUs; None when
    ``sinfo`` cannot tell."""
    out = _slurm_command(["sinfo", "-h", "-N", "-o", "%P|%c|%m|%G"])
    if out.returncode != 0:
        return None
    rows = []
    for line in out.stdout.splitlines():
        fields = line.strip().split("|")
        if len(fields) != 4:
            continue
        part, cpus, mem, gres = fields
        gpus = sum(int(n) for n in re.findall(r"gpu(?::[^:(,]+)?:(\d+)", gres))
        rows.append({
            "partition": part.rstrip("*"), "default": part.endswith("*"),
            "cpus": _int(cpus), "mem_mb": _int(mem), "gpus": gpus,
        })  # fmt: skip
    return rows


def _int(text: str) -> int | None:
    match = re.match(r"\d+", text.strip())
    return int(match.group()) if match else None


def _mem_mb(mem: str) -> float | None:
    """SLURM's ``--mem`` value (``32GB``, ``1024MB``, ``500``) in MB."""
    match = re.fullmatch(r"(\d+(?:\.\d+)?)\s*([KMGT]?)B?", str(mem).strip(), re.IGNORECASE)
    if not match:
        return None
    scale = {"K": 1 / 1024, "": 1, "M": 1, "G": 1024, "T": 1024**2}[match.group(2).upper()]
    return float(match.group(1)) * scale


def check_cluster(params: dict[str, Any], n_jobs: int, folder: Path) -> None:
    """A one-line ValueError for a request the cluster cannot run: unknown partition,
    more CPUs / memory / GPUs than any node has, or what ``sbatch --test-only`` rejects."""
    rows = _partitions()
    if rows:
        names = list(dict.fromkeys(r["partition"] for r in rows))
        part = params.get("partition")
        if part is not None and str(part) not in names:
            raise ValueError(
                f"unknown SLURM partition {part!r} (slurm_partition); the cluster has: "
                f"{', '.join(names)}"
            )
        if part is None:
            default = [r["partition"] for r in rows if r["default"]]
            part = default[0] if default else None
        nodes = [r for r in rows if r["partition"] == part]
        where = f"any node of partition {part!r}"
        tasks = max(1, int(params.get("ntasks_per_node") or 1))
        cpus = int(params.get("cpus_per_task") or 1) * tasks
        most = max((r["cpus"] or 0 for r in nodes), default=0)
        if nodes and most and cpus > most:
            raise ValueError(
                f"cpus_per_task={params.get('cpus_per_task')} asks for {cpus} CPUs per node, "
                f"more than {where} has ({most}); lower cpus_per_task in the SLURM config"
            )
        mem = _mem_mb(params["mem"]) if params.get("mem") else None
        most = max((r["mem_mb"] or 0 for r in nodes), default=0)
        if nodes and mem and most and mem > most:
            raise ValueError(
                f"mem_gb={mem / 1024:g} is more memory than {where} has "
                f"({most / 1024:.1f} GB); lower mem_gb in the SLURM config"
            )
        gpus = int(params.get("gpus_per_node") or 0)
        most = max((r["gpus"] for r in nodes), default=0)
        if nodes and gpus > most:
            raise ValueError(
                f"gpus_per_node={gpus} is more GPUs than {where} has ({most}); "
                "lower gpus_per_node or choose a GPU partition (slurm_partition)"
            )
    # everything else (account, QOS, time limit, constraints): ask sbatch, queueing nothing
    from submitit.slurm.slurm import _make_sbatch_string

    folder.mkdir(parents=True, exist_ok=True)
    map_count = n_jobs if n_jobs > 1 else None
    text = _make_sbatch_string(command="true", folder=folder, map_count=map_count, **params)
    with tempfile.NamedTemporaryFile("w", suffix=".sh", dir=folder, delete=False) as f:
        f.write(text)
    try:
        out = _slurm_command(["sbatch", "--test-only", f.name])
    finally:
        Path(f.name).unlink(missing_ok=True)
    if out.returncode != 0:
        raise ValueError(f"SLURM rejects the request: {last_line(out.stderr or out.stdout)}")


# --------------------------------------------------------------------------- jobs.json


def _jobs_file(folder: Path) -> Path:
    return folder / JOBS_FILE


def _read_jobs(folder: Path) -> dict[str, str]:
    try:
        data = json.loads(_jobs_file(folder).read_text())
    except (OSError, ValueError):
        return {}
    return {str(k): str(v) for k, v in data.items()} if isinstance(data, dict) else {}


def record_jobs(folder: Path, jobs: dict[str, str]) -> None:
    """Add {run name: job id} to ``<folder>/jobs.json`` (replaced atomically)."""
    data = {**_read_jobs(folder), **jobs}
    tmp = _jobs_file(folder).with_suffix(".tmp")
    tmp.write_text(json.dumps(data, indent=1, sort_keys=True))
    tmp.replace(_jobs_file(folder))


def live_jobs(folder: Path, names: list[str]) -> dict[str, Any]:
    """The runs of ``names`` whose recorded job is still queued or running: {name: job}."""
    recorded = {name: jid for name, jid in _read_jobs(folder).items() if name in names}
    if not recorded:
        return {}
    states = _squeue(list(recorded.values())) or {}
    return {
        name: submitit.SlurmJob(folder=folder, job_id=jid, tasks=[0])
        for name, jid in recorded.items()
        if states.get(jid, ("", ""))[0] not in ("", *TERMINAL_STATES)
    }


# --------------------------------------------------------------------------- job states


def _squeue(job_ids: list[str]) -> dict[str, tuple[str, str]] | None:
    """{job id: (state, reason)} of the jobs SLURM still knows (finished ones for a few
    minutes, ``MinJobAge``); None when ``squeue`` fails."""
    base = sorted({jid.split("_")[0] for jid in job_ids})
    out = _slurm_command(
        ["squeue", "-h", "-r", "-t", "all", "-o", "%i|%T|%r", "-j", ",".join(base)]
    )
    if out.returncode != 0:
        return {} if "invalid job id" in out.stderr.lower() else None
    states = {}
    for line in out.stdout.splitlines():
        jid, _, rest = line.strip().partition("|")
        state, _, reason = rest.partition("|")
        states[jid] = (state.strip(), reason.strip())
    return states


def _sacct(job_ids: list[str]) -> dict[str, str]:
    """{job id: state} from the accounting database; empty when the cluster keeps none."""
    base = sorted({jid.split("_")[0] for jid in job_ids})
    out = _slurm_command(["sacct", "-n", "-P", "-X", "-o", "JobID,State", "-j", ",".join(base)])
    if out.returncode != 0 or shutil.which("sacct") is None:
        return {}
    states = {}
    for line in out.stdout.splitlines():
        jid, _, state = line.strip().partition("|")
        if state:
            states[jid] = state.split()[0]
    return states


# --------------------------------------------------------------------------- waiting


@dataclass
class _Watch:
    job: Any
    name: str
    label: str = ""
    ended: float | None = None


def _result(job: Any, name: str) -> Path | str:
    """The run directory a finished job returned, or a line saying how it failed."""
    try:
        outcome, value = submitit_utils.pickle_load(job.paths.result_pickle)
    except Exception as err:  # noqa: BLE001 - a torn or foreign pickle is a failure to report
        return f"job {job.job_id} (run {name}): unreadable result ({err})"
    if outcome == "success":
        return Path(value)
    return (
        f"job {job.job_id} (run {name}) failed: {error_line(str(value))}; log: {job.paths.stderr}"
    )


def wait_for_jobs(jobs: list[Any], names: list[str]) -> list[Path | str]:
    """Wait for every SLURM job (run ``names[i]`` is ``jobs[i]``); each gives its run
    directory, or, ending without a result, a line saying why."""
    watches = {job.job_id: _Watch(job, name) for job, name in zip(jobs, names, strict=True)}
    results: dict[str, Path | str] = {}
    start = time.monotonic()
    warned = ""
    try:
        while len(results) < len(watches):
            for jid, w in watches.items():
                if jid not in results and w.job.paths.result_pickle.exists():
                    results[jid] = _finish(w)
            waiting = [jid for jid in watches if jid not in results]
            if not waiting:
                break
            states = _squeue(waiting)
            if states is None:  # the controller did not answer: keep waiting, say so once
                if not warned:
                    warned = "squeue failed; still waiting for the jobs"
                    _say(warned)
                states = {}
            unknown = [jid for jid in waiting if jid not in states]
            if unknown:
                states.update({jid: (st, "") for jid, st in _sacct(unknown).items()})
            now = time.monotonic()
            for jid in waiting:
                w = watches[jid]
                state, reason = states.get(jid, ("", ""))
                show = state or "no longer in the queue"
                if state == "PENDING" and reason not in ("", "None"):
                    show = f"PENDING ({reason})"
                if show != w.label:
                    w.label = show
                    _say(f"job {jid} {show}: {w.name}")
                if state == "PENDING" and reason in HOPELESS_REASONS:
                    _slurm_command(["scancel", jid])
                    results[jid] = (
                        f"job {jid} (run {w.name}) cannot start: {reason}, "
                        f"{HOPELESS_REASONS[reason]}; cancelled it"
                    )
                    continue
                if state and state not in TERMINAL_STATES:
                    w.ended = None
                    continue
                w.ended = now if w.ended is None else w.ended
                if now - w.ended >= RESULT_GRACE_S:  # ended, and no result file came
                    if w.job.paths.result_pickle.exists():
                        results[jid] = _finish(w)
                        continue
                    what = f"ended {state}" if state else "left the queue (state unknown)"
                    results[jid] = (
                        f"job {jid} (run {w.name}) {what} without a result; "
                        f"log: {w.job.paths.stderr}"
                    )
            if len(results) < len(watches):
                time.sleep(min(POLL_MAX_S, max(1.0, (time.monotonic() - start) / 20)))
    except KeyboardInterrupt:
        left = [jid for jid in watches if jid not in results]
        arrays = " ".join(sorted({jid.split("_")[0] for jid in left}))
        _say(
            f"stopped waiting; {len(left)} jobs stay queued or running ({' '.join(left)}). "
            f"`scancel {arrays}` cancels them; the same sweep waits for them again"
        )
        raise
    return [results[job.job_id] for job in jobs]


def _finish(w: _Watch) -> Path | str:
    got = _result(w.job, w.name)
    _say(f"job {w.job.job_id} {'done' if isinstance(got, Path) else 'FAILED'}: {w.name}")
    return got


# --------------------------------------------------------------------------- helpers


def _say(message: str) -> None:
    """A progress line: on stderr, so that stdout stays the list of run directories."""
    print(message, file=sys.stderr, flush=True)


def _slurm_command(argv: list[str], timeout: float = 60) -> subprocess.CompletedProcess:
    try:
        return subprocess.run(argv, capture_output=True, text=True, timeout=timeout)
    except (OSError, subprocess.TimeoutExpired) as err:
        return subprocess.CompletedProcess(argv, 1, "", f"{argv[0]}: {err}")


def last_line(text: str) -> str:
    """The last non-blank line of a command's output or an error message."""
    lines = [ln.strip() for ln in str(text).strip().splitlines() if ln.strip()]
    return lines[-1] if lines else "no message"


def error_line(trace: str) -> str:
    """The exception line of a traceback (its last line that is not a rule or a hint)."""
    lines = [ln.strip() for ln in trace.strip().splitlines()]
    lines = [ln for ln in lines if ln and not set(ln) <= {"-"}]
    for ln in reversed(lines):
        if re.match(r"^[\w.]+(Error|Exception|Interrupt|Exit)\b", ln):
            return ln
    return lines[-1] if lines else "no error message"
