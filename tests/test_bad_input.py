"""Bad input is a clear ValueError (or exit code 2) naming the value and what was expected.

Nothing here trains: every call fails in validation, before a run directory exists.
"""

import dataclasses
import re

import pytest
import torch

from vslbook.cli import main
from vslbook.envs import check_env_id
from vslbook.erl.pg import ERLPGConfig
from vslbook.registry import check_seed, config_from_overrides
from vslbook.srl.diffusion_policy import DiffusionPolicy, DiffusionPolicyConfig
from vslbook.srl.dime_config import CrossQConfig, DIMEConfig, DIMEGaussianConfig
from vslbook.srl.gaussian_policy import GaussianPolicy
from vslbook.sweep import sweep  # imports submitit at collection, not under capsys
from vslbook.training import run

ENV = "vslbook/PointReach-v0"
SMALL = {"hidden": 8, "n_layers": 1, "n_frequencies": 4}


def _empty(path) -> bool:
    return not path.exists() or not any(path.iterdir())


# ----------------------------------------------------------------------------- env id and seed


@pytest.mark.parametrize(
    "env_id",
    [
        "dm_control/cheetah-run-v0",
        "vslbook/PointMassFourGoals-v0",
        "vslbook/PointReach-v0",
        "myoHandReachRandom-v0",
        "Humanoid-v5",
        "Pendulum-v1",
    ],
)
def test_known_env_ids_pass_without_building_a_simulator(env_id):
    check_env_id(env_id)


def test_unknown_env_id_names_it_and_suggests_close_matches(tmp_path):
    with pytest.raises(ValueError, match=r"unknown environment 'dm_control/cheetah-runn-v0'; "
                       r"did you mean dm_control/cheetah-run-v0"):
        run("dime", "dm_control/cheetah-runn-v0", root=tmp_path / "runs")
    with pytest.raises(ValueError, match=r"unknown environment 'vslbook/PointReach-v9'.*"
                       r"vslbook provides .*vslbook/PointReach-v0"):
        run("erl-pg", "vslbook/PointReach-v9", root=tmp_path / "runs")
    assert _empty(tmp_path / "runs")


@pytest.mark.parametrize("seed", [-1, 2.5, "x", "3", True, None, 2**32, 2**64])
@pytest.mark.parametrize("algo,env", [("erl-pg", ENV), ("svsl", "vslbook/PlanarReacher-v0"),
                                      ("dime", "dm_control/cheetah-run-v0")])  # fmt: skip
def test_bad_seed_is_an_error_before_any_directory(tmp_path, seed, algo, env):
    # one seed range for every algorithm: 0 <= seed < 2**32
    with pytest.raises(ValueError, match=rf"seed must be an integer with 0 <= seed < 2\*\*32, "
                       rf"got {re.escape(repr(seed))}"):  # fmt: skip
        run(algo, env, seed, "smoke", root=tmp_path / "runs")
    assert _empty(tmp_path / "runs")


def test_check_seed_accepts_integers():
    import numpy as np

    assert check_seed(0) == 0 and check_seed(np.int64(7)) == 7
    assert check_seed(2**32 - 1) == 2**32 - 1


def test_cli_run_bad_env_and_seed(tmp_path, capsys):
    root = tmp_path / "runs"
    assert main(["run", "dime", "--env", "cheetah-run", "--root", str(root)]) == 2
    err = capsys.readouterr().err
    assert err.startswith("vslbook: error: unknown environment 'cheetah-run'")
    assert "Traceback" not in err
    for seed in ("-1", "2.5", "x", str(2**32)):
        with pytest.raises(SystemExit) as exc:
            main(["run", "erl-pg", "--env", ENV, "--seed", seed, "--root", str(root)])
        assert exc.value.code == 2
        err = capsys.readouterr().err
        assert f"argument --seed: expected an integer with 0 <= seed < 2**32, got '{seed}'" in err
    assert _empty(root)


def test_cli_sweep_bad_env_is_one_line_and_exit_2(tmp_path, capsys):
    root = tmp_path / "runs"
    argv = ["sweep", "dime", "--env", "dm_control/dog-rum-v0", "--seeds", "0",
            "--executor", "debug", "--root", str(root)]
    assert main(argv) == 2
    captured = capsys.readouterr()
    lines = captured.err.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in captured.err
    assert lines[0].startswith("vslbook: error: unknown environment 'dm_control/dog-rum-v0'")
    assert "dm_control/dog-run-v0" in lines[0]
    assert captured.out == ""
    assert _empty(root)


def test_sweep_checks_envs_and_seeds_before_submitting(tmp_path):
    root = tmp_path / "runs"
    with pytest.raises(ValueError, match=r"unknown environment 'vslbook/PointReach'; did you"):
        sweep("erl-pg", ["vslbook/PointReach"], [0], executor="debug", root=root)
    with pytest.raises(ValueError, match=r"seed must be an integer with 0 <= seed < 2\*\*32, got -1"):  # noqa: E501
        sweep("erl-pg", [ENV], [0, -1], executor="debug", root=root)
    assert _empty(root)


# ----------------------------------------------------------------------------- device


@pytest.mark.skipif(torch.cuda.is_available(), reason="checks the error on a machine without CUDA")
@pytest.mark.parametrize("device", ["cuda", "cuda:0", "cuda:3"])
def test_cuda_without_cuda_is_a_clear_error(device):
    with pytest.raises(ValueError, match=rf"device '{device}' requested but CUDA is not available"):
        DIMEConfig(device=device)


@pytest.mark.skipif(torch.cuda.is_available(), reason="checks the error on a machine without CUDA")
def test_cli_set_device_cuda_without_cuda(tmp_path, capsys):
    argv = ["run", "dime", "--env", "vslbook/PointMassFourGoals-v0", "--root", str(tmp_path),
            "--set", "device=cuda"]
    assert main(argv) == 2
    assert "device 'cuda' requested but CUDA is not available" in capsys.readouterr().err
    assert _empty(tmp_path)


def test_cuda_index_beyond_the_device_count_is_a_clear_error():
    count = torch.cuda.device_count() if torch.cuda.is_available() else 0
    expected = "this machine has" if count else "CUDA is not available"
    with pytest.raises(ValueError, match=rf"device 'cuda:{count}' requested but .*{expected}"):
        DIMEConfig(device=f"cuda:{count}")


def test_auto_cpu_stay_valid_and_nonsense_is_unknown():
    DIMEConfig(device="auto")
    DIMEConfig(device="cpu")
    if torch.cuda.is_available():
        DIMEConfig(device="cuda")
    with pytest.raises(ValueError, match=r"unknown device 'gpu'"):
        DIMEConfig(device="gpu")


# ----------------------------------------------------------------------------- policy input


def _policies():
    return [
        DiffusionPolicy(3, 2, DiffusionPolicyConfig(n_steps=2, **SMALL)),
        GaussianPolicy(3, 2, hidden=8, n_layers=1),
    ]


@pytest.mark.parametrize("policy", _policies(), ids=["diffusion", "gaussian"])
@pytest.mark.parametrize("shape", [(4, 5), (3,), (2, 4, 3), (4, 2)])
def test_policy_sample_checks_the_observation_shape(policy, shape):
    got = rf"\({', '.join(map(str, shape))},?\)"
    with pytest.raises(ValueError, match=rf"\(batch, obs_dim\) = \(batch, 3\), got {got}"):
        policy.sample(torch.zeros(shape))
    assert policy.sample(torch.zeros(4, 3)).action.shape == (4, 2)


# ----------------------------------------------------------------------------- integer fields


def _int_fields(cls):
    return [f.name for f in dataclasses.fields(cls) if f.type == "int"]


@pytest.mark.parametrize("cls", [DIMEConfig, DIMEGaussianConfig, CrossQConfig])
def test_every_int_field_of_the_dime_configs_rejects_a_float(cls):
    names = _int_fields(cls)
    assert "utd" in names and "n_atoms" in names
    for name in names:
        with pytest.raises(ValueError, match=rf"^{name} must be an integer >= \d, got 2.5$"):
            cls(**{name: 2.5})
        with pytest.raises(ValueError, match=rf"^{name} must be an integer"):
            cls(**{name: True})


def test_diffusion_policy_config_int_fields_reject_a_float():
    for name in ("n_steps", "n_frequencies", "hidden", "n_layers"):
        with pytest.raises(ValueError, match=rf"^{name} must be an integer, got 2.5$"):
            DiffusionPolicyConfig(**{name: 2.5})


def test_overrides_with_a_float_for_an_int_field():
    with pytest.raises(ValueError, match=r"^utd=2.5: expected an integer"):
        config_from_overrides(DIMEConfig, {"utd": "2.5"})
    with pytest.raises(ValueError, match=r"^iterations=2.5: expected an integer"):
        config_from_overrides(ERLPGConfig, {"iterations": 2.5})  # ERLPGConfig itself lets it by
    assert config_from_overrides(DIMEConfig, {"utd": "3", "fixed_alpha": "none"}).utd == 3


def test_cli_set_int_and_bool_fields(tmp_path, capsys):
    base = ["run", "dime", "--env", "vslbook/PointMassFourGoals-v0", "--root", str(tmp_path)]
    assert main([*base, "--set", "utd=2.5"]) == 2
    assert "vslbook: error: utd=2.5: expected an integer" in capsys.readouterr().err
    assert main([*base, "--set", "learn_beta=maybe"]) == 2
    assert "cannot convert learn_beta='maybe' to bool" in capsys.readouterr().err
    assert _empty(tmp_path)


# ----------------------------------------------------------------------------- help


@pytest.mark.parametrize("command", ["run", "sweep"])
def test_help_lists_the_registered_algorithms(command, capsys):
    with pytest.raises(SystemExit) as exc:
        main([command, "--help"])
    assert exc.value.code == 0
    out = capsys.readouterr().out
    assert "registered algorithms" in out
    for name in ("dime", "dime-gaussian", "crossq", "erl-pg"):
        assert f"\n  {name} " in out
    assert "DIME (Algorithm 4)" in out and "envs: vslbook/PointReach-v0" in out
