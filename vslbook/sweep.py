"""Run a grid of (algorithm, env, config, seed) through submitit.

The same call runs on a laptop and on a SLURM cluster; only the executor changes::

    from vslbook.sweep import sweep
    runs = sweep("erl-pg", envs=["vslbook/PointReach-v0"], seeds=range(3),
                 grid={"learning_rate": [0.02, 0.05]}, budget="reduced",
                 executor="local", root="runs")

This module holds the grid, :func:`sweep`, the executors and the submission of the jobs;
:mod:`vslbook.slurm_jobs` holds what SLURM adds around the submission: the request checked
against the cluster, the record of submitted jobs (``jobs.json``) and the wait for them.

Executors:

``debug``  in this process, one job after another (submitit's DebugExecutor).
``local``  one subprocess per job on this machine (submitit's LocalExecutor).
``slurm``  a job array on a SLURM cluster. Its settings are a dict or a YAML file of
           submitit parameters, for example::

               # slurm.yaml
               slurm_partition: gpu
               timeout_min: 720
               cpus_per_task: 8
               gpus_per_node: 1
               mem_gb: 32
               slurm_array_parallelism: 50
               slurm_additional_parameters: {account: my_project}

           The keys are submitit's shared parameters (``timeout_min``, ``mem_gb``,
           ``cpus_per_task``, ``gpus_per_node``, ``nodes``, ``tasks_per_node``, ``name``,
           ``stderr_to_stdout``) and ``slurm_`` + any parameter of submitit's
           ``SlurmExecutor`` (``slurm_partition``, ``slurm_account``, ``slurm_qos``, ...).

Each job calls :func:`vslbook.training.run`, so a re-submitted sweep resumes every
interrupted run from its checkpoint and skips the finished ones; a run already DONE is
not submitted at all. A second process on a run that is training stops with an error
naming the holder (the run directory's lock), so a run is never trained twice at once.

On SLURM (``vslbook sweep ... --executor slurm --slurm slurm.yaml``; the checks and the
waiting are in :mod:`vslbook.slurm_jobs`):

* **Before submitting**, the YAML keys are checked against submitit's parameters, and the
  request against the cluster: the partition must exist (``sinfo``), ``cpus_per_task``,
  ``mem_gb`` and ``gpus_per_node`` must fit one of its nodes, and ``sbatch --test-only``
  must accept the job. Each problem, like a failing ``sbatch``, is one line
  (``vslbook: error: ...``, exit status 2); nothing is queued.
* **On submitting**, the job ids and the log folder (``<root>/_submitit``, submitit's
  stdout / stderr of every job) are printed at once, on stderr. The job of each run is
  recorded in ``<log folder>/jobs.json``: a sweep started again while that job is still
  queued or running waits for it instead of submitting the run a second time.
* **While waiting**, each job's state is polled with ``squeue`` (``sacct`` where the
  cluster keeps accounting) and every change is printed. A job that ends without a
  result (cancelled, failed, timed out, or gone from the queue: a cluster without
  accounting forgets finished jobs) is reported with its log; a job pending for a reason
  that cannot change (``PartitionConfig``, ``PartitionTimeLimit``, an invalid account or
  QOS, ...) is cancelled and reported. The other jobs are waited for; the sweep then
  ends with :class:`SweepError` (``vslbook sweep`` prints the finished runs, then one
  ``vslbook: error:`` line per job, and exits 1). Running the same sweep again resumes
  the unfinished runs.
* **Ctrl-C** stops waiting, not the jobs: it prints how to cancel them (``scancel``).
* ``wait=False`` (``vslbook sweep --no-wait``) submits and returns the submitit jobs
  (the command prints their ids, one a line); a later ``vslbook sweep`` with the same
  arguments waits for them and lists the run directories.
"""

from __future__ import annotations

import contextlib
import io
import itertools
import os
import sys
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any

import submitit
from submitit.core import utils as submitit_utils

from vslbook.budget import get_budget
from vslbook.registry import (
    check_run_request,
    check_seed,
    config_from_overrides,
    get_algorithm,
)
from vslbook.results import RunDir
from vslbook.slurm_jobs import (
    check_cluster,
    check_slurm_config,
    error_line,
    last_line,
    live_jobs,
    load_slurm_config,
    record_jobs,
    require_slurm_commands,
    wait_for_jobs,
)
from vslbook.training import REUSE_STALE_ENV, run, run_name

EXECUTORS = ("debug", "local", "slurm")


class SweepError(RuntimeError):
    """Jobs of a sweep ended without a result. ``paths`` holds the runs that finished and
    ``problems`` one line per job that did not."""

    def __init__(self, problems: list[str], paths: list[Path]) -> None:
        super().__init__("\n".join(problems))
        self.problems = problems
        self.paths = paths


def _say(message: str) -> None:
    """A progress line: on stderr, so that stdout stays the list of run directories."""
    print(message, file=sys.stderr, flush=True)


def expand_grid(grid: Mapping[str, Sequence[Any]] | None) -> list[dict[str, Any]]:
    """All combinations of a {field: [values]} grid, as a list of override dicts."""
    if not grid:
        return [{}]
    for key, values in grid.items():
        if isinstance(values, (str, bytes)) or not isinstance(values, Iterable):
            raise ValueError(f"grid[{key!r}] must be a list of values, got {values!r}")
    keys = list(grid)
    return [dict(zip(keys, combo, strict=True)) for combo in itertools.product(*grid.values())]


def _job(algo: str, env: str, seed: int, budget: str, root: str, overrides: dict) -> str:
    # wait=True: a run another sweep (or a hand-started run) trains is waited for, then
    # reused as finished, instead of failing this job or training it twice
    rd = run(algo, env, seed, budget, root=root, overrides=overrides, progress=False, wait=True)
    return str(rd.path)


def sweep(
    algo: str,
    envs: Sequence[str],
    seeds: Iterable[int] | None = None,
    *,
    grid: Mapping[str, Sequence[Any]] | None = None,
    budget: str | None = None,
    root: str | Path = "runs",
    executor: str = "local",
    slurm: Mapping[str, Any] | str | Path | None = None,
    log_dir: str | Path | None = None,
    wait: bool = True,
) -> list[Any]:
    """Train every (env, grid point, seed) and return the run directories' paths.

    ``seeds`` defaults to ``range(budget.seeds)``. Runs already DONE are not submitted.
    With ``wait=False`` the submitit jobs of the runs still to train are returned instead
    (useful on a cluster). Raises :class:`SweepError` when jobs end without a result,
    ValueError for a bad request (before anything is submitted).
    """
    if executor not in EXECUTORS:
        raise ValueError(f"unknown executor {executor!r}; expected one of {', '.join(EXECUTORS)}")
    if not wait and executor == "debug":
        raise ValueError(
            "wait=False (--no-wait) needs the local or slurm executor; "
            "the debug executor runs its jobs in this process"
        )
    spec = get_algorithm(algo)
    bud = get_budget(budget)
    points = expand_grid(grid)
    envs = [envs] if isinstance(envs, str) else list(envs)
    seed_list = list(range(bud.seeds) if seeds is None else seeds)
    for env in envs:  # env ids, configs and seeds: a bad one is an error here, not in a job
        check_run_request(spec, env, 0)
        for point in points:
            config_from_overrides(spec.config, point, spec.default_config(env, bud, point))
    seed_list = [check_seed(s) for s in seed_list]
    params: dict[str, Any] = {}
    if executor == "slurm":
        source = f"SLURM config {str(slurm)!r}" if isinstance(slurm, (str, Path)) else "slurm"
        params = load_slurm_config(slurm)
        check_slurm_config(params, source)
    root_path = Path(root).resolve()
    jobs_args = [
        (algo, env, int(s), bud.name, str(root_path), point)
        for env in envs
        for point in points
        for s in seed_list
    ]
    paths = [root_path / run_name(a, e, s, b, overrides=p) for a, e, s, b, _, p in jobs_args]
    todo = [i for i, path in enumerate(paths) if not _finished(path)]
    if len(todo) < len(paths):
        _say(f"{len(paths) - len(todo)} of {len(paths)} runs already DONE; not submitted again")
    if not todo:
        return paths if wait else []

    folder = (Path(log_dir) if log_dir else Path(root) / "_submitit").resolve()
    if executor == "slurm":
        jobs = _submit_slurm(folder, params, [jobs_args[i] for i in todo],
                             [paths[i] for i in todo])  # fmt: skip
    else:
        ex = submitit.AutoExecutor(folder=folder, cluster=executor)
        ex.update_parameters(timeout_min=24 * 60)
        if executor == "debug":
            jobs = [ex.submit(_job, *jobs_args[i]) for i in todo]
        else:
            with ex.batch():
                jobs = [ex.submit(_job, *jobs_args[i]) for i in todo]
            ids = " ".join(str(job.job_id) for job in jobs)
            _say(f"started {len(jobs)} local jobs (pids {ids}); logs in {folder}")
    if not wait:
        return jobs
    names = [paths[i].name for i in todo]
    if executor == "slurm":
        results = wait_for_jobs(jobs, names)
    else:
        results = _wait_plain(jobs, names)
    out = list(paths)
    problems = []
    for i, got in zip(todo, results, strict=True):
        if isinstance(got, Path):
            out[i] = got
        else:
            problems.append(got)
            out[i] = None
    if problems:
        raise SweepError(problems, [p for p in out if p is not None])
    return out


def _finished(path: Path) -> bool:
    """True when ``path`` is a DONE run :func:`run` would reuse: made by the running code,
    or any code with ``$VSLBOOK_REUSE_STALE`` set (cheap: a few stats and a hash)."""
    rd = RunDir(path)
    reuse = os.environ.get(REUSE_STALE_ENV, "").strip().lower() in ("1", "true", "yes")
    try:
        return rd.done and (reuse or rd.code_matches)
    except (OSError, ValueError):
        return False


# --------------------------------------------------------------------------- local / debug


def _wait_plain(jobs: list[Any], names: list[str]) -> list[Path | str]:
    out: list[Path | str] = []
    for job, name in zip(jobs, names, strict=True):
        try:
            out.append(Path(job.result()))
        except submitit_utils.UncompletedJobError as err:
            out.append(f"job {job.job_id} (run {name}) failed: {error_line(str(err))}")
    return out


# --------------------------------------------------------------------------- SLURM


def _submit_slurm(
    folder: Path, params: dict[str, Any], jobs_args: list[tuple], paths: list[Path]
) -> list[Any]:
    """Check the request against the cluster, then submit one job array (runs whose job
    is still queued or running are waited for instead)."""
    require_slurm_commands()
    ex = submitit.AutoExecutor(folder=folder, cluster="slurm")
    try:
        ex.update_parameters(**params)
    except (ValueError, NameError, AssertionError, TypeError) as err:
        raise ValueError(f"bad SLURM config: {last_line(str(err).splitlines()[0])}") from None
    sbatch_params = dict(ex._executor.parameters)

    attached = live_jobs(folder, [p.name for p in paths])
    new = [i for i, path in enumerate(paths) if path.name not in attached]
    jobs: list[Any] = [attached.get(path.name) for path in paths]
    if attached:
        ids = " ".join(job.job_id for job in attached.values())
        _say(
            f"{len(attached)} runs are already queued or running (jobs {ids}); "
            "waiting for them instead of submitting again"
        )
    if not new:
        return jobs
    check_cluster(sbatch_params, len(new), folder)
    err_buffer = io.StringIO()  # submitit prints sbatch's stderr; it is in the error below
    try:
        with contextlib.redirect_stderr(err_buffer), ex.batch():
            submitted = [ex.submit(_job, *jobs_args[i]) for i in new]
    except (submitit_utils.FailedJobError, submitit_utils.FailedSubmissionError, OSError) as err:
        raise ValueError(f"sbatch failed: {last_line(str(err))}") from None
    for i, job in zip(new, submitted, strict=True):
        jobs[i] = job
    record_jobs(folder, {paths[i].name: jobs[i].job_id for i in new})
    array = sorted({job.job_id.split("_")[0] for job in submitted})
    _say(
        f"submitted {len(submitted)} SLURM jobs (job {', '.join(array)}: "
        f"{' '.join(job.job_id for job in submitted)}); logs in {folder}"
    )
    return jobs
