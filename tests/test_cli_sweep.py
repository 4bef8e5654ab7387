import json
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

from vslbook.cli import main
from vslbook.slurm_jobs import load_slurm_config
from vslbook.sweep import expand_grid, sweep

ENV = "vslbook/PointReach-v0"


def test_console_script_lists_budgets():
    exe = shutil.which("vslbook") or str(
        __import__("pathlib").Path(sys.executable).with_name("vslbook")
    )
    out = subprocess.run([exe, "budgets"], capture_output=True, text=True, check=True).stdout
    assert "smoke" in out and "reduced" in out and "full" in out


def test_cli_run_and_resume(tmp_path, capsys):
    argv = [
        "run",
        "erl-pg",
        "--env",
        ENV,
        "--seed",
        "0",
        "--budget",
        "smoke",
        "--root",
        str(tmp_path),
        "--no-progress",
        "--set",
        "learning_rate=0.1",
    ]
    assert main(argv) == 0
    out = capsys.readouterr().out
    assert "eval_return" in out
    assert main(argv) == 0  # second call finds the DONE run


def test_cli_set_is_repeatable(tmp_path, capsys):
    """Every --set counts (argparse would otherwise keep only the last one)."""
    base = ["run", "erl-pg", "--env", ENV, "--budget", "smoke", "--root", str(tmp_path),
            "--no-progress"]  # fmt: skip
    assert main([*base, "--set", "learning_rate=0.1", "--set", "init_std=0.5"]) == 0
    (config,) = tmp_path.glob("*/config.json")
    got = json.loads(config.read_text())
    assert got["learning_rate"] == 0.1 and got["init_std"] == 0.5


def test_cli_bad_input_exits_2_with_message(tmp_path, capsys):
    assert main(["run", "nope", "--env", ENV, "--root", str(tmp_path)]) == 2
    assert "unknown algorithm 'nope'" in capsys.readouterr().err
    assert main(["run", "erl-pg", "--env", ENV, "--budget", "huge", "--root", str(tmp_path)]) == 2
    assert "unknown budget 'huge'" in capsys.readouterr().err
    assert main(["figure", "no-such-figure"]) == 2
    assert "unknown figure" in capsys.readouterr().err
    assert (
        main(["run", "erl-pg", "--env", ENV, "--set", "learning_rate=abc", "--root", str(tmp_path)])
        == 2
    )
    assert "cannot convert learning_rate='abc' to float" in capsys.readouterr().err


def test_cli_lists_registries(capsys):
    assert main(["algorithms"]) == 0
    assert "erl-pg" in capsys.readouterr().out
    assert main(["figures"]) == 0
    assert capsys.readouterr().out.strip()


def test_expand_grid():
    assert expand_grid(None) == [{}]
    assert expand_grid({"a": [1, 2], "b": ["x"]}) == [{"a": 1, "b": "x"}, {"a": 2, "b": "x"}]
    with pytest.raises(ValueError, match=r"grid\['a'\] must be a list"):
        expand_grid({"a": 3})


def test_slurm_config_from_yaml(tmp_path):
    cfg = {"slurm_partition": "gpu", "timeout_min": 60, "gpus_per_node": 1}
    path = tmp_path / "slurm.yaml"
    path.write_text(yaml.safe_dump(cfg))
    assert load_slurm_config(path) == cfg
    assert load_slurm_config(cfg) == cfg
    with pytest.raises(ValueError, match="does not exist"):
        load_slurm_config(tmp_path / "missing.yaml")


def test_sweep_debug_executor_runs_grid(tmp_path):
    paths = sweep(
        "erl-pg",
        [ENV],
        seeds=[0, 1],
        grid={"learning_rate": [0.05, 0.1]},
        budget="smoke",
        root=tmp_path,
        executor="debug",
    )
    assert len(paths) == 4 and len(set(paths)) == 4
    assert all((p / "DONE").exists() for p in paths)


@pytest.mark.slow
def test_sweep_local_executor_subprocesses(tmp_path):
    paths = sweep("erl-pg", [ENV], seeds=[0], budget="smoke", root=tmp_path, executor="local")
    assert len(paths) == 1 and (paths[0] / "DONE").exists()


def test_sweep_rejects_bad_input(tmp_path):
    with pytest.raises(ValueError, match="unknown executor 'k8s'"):
        sweep("erl-pg", [ENV], [0], executor="k8s", root=tmp_path)
    with pytest.raises(ValueError, match="has no field 'nope'"):
        sweep("erl-pg", [ENV], [0], grid={"nope": [1]}, root=tmp_path, executor="debug")


def test_set_parses_optional_and_boolean_fields():
    from vslbook.registry import config_from_overrides, config_from_record
    from vslbook.srl.dime import DIMEConfig

    cfg = config_from_overrides(
        DIMEConfig,
        {"fixed_alpha": "0.1", "v_min": "-10", "v_max": "10", "learn_beta": "false",
         "critic": "scalar", "n_diffusion_steps": "2"},
    )  # fmt: skip
    assert (cfg.fixed_alpha, cfg.v_min, cfg.v_max) == (0.1, -10.0, 10.0)
    assert (cfg.learn_beta, cfg.critic, cfg.n_diffusion_steps) == (False, "scalar", 2)
    assert config_from_overrides(DIMEConfig, {"fixed_alpha": "none"}).fixed_alpha is None
    message = re.escape("cannot convert fixed_alpha='abc' to float | None")
    with pytest.raises(ValueError, match=message):
        config_from_overrides(DIMEConfig, {"fixed_alpha": "abc"})
    with pytest.raises(ValueError, match="cannot convert learn_beta='maybe' to bool"):
        config_from_overrides(DIMEConfig, {"learn_beta": "maybe"})
    record = {"algo": "dime", "env": "Pendulum-v1", "seed": 0, "budget": "smoke", "utd": 3}
    assert config_from_record(DIMEConfig, record).utd == 3


# DIME through the command line: tiny networks, one Pendulum episode at the smoke budget.
DIME_TINY = [
    "total_steps=100000", "learning_starts=0", "critic_hidden=16", "actor_hidden=16",
    "n_diffusion_steps=2", "batch_size=16", "eval_episodes=1", "v_min=-1600", "v_max=100",
    "num_threads=1",
]  # fmt: skip


def test_dime_runs_and_sweeps_from_the_command_line(tmp_path, capsys):
    common = ["--env", "Pendulum-v1", "--budget", "smoke", "--root", str(tmp_path)]
    assert main(["run", "dime", "--seed", "0", *common, "--no-progress",
                 "--set", *DIME_TINY, "fixed_alpha=0.2"]) == 0  # fmt: skip
    out = capsys.readouterr().out
    assert '"env_steps": 200' in out
    config = json.loads((Path(out.splitlines()[0]) / "config.json").read_text())
    assert (config["algo"], config["fixed_alpha"], config["v_min"]) == ("dime", 0.2, -1600.0)

    grid = [*DIME_TINY, "n_diffusion_steps=1,2"]
    grid = [g for g in grid if not g.startswith("n_diffusion_steps=2")]
    assert main(["sweep", "dime", *common, "--seeds", "0", "--executor", "debug",
                 "--grid", *grid]) == 0  # fmt: skip
    paths = [Path(p) for p in capsys.readouterr().out.split()]
    assert len(paths) == 2 and all((p / "DONE").exists() for p in paths)
    steps = sorted(json.loads((p / "config.json").read_text())["n_diffusion_steps"] for p in paths)
    assert steps == [1, 2]


# ---------------------------------------------------------------- the SLURM path, no cluster
# (a real single-node SLURM runs in tests/test_slurm_sweep.py)


def test_slurm_config_keys_and_types_are_checked_before_submitting(tmp_path):
    from vslbook.slurm_jobs import check_slurm_config

    check_slurm_config({"slurm_partition": "gpu", "timeout_min": 60, "mem_gb": 0.5,
                        "slurm_additional_parameters": {"account": "x"}})  # fmt: skip
    with pytest.raises(ValueError, match=r"unknown key 'partition' in slurm \(did you mean "
                       r"'slurm_partition'\?\); expected one of name, timeout_min"):  # fmt: skip
        check_slurm_config({"partition": "gpu"}, "slurm")
    with pytest.raises(ValueError, match="timeout_min in slurm must be int, got '60'"):
        check_slurm_config({"timeout_min": "60"}, "slurm")
    with pytest.raises(ValueError, match="cpus_per_task in slurm must be int, got True"):
        check_slurm_config({"cpus_per_task": True}, "slurm")
    path = tmp_path / "slurm.yaml"
    path.write_text("slurm_partiton: gpu\n")
    with pytest.raises(ValueError, match=r"unknown key 'slurm_partiton' in SLURM config '.*"
                       r"slurm.yaml' \(did you mean 'slurm_partition'\?\)"):  # fmt: skip
        sweep("erl-pg", [ENV], [0], executor="slurm", slurm=path, root=tmp_path)
    assert not (tmp_path / "_submitit").exists()


def test_cli_slurm_errors_are_one_line(tmp_path, capsys, monkeypatch):
    path = tmp_path / "slurm.yaml"
    path.write_text("partition: gpu\n")
    argv = ["sweep", "erl-pg", "--env", ENV, "--seeds", "0", "--root", str(tmp_path),
            "--executor", "slurm", "--slurm", str(path)]  # fmt: skip
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.startswith("vslbook: error: unknown key 'partition'") and err.count("\n") == 1
    monkeypatch.setenv("PATH", str(tmp_path))  # no sbatch, squeue, sinfo, srun
    path.write_text("slurm_partition: gpu\n")
    assert main(argv) == 2
    assert "executor 'slurm' needs SLURM's commands on PATH" in capsys.readouterr().err
    assert main([*argv[:-4], "--executor", "debug", "--no-wait"]) == 2
    assert "--no-wait) needs the local or slurm executor" in capsys.readouterr().err


def test_sweep_skips_done_runs(tmp_path, capsys, monkeypatch):
    monkeypatch.setenv("VSLBOOK_REUSE_STALE", "1")  # DONE counts even if the code changes
    first = sweep("erl-pg", [ENV], [0, 1], budget="smoke", root=tmp_path, executor="debug")
    capsys.readouterr()
    mtimes = [(p / "DONE").stat().st_mtime_ns for p in first]
    again = sweep("erl-pg", [ENV], [0, 1], budget="smoke", root=tmp_path, executor="debug")
    assert again == first
    assert "2 of 2 runs already DONE; not submitted again" in capsys.readouterr().err
    assert [(p / "DONE").stat().st_mtime_ns for p in again] == mtimes
    assert sweep("erl-pg", [ENV], [0, 1], budget="smoke", root=tmp_path, executor="local",
                 wait=False) == []  # fmt: skip


class _FakeJob:
    def __init__(self, job_id, folder):
        import submitit

        self.job_id = job_id
        self.paths = submitit.core.utils.JobPaths(folder, job_id=job_id, task_id=0)


def test_waiting_ends_for_jobs_without_a_result(tmp_path, capsys, monkeypatch):
    """No accounting: a job gone from squeue, a cancelled one, a hopeless pending one and a
    failed one are each reported in a line; a finished one gives its run directory."""
    import submitit

    from vslbook import slurm_jobs

    jobs = [_FakeJob(f"7_{i}", tmp_path) for i in range(5)]
    tmp_path.mkdir(exist_ok=True)
    submitit.core.utils.cloudpickle_dump(("success", str(tmp_path / "run0")),
                                         jobs[0].paths.result_pickle)  # fmt: skip
    submitit.core.utils.cloudpickle_dump(("error", "Traceback ...\nValueError: boom"),
                                         jobs[4].paths.result_pickle)  # fmt: skip
    queue = {"7_2": ("CANCELLED", "None"), "7_3": ("PENDING", "PartitionConfig")}
    cancelled = []
    monkeypatch.setattr(slurm_jobs, "_squeue", lambda ids: {j: queue[j] for j in ids if j in queue})
    monkeypatch.setattr(slurm_jobs, "_sacct", lambda ids: {})
    monkeypatch.setattr(slurm_jobs, "_slurm_command", lambda argv, **kw: cancelled.append(argv))
    monkeypatch.setattr(slurm_jobs, "RESULT_GRACE_S", 0.0)
    monkeypatch.setattr(slurm_jobs.time, "sleep", lambda s: None)
    got = slurm_jobs.wait_for_jobs(jobs, [f"r{i}" for i in range(5)])
    assert got[0] == tmp_path / "run0"
    assert got[1].startswith("job 7_1 (run r1) left the queue (state unknown) without a result")
    assert got[2].startswith("job 7_2 (run r2) ended CANCELLED without a result; log: ")
    assert got[3].startswith("job 7_3 (run r3) cannot start: PartitionConfig, the request")
    assert got[4].startswith("job 7_4 (run r4) failed: ValueError: boom; log: ")
    assert cancelled == [["scancel", "7_3"]]
    assert "job 7_2 CANCELLED: r2" in capsys.readouterr().err


def test_cli_reports_jobs_without_a_result(tmp_path, capsys, monkeypatch):
    from vslbook import sweep as sweep_mod

    def fails(*args, **kwargs):
        raise sweep_mod.SweepError(["job 7_1 (run r1) ended CANCELLED without a result"],
                                   [tmp_path / "r0"])  # fmt: skip

    monkeypatch.setattr(sweep_mod, "sweep", fails)
    assert main(["sweep", "erl-pg", "--env", ENV, "--root", str(tmp_path)]) == 1
    out, err = capsys.readouterr()
    assert out.split() == [str(tmp_path / "r0")]
    assert err == "vslbook: error: job 7_1 (run r1) ended CANCELLED without a result\n"


@pytest.mark.slow
def test_overlapping_sweeps_end_with_one_clean_run_each(tmp_path):
    """Two sweeps that share seed 1 run at once: the run they share is trained once (the
    second job waits on its lock, then reuses it), and no run directory repeats a row."""
    import os

    import pandas as pd

    from vslbook.data import collect_runs
    from vslbook.results import RunDir

    root = tmp_path / "runs"
    base = [sys.executable, "-m", "vslbook.cli", "sweep", "erl-pg", "--env",
            "vslbook/PointReach-v0", "--budget", "smoke", "--executor", "local",
            "--root", str(root), "--seeds"]  # fmt: skip
    env = dict(os.environ, OMP_NUM_THREADS="1", VSLBOOK_REUSE_STALE="1")
    procs = [subprocess.Popen([*base, *seeds], env=env, stdout=subprocess.PIPE,
                              stderr=subprocess.PIPE, text=True)
             for seeds in (["0", "1"], ["1", "2"])]  # fmt: skip
    outs = [p.communicate(timeout=600) for p in procs]
    assert [p.returncode for p in procs] == [0, 0], [o[1][-2000:] for o in outs]
    dirs = sorted(p for p in root.iterdir() if (p / "config.json").is_file())
    assert len(dirs) == 3
    for path in dirs:
        rd = RunDir.open(path)
        assert rd.done
        rd.check_done()
        steps = [r["step"] for r in rd.metrics()]
        assert steps == sorted(set(steps))
    written = collect_runs(dirs, tmp_path / "data")
    runs = pd.read_csv(written["runs.csv"])
    evals = pd.read_csv(written["evals.csv.gz"])
    assert len(runs) == 3 and not evals.duplicated(["run", "step", "metric"]).any()
