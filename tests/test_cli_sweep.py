import json
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

from vslbook.cli import main
from vslbook.sweep import expand_grid, load_slurm_config, sweep

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
