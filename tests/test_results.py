"""Run directories, resume, the data/ schema and the paper data's integrity check."""

from __future__ import annotations

import hashlib
import json
import random

import numpy as np
import pandas as pd
import pytest
import torch

from vslbook import data as results_data
from vslbook import results, rng_state
from vslbook.data import DataIntegrityError
from vslbook.results import RunDir

CONFIG = {"algo": "dime", "env": "dmc_cheetah_run", "seed": 3, "lr": 3e-4, "budget": "smoke"}


@pytest.fixture
def run(tmp_path):
    return RunDir.create(tmp_path / "runs", CONFIG)


# --------------------------------------------------------------------------- run directory


def test_create_writes_config_and_env(run):
    assert run.name == f"dime-dmc_cheetah_run-s3-{results.config_hash(CONFIG)[:8]}"
    text = (run.path / "config.json").read_text()
    assert json.loads(text) == CONFIG
    assert list(json.loads(text)) == sorted(CONFIG)
    env = run.env
    assert {"python", "platform", "cpu", "hostname", "packages", "git_sha", "timestamp"} <= set(env)
    assert env["packages"]["numpy"] == np.__version__
    simd = np.show_config(mode="dicts")["SIMD Extensions"]["found"]  # the CPU NumPy ran on
    assert env["cpu"] and all(name in env["cpu"] for name in simd)
    assert not run.done


def test_config_hash_is_canonical():
    reordered = dict(reversed(list(CONFIG.items())))
    assert results.config_hash(reordered) == results.config_hash(CONFIG)
    assert results.config_hash({**CONFIG, "seed": 4}) != results.config_hash(CONFIG)
    assert len(results.config_hash(CONFIG)) == 64


def test_reopen_same_config_resumes(run, tmp_path):
    run.log(0, ret=1.0)
    again = RunDir.create(tmp_path / "runs", dict(CONFIG))
    assert again.path == run.path
    assert again.metrics() == [{"step": 0, "ret": 1.0}]
    assert RunDir.open(run.path).config == CONFIG
    with pytest.raises(FileExistsError):
        RunDir.create(tmp_path / "runs", CONFIG, exist_ok_resume=False)


def test_config_mismatch_names_the_keys(run, tmp_path):
    expected = r"different config[\s\S]*lr: 0.0003 \(existing\) vs 0.001 \(new\)"
    with pytest.raises(ValueError, match=expected):
        RunDir.create(tmp_path / "runs", {**CONFIG, "lr": 1e-3}, name=run.name)


def test_bad_names_and_open_errors(tmp_path):
    with pytest.raises(ValueError, match="not a plain directory name"):
        RunDir.create(tmp_path, CONFIG, name="../escape")
    with pytest.raises(FileNotFoundError, match="config.json"):
        RunDir.open(tmp_path)


# --------------------------------------------------------------------------- metrics


def test_metrics_append_and_read(run):
    run.log(0, ret=1.5, phase="warmup", n=np.int64(2))
    run.log(10, ret=float("nan"), loss=np.float32(0.25))
    rows = run.metrics()
    assert rows == [
        {"step": 0, "ret": 1.5, "phase": "warmup", "n": 2},
        {"step": 10, "ret": None, "loss": 0.25},
    ]
    frame = run.metrics_frame()
    assert list(frame["step"]) == [0, 10]
    assert np.isnan(frame.loc[1, "ret"])
    with pytest.raises(TypeError, match="metric 'bad'"):
        run.log(20, bad=[1, 2])
    with pytest.raises(ValueError, match="non-negative integer"):
        run.log(-1, ret=0.0)


def test_torn_last_line_is_ignored_and_repaired(run):
    run.log(0, ret=1.0)
    with open(run.metrics_path, "a") as fh:
        fh.write('{"step": 5, "re')
    assert run.metrics() == [{"step": 0, "ret": 1.0}]
    run.log(5, ret=2.0)
    assert run.metrics() == [{"step": 0, "ret": 1.0}, {"step": 5, "ret": 2.0}]


# --------------------------------------------------------------------------- checkpoint


def test_checkpoint_round_trip_is_atomic(run):
    assert run.load_checkpoint() is None
    state = {"w": torch.arange(4.0), "it": 7, "opt": {"lr": 0.1}}
    path = run.save_checkpoint(state)
    assert path == run.path / "checkpoint" / "state.pt"
    assert not path.with_name("state.pt.tmp").exists()
    assert "_metrics_lines" not in state
    loaded = run.load_checkpoint()
    assert torch.equal(loaded["w"], state["w"])
    assert loaded["it"] == 7 and loaded["opt"] == {"lr": 0.1}
    assert loaded["_metrics_lines"] == 0


def test_load_checkpoint_truncates_later_metrics(run):
    for step in range(3):
        run.log(step, ret=float(step))
    run.save_checkpoint({"it": 3})
    run.log(3, ret=3.0)
    run.log(4, ret=4.0)
    state = run.load_checkpoint()
    assert state["_metrics_lines"] == 3
    assert [row["step"] for row in run.metrics()] == [0, 1, 2]
    run.log(3, ret=3.0)
    assert [row["step"] for row in run.metrics()] == [0, 1, 2, 3]


def test_mark_done(run):
    for step in (1, 2, 5):
        run.log(step, x=step)
    run.mark_done({"final_return": 12.5}, last_step=5)
    assert run.done
    done = json.loads((run.path / "DONE").read_text())
    lines = (run.path / "metrics.jsonl").read_bytes()
    assert done["final_return"] == 12.5
    assert done["metrics"] == {"rows": 3, "last_step": 5,
                               "sha256": hashlib.sha256(lines).hexdigest()}  # fmt: skip
    run.check_done()  # the metrics are what DONE recorded


def test_done_needs_rows_that_cover_the_run(run):
    with pytest.raises(RuntimeError, match="no rows in metrics.jsonl"):
        run.mark_done()
    run.log(1, x=1)
    run.log(2, x=2)
    with pytest.raises(RuntimeError, match="ends at step 2, expected 3"):
        run.mark_done(last_step=3)
    run.log(2, x=2)
    with pytest.raises(RuntimeError, match=r"step 2 \(row 3\) follows step 2; rows repeat"):
        run.mark_done()
    assert not run.done


@pytest.mark.parametrize("damage", ["delete", "truncate", "append", "only_done"])
def test_a_done_that_its_metrics_do_not_back_is_an_error(tmp_path, damage):
    rd = RunDir.create(tmp_path, CONFIG)
    for step in range(1, 4):
        rd.log(step, x=step)
    rd.mark_done()
    metrics = rd.path / "metrics.jsonl"
    if damage == "delete":
        metrics.unlink()
    elif damage == "truncate":
        metrics.write_text(metrics.read_text().splitlines(keepends=True)[0])
    elif damage == "append":
        rd.log(4, x=4)
    else:  # a folder holding only DONE (written by hand or older code)
        metrics.unlink()
        (rd.path / "DONE").write_text("{}")
    with pytest.raises(results.RunDirError, match=r"marked DONE but .*--restart"):
        rd.check_done()


def test_rewind_drops_rows_without_a_checkpoint_and_after_one(run):
    for step in range(1, 4):
        run.log(step, x=step)
    assert run.rewind() == 3 and run.metrics() == []  # no checkpoint: the run starts over
    for step in range(1, 4):
        run.log(step, x=step)
    run.save_checkpoint({"it": 3})
    run.log(4, x=4)
    assert run.rewind() == 0  # the checkpoint's own count is applied when it is loaded
    assert run.load_checkpoint()["it"] == 3 and [r["step"] for r in run.metrics()] == [1, 2, 3]


@pytest.mark.parametrize("content", [b"", b"PK\x03\x04 not a zip", b"garbage" * 10])
def test_a_corrupt_checkpoint_is_one_line_naming_it(run, content):
    run.log(1, x=1)
    run.save_checkpoint({"it": 1})
    run.checkpoint_path.write_bytes(content)
    with pytest.raises(results.RunDirError) as err:
        run.load_checkpoint()
    message = str(err.value)
    assert "\n" not in message and str(run.checkpoint_path) in message and "--restart" in message


# --------------------------------------------------------------------------- RNG state


def _draws(gen):
    return (
        random.random(),
        np.random.rand(),  # noqa: NPY002 - the global RNG is what is being captured
        gen.normal(),
        torch.rand(1).item(),
    )


def test_rng_state_round_trip():
    gen = np.random.default_rng(1)
    _draws(gen)
    state = rng_state.rng_state(gen)
    first = [_draws(gen) for _ in range(3)]
    _draws(gen)
    rng_state.restore_rng_state(state, gen)
    assert [_draws(gen) for _ in range(3)] == first


def test_rng_state_survives_a_checkpoint(run):
    gen = np.random.default_rng(5)
    run.save_checkpoint({"rng": rng_state.rng_state(gen)})
    expected = _draws(gen)
    other = np.random.default_rng(99)
    rng_state.restore_rng_state(run.load_checkpoint()["rng"], other)
    assert _draws(other) == expected


def test_restore_rng_state_rejects_mismatch():
    with pytest.raises(ValueError, match="missing keys"):
        rng_state.restore_rng_state({"python": None})
    state = rng_state.rng_state(None)
    with pytest.raises(ValueError, match="Generator"):
        rng_state.restore_rng_state(state, np.random.default_rng(0))


# --------------------------------------------------------------------------- data schema


def _make_runs(root):
    runs = []
    for seed in (0, 1):
        run = RunDir.create(root, {**CONFIG, "seed": seed})
        run.log(0, ret=1.0 + seed, phase="eval")
        run.log(100, ret=2.5 + seed, loss=0.1)
        runs.append(run)
    runs[0].mark_done()
    return runs


def test_collect_runs_schema_and_determinism(tmp_path):
    runs = _make_runs(tmp_path / "runs")
    first = results_data.collect_runs([r.path for r in runs], tmp_path / "a")
    second = results_data.collect_runs(list(reversed(runs)), tmp_path / "b")
    for name in ("runs.csv", "evals.csv.gz", "registry.json"):
        assert first[name].read_bytes() == second[name].read_bytes(), name
    table = results_data.load_table("runs.csv", tmp_path / "a")
    assert list(table.columns) == ["run", "algo", "env", "seed", "budget", "config_hash", "status"]
    assert list(table["status"]) == ["done", "incomplete"]
    assert list(table["seed"]) == [0, 1]
    evals = results_data.load_table("evals.csv.gz", tmp_path / "a")
    assert list(evals.columns) == ["run", "step", "metric", "value"]
    assert len(evals) == 6 and set(evals["metric"]) == {"ret", "loss"}
    registry = json.loads(first["registry.json"].read_text())
    assert registry["evals.csv.gz"]["rows"] == 6 and registry["runs.csv"]["rows"] == 2


def test_load_table_default_directory(tmp_path, monkeypatch):
    monkeypatch.setenv("VSLBOOK_DATA", str(tmp_path / "data"))
    assert results_data.data_dir() == tmp_path / "data"
    results_data.collect_runs(_make_runs(tmp_path / "runs"), tmp_path / "data" / "results")
    assert len(results_data.load_table("runs.csv")) == 2


def test_load_table_detects_one_byte_corruption(tmp_path):
    out = results_data.collect_runs(_make_runs(tmp_path / "runs"), tmp_path / "out")
    path = out["runs.csv"]
    data = bytearray(path.read_bytes())
    data[-3] ^= 0x01
    path.write_bytes(bytes(data))
    with pytest.raises(DataIntegrityError, match=r"runs.csv.*sha256 does not match.*expected"):
        results_data.load_table("runs.csv", tmp_path / "out")
    with pytest.raises(DataIntegrityError):
        results_data.verify_file(path)


def test_load_table_missing_registry_or_entry(tmp_path):
    pd.DataFrame({"a": [1, 2]}).to_csv(tmp_path / "extra.csv", index=False)
    with pytest.raises(DataIntegrityError, match="no registry.json"):
        results_data.load_table("extra.csv", tmp_path)
    results_data.register_file(tmp_path / "extra.csv", "two numbers")
    pd.DataFrame({"b": [3]}).to_csv(tmp_path / "other.csv", index=False)
    with pytest.raises(DataIntegrityError, match="other.csv is not listed.*extra.csv"):
        results_data.load_table("other.csv", tmp_path)
    assert results_data.load_table("extra.csv", tmp_path)["a"].tolist() == [1, 2]


# --------------------------------------------------------------------------- paper data


def test_paper_curves_has_21_tasks_with_10_seeds(monkeypatch):
    monkeypatch.delenv("VSLBOOK_DATA", raising=False)
    frame = results_data.paper_curves()
    assert list(frame.columns) == ["env", "seed", "env_steps", "mean_return"]
    seeds = frame.groupby("env")["seed"].nunique()
    assert len(seeds) == 21 and (seeds == 10).all()
    assert results_data.paper_tasks() == sorted(seeds.index)
    dog = results_data.paper_curves("dmc_dog_run")
    assert set(dog["env"]) == {"dmc_dog_run"} and dog["env_steps"].max() == 3_000_000


def test_paper_curves_rejects_unknown_task(monkeypatch):
    monkeypatch.delenv("VSLBOOK_DATA", raising=False)
    with pytest.raises(ValueError, match=r"unknown task 'dmc_cat_run'.*dmc_acrobot.*gym_ant_v3"):
        results_data.paper_curves("dmc_cat_run")
