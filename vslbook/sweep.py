"""Run a grid of (algorithm, env, config, seed) through submitit.

The same call runs on a laptop and on a SLURM cluster; only the executor changes::

    from vslbook.sweep import sweep
    runs = sweep("erl-pg", envs=["vslbook/PointReach-v0"], seeds=range(3),
                 grid={"learning_rate": [0.02, 0.05]}, budget="reduced",
                 executor="local", root="runs")

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

Each job calls :func:`vslbook.training.run`, so a re-submitted sweep resumes every
interrupted run from its checkpoint and skips the finished ones.
"""

from __future__ import annotations

import itertools
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any

import submitit
import yaml

from vslbook.budget import get_budget
from vslbook.registry import (
    check_run_request,
    check_seed,
    config_from_overrides,
    get_algorithm,
)
from vslbook.training import run

EXECUTORS = ("debug", "local", "slurm")


def expand_grid(grid: Mapping[str, Sequence[Any]] | None) -> list[dict[str, Any]]:
    """All combinations of a {field: [values]} grid, as a list of override dicts."""
    if not grid:
        return [{}]
    for key, values in grid.items():
        if isinstance(values, (str, bytes)) or not isinstance(values, Iterable):
            raise ValueError(f"grid[{key!r}] must be a list of values, got {values!r}")
    keys = list(grid)
    return [dict(zip(keys, combo, strict=True)) for combo in itertools.product(*grid.values())]


def load_slurm_config(slurm: Mapping[str, Any] | str | Path | None) -> dict[str, Any]:
    """SLURM parameters from a dict or a YAML file (see the module docstring)."""
    if slurm is None:
        return {}
    if isinstance(slurm, (str, Path)):
        path = Path(slurm)
        if not path.is_file():
            raise ValueError(f"SLURM config file {str(path)!r} does not exist")
        loaded = yaml.safe_load(path.read_text()) or {}
        if not isinstance(loaded, dict):
            raise ValueError(
                f"SLURM config {str(path)!r} must hold a mapping, got {type(loaded).__name__}"
            )
        return loaded
    return dict(slurm)


def _job(algo: str, env: str, seed: int, budget: str, root: str, overrides: dict) -> str:
    return str(run(algo, env, seed, budget, root=root, overrides=overrides, progress=False).path)


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

    ``seeds`` defaults to ``range(budget.seeds)``. With ``wait=False`` the submitit jobs
    are returned instead (useful on a cluster).
    """
    if executor not in EXECUTORS:
        raise ValueError(f"unknown executor {executor!r}; expected one of {', '.join(EXECUTORS)}")
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
    jobs_args = [
        (algo, env, int(s), bud.name, str(Path(root).resolve()), point)
        for env in envs
        for point in points
        for s in seed_list
    ]

    folder = Path(log_dir) if log_dir else Path(root) / "_submitit"
    if executor == "slurm":
        ex = submitit.AutoExecutor(folder=folder, cluster="slurm")
        ex.update_parameters(**load_slurm_config(slurm))
    else:
        ex = submitit.AutoExecutor(folder=folder, cluster=executor)
        ex.update_parameters(timeout_min=24 * 60)
    if executor == "debug":
        jobs = [ex.submit(_job, *args) for args in jobs_args]
    else:
        with ex.batch():
            jobs = [ex.submit(_job, *args) for args in jobs_args]
    if not wait:
        return jobs
    return [Path(job.result()) for job in jobs]
