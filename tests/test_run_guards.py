"""Guards around training runs: divergence ends a run FAILED (never DONE) and statistics name
the runs they could not use; a finished run is reused only by the code that produced it."""

import hashlib
import json
import warnings
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import torch

import vslbook.srl.dime_loop as dime_loop
from vslbook.data import collect_runs, load_table
from vslbook.experiments.dime_runs import run_variants
from vslbook.results import DivergenceError, RunDir
from vslbook.srl.dime_config import (
    DIMEConfig,
    config_differences,
    describe_differences,
    named_config,
)
from vslbook.srl.divergence import WATCHED, FiniteWatch
from vslbook.stats import iqm_curve
from vslbook.training import run

ENV = "Pendulum-v1"
TINY = dict(
    total_steps=100_000,  # -> 200 env steps (one episode) at the smoke budget
    learning_starts=0,
    critic_hidden=16,
    actor_hidden=16,
    n_diffusion_steps=2,
    batch_size=16,
    eval_every=100_000,  # -> 1000: one evaluation at the end
    eval_episodes=1,
    v_min=-1600.0,
    v_max=100.0,
    num_threads=1,
)



def _nan_after(monkeypatch, calls: int):
    """Make the loop's critic update report a NaN loss from its ``calls``-th call on."""
    real = dime_loop.critic_update
    count = {"n": 0}

    def update(agent, batch):
        stats = real(agent, batch)
        count["n"] += 1
        if count["n"] >= calls:
            return stats._replace(loss=torch.tensor(float("nan")))
        return stats

    monkeypatch.setattr(dime_loop, "critic_update", update)


def test_divergence_marks_the_run_failed_never_done(tmp_path, monkeypatch):
    _nan_after(monkeypatch, calls=7)  # 2 critic updates per step: the 7th is in step 4
    with pytest.warns(UserWarning, match="diverged at step 4: non-finite critic_loss"):
        rd = run("dime", ENV, 0, "smoke", root=tmp_path, overrides=TINY, progress=False)
    assert rd.status == "failed" and not rd.done
    failure = json.loads((rd.path / "FAILED").read_text())
    assert failure["step"] == 4 and failure["quantity"] == "critic_loss"
    with pytest.raises(RuntimeError, match="FAILED"):
        rd.mark_done({})
    # a second call does not train again (same code, deterministic divergence)
    monkeypatch.undo()
    with pytest.warns(UserWarning, match="diverged before"):
        again = run("dime", ENV, 0, "smoke", root=tmp_path, overrides=TINY, progress=False)
    assert again.path == rd.path and again.status == "failed"
    collect_runs([rd], tmp_path / "tables")
    assert load_table("runs.csv", tmp_path / "tables").status.tolist() == ["failed"]


def test_non_finite_parameter_is_caught_at_evaluation(tmp_path, monkeypatch):
    real = dime_loop.evaluate

    def poisoned(policy, env, **kwargs):
        return real(policy, env, **kwargs)

    def corrupt_then_check(step, agent):
        with torch.no_grad():
            agent.policy.score_net.out.bias.fill_(float("inf"))
        return check(step, agent)

    check = dime_loop.require_finite_parameters
    monkeypatch.setattr(dime_loop, "require_finite_parameters", corrupt_then_check)
    with pytest.warns(UserWarning, match="non-finite parameter policy.score_net.out.bias"):
        rd = run("dime", ENV, 1, "smoke", root=tmp_path, overrides=TINY, progress=False)
    assert rd.failure["step"] == 200


def test_statistics_name_the_runs_they_could_not_use(tmp_path, monkeypatch):
    _nan_after(monkeypatch, calls=1)  # every run of this call diverges at its first update
    with pytest.warns(UserWarning, match="diverged"):
        bad = run_variants(ENV, {"x": ("dime", {})}, seeds=1, budget="smoke",
                           root=tmp_path / "r", tables=tmp_path / "t1", common=TINY,
                           progress=False)  # fmt: skip
    assert list(bad.unusable) == [bad.runs["x"][0].name]
    assert "not used (1)" in bad.captions()
    monkeypatch.undo()
    good = run_variants(ENV, {"y": ("dime", {"actor_hidden": 8})}, seeds=1, budget="smoke",
                        root=tmp_path / "r", tables=tmp_path / "t2", common=TINY,
                        progress=False)  # fmt: skip
    frames = [f for f in (bad.evals, good.evals) if not f.empty]
    both = type(good)(pd.concat(frames), {**bad.runs, **good.runs},
                      {**bad.overrides, **good.overrides})  # fmt: skip
    with pytest.warns(UserWarning, match=r"1 run\(s\) could not be used .*FAILED"):
        rows = both.curve_rows()
    assert set(rows.variant) == {"y"}
    # iqm_curve itself reports runs whose values are not finite
    frame = pd.DataFrame({"env_steps": [1, 2, 1, 2], "mean_return": [1.0, np.nan, 2.0, 3.0],
                          "seed": [0, 0, 1, 1]})  # fmt: skip
    with pytest.warns(UserWarning, match=r"1 run\(s\) have non-finite 'mean_return'.*0 \(1 point"):
        curve = iqm_curve(frame, reps=50)
    assert curve.attrs["unused_runs"] == {"0": 1}
    assert curve.n_runs.tolist() == [2, 1]


def test_finished_run_is_reused_only_by_the_same_code(tmp_path, capsys):
    kwargs = dict(root=tmp_path, overrides=TINY, progress=False)
    first = run("dime", ENV, 0, "smoke", **kwargs)
    assert first.done and first.code_matches
    stamp = (first.path / "DONE").stat().st_mtime_ns
    assert run("dime", ENV, 0, "smoke", **kwargs).path == first.path  # same code: reused
    assert (first.path / "DONE").stat().st_mtime_ns == stamp

    env = json.loads((first.path / "env.json").read_text())
    env["code_hash"] = "0" * 64  # as if another version of the package had made it
    (first.path / "env.json").write_text(json.dumps(env))
    # other code that gives the same numbers: its replay of the first rows matches, the run
    # is kept (not retrained) and today's fingerprint is added to it
    kept = run("dime", ENV, 0, "smoke", **kwargs)
    assert kept.path == first.path and kept.code_matches
    assert (first.path / "DONE").stat().st_mtime_ns == stamp
    assert kept.env["code_hash"] == "0" * 64 and len(kept.env["code_hashes_verified"]) == 1
    assert "replay identically with today's code: kept" in capsys.readouterr().out

    # other code that gives other numbers: as if the recorded first row differed
    env = json.loads((first.path / "env.json").read_text())
    env["code_hash"], env["code_hashes_verified"] = "0" * 64, []
    (first.path / "env.json").write_text(json.dumps(env))
    lines = first.metrics_path.read_text().splitlines(keepends=True)
    row = json.loads(lines[0])
    row["eval_return"] = row["eval_return"] + 1.0
    first.metrics_path.write_text(json.dumps(row) + "\n" + "".join(lines[1:]))
    done = json.loads((first.path / "DONE").read_text())  # a DONE that backs these rows
    done["metrics"]["sha256"] = hashlib.sha256(first.metrics_path.read_bytes()).hexdigest()
    (first.path / "DONE").write_text(json.dumps(done))
    reused = run("dime", ENV, 0, "smoke", reuse_stale=True, **kwargs)
    assert reused.path == first.path and not reused.code_matches
    assert "WARNING" in capsys.readouterr().out

    fresh = run("dime", ENV, 0, "smoke", **kwargs)
    assert fresh.path == first.path and fresh.done and fresh.code_matches
    # the re-run records the algorithm's code scope like any new run
    assert fresh.env["code_excluded"] == sorted(("erl/", "envs/robot/", "experiments/"))
    moved = list((tmp_path / "_stale").iterdir())
    assert len(moved) == 1 and RunDir.open(moved[0]).code_hash == "0" * 64
    out = capsys.readouterr().out
    assert "replay: row 1, eval_return:" in out and "moved to" in out


def test_named_configurations_and_generated_differences():
    cpu = named_config("cpu-256")
    diffs = config_differences(cpu, DIMEConfig)
    assert diffs == {"n_diffusion_steps": (4, 16), "critic_hidden": (256, 2048)}
    assert describe_differences({}, DIMEConfig) == "as Table C.2"
    text = describe_differences({**cpu, "total_steps": 5, "num_threads": 1}, DIMEConfig)
    assert text == "vs Table C.2: n_diffusion_steps 4 (thesis 16), critic_hidden 256 (thesis 2048)"
    with pytest.raises(ValueError, match="unknown named configuration 'gpu'"):
        named_config("gpu")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert config_differences(DIMEConfig(learning_starts=0)) == {"learning_starts": (0, 5000)}


def test_a_runs_thread_setting_does_not_outlive_it(tmp_path):
    before = torch.get_num_threads()
    torch.set_num_threads(2)
    try:
        run("dime", ENV, 3, "smoke", root=tmp_path, overrides=TINY, progress=False)
        assert torch.get_num_threads() == 2  # TINY sets num_threads=1 for the run only
    finally:
        torch.set_num_threads(before)


def test_code_identity_covers_only_the_code_a_run_can_reach(tmp_path):
    from vslbook.registry import get_algorithm
    from vslbook.results import NOT_RUN_CODE, code_fingerprint

    rd = run("dime", ENV, 0, "smoke", root=tmp_path, overrides=TINY, progress=False)
    env = json.loads((rd.path / "env.json").read_text())
    assert env["code_excluded"] == sorted(get_algorithm("dime").independent_of)
    assert rd.code_matches
    assert env["code_hash"] == code_fingerprint(("erl/", "envs/robot/", "experiments/"))
    # Leaving out existing files changes the hash; the bare call still covers erl/.
    assert code_fingerprint() != code_fingerprint(("erl/",))
    assert set(NOT_RUN_CODE) >= {"data.py", "figures.py", "plots.py", "stats.py"}
    from vslbook.registry import ALGORITHM_MODULES, ALGORITHMS, load_plugins

    load_plugins()  # every registered algorithm says where it lives
    assert set(ALGORITHMS) <= set(ALGORITHM_MODULES)


def test_dime_runs_import_nothing_they_declare_independent_of(tmp_path):
    # The claim behind `independent_of` checked in a fresh interpreter: a DIME run through
    # the CLI loads no module under vslbook/erl or vslbook/envs/robot.
    import subprocess
    import sys

    script = (
        "import sys, json\n"
        "from vslbook.training import run\n"
        f"run('dime', {ENV!r}, 0, 'smoke', root={str(tmp_path)!r}, overrides={TINY!r},"
        " progress=False)\n"
        "print(json.dumps(sorted(m for m in sys.modules if m.startswith('vslbook.'))))\n"
    )
    out = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True,
                         check=True, env={**__import__("os").environ, "OMP_NUM_THREADS": "1"})
    loaded = json.loads(out.stdout.strip().splitlines()[-1])
    assert "vslbook.srl.dime" in loaded
    assert not [m for m in loaded
                if m.startswith(("vslbook.erl", "vslbook.envs.robot", "vslbook.experiments"))]


@pytest.mark.slow
def test_the_experiments_modules_runs_load_are_part_of_their_code_identity(tmp_path):
    # experiments/ holds analysis and run code: every module of it that a Chapter 3 or 4
    # run loads, trained in a fresh interpreter, must be in RUN_EXPERIMENTS, or editing it
    # would never mark the run's numbers stale. erl-pg loads none.
    import subprocess
    import sys

    from vslbook.provenance import RUN_EXPERIMENTS

    runs = [("svsl", "vslbook/BeerPong-v0"), ("hireps", "vslbook/BeerPong-v0"),
            ("ladips", "vslbook/TableTennisCh3-v0"), ("ppo", "vslbook/Reacher5Ch3Step-v0"),
            ("diskill", "vslbook/Reacher5-v0"),
            ("ppo-ch4", "vslbook/Reacher5SparseStep-v0")]  # fmt: skip
    script = (
        "import sys, json\n"
        "from vslbook.training import run\n"
        f"for algo, env in {runs!r}:\n"
        f"    run(algo, env, 0, 'smoke', root={str(tmp_path)!r}, progress=False)\n"
        "print(json.dumps(sorted(m for m in sys.modules if m.startswith('vslbook.'))))\n"
    )
    env = {**__import__("os").environ, "OMP_NUM_THREADS": "1", "VSLBOOK_WORKERS": "0"}
    out = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True,
                         check=True, env=env)  # fmt: skip
    loaded = json.loads(out.stdout.strip().splitlines()[-1])
    used = {m.removeprefix("vslbook.").replace(".", "/") + ".py"
            for m in loaded if m.startswith("vslbook.experiments.")}  # fmt: skip
    assert {"experiments/ch3_algorithms.py", "experiments/svsl_beer_pong.py"} <= used
    assert sorted(used - set(RUN_EXPERIMENTS)) == []


def test_editing_run_code_in_experiments_changes_the_code_identity(tmp_path):
    import shutil

    import vslbook
    from vslbook.provenance import package_fingerprint

    package = tmp_path / "vslbook"
    shutil.copytree(Path(vslbook.__file__).parent, package,
                    ignore=shutil.ignore_patterns("__pycache__"))  # fmt: skip
    before = package_fingerprint(package)

    def edited(rel: str) -> str:
        path = package / rel
        text = path.read_text()
        path.write_text(text + "\n# an edit\n")
        try:
            return package_fingerprint.__wrapped__(package)
        finally:
            path.write_text(text)

    assert edited("experiments/svsl_mixtures.py") != before  # a run loop's tests
    assert edited("experiments/ch4_algorithms.py") != before
    assert edited("erl/svsl.py") != before
    assert edited("experiments/figure_draws.py") == before  # figures only
    assert edited("plots.py") == before
    assert edited("plot_style.py") == before
    # an algorithm's scope leaves its unreachable code out, run code of experiments/ too
    scoped = package_fingerprint.__wrapped__(package, ("experiments/",))
    path = package / "experiments/svsl_mixtures.py"
    path.write_text(path.read_text() + "\n# an edit\n")
    assert package_fingerprint.__wrapped__(package, ("experiments/",)) == scoped


# ------------------------------------------------------------------ divergence on the device


def test_finite_watch_keeps_the_first_non_finite_update():
    watch = FiniteWatch(("a", "b", "c"), torch.device("cpu"))
    watch.add(1, a=torch.tensor(1.0), b=torch.tensor(2.0))
    watch.check()  # all finite: nothing to say
    watch.add(2, c=torch.tensor(3.0))
    watch.add(3, a=torch.tensor(0.5), b=torch.tensor(float("-inf")))
    watch.add(4, a=torch.tensor(float("nan")), b=torch.tensor(1.0))  # later: not reported
    watch.add(5, c=torch.tensor(float("nan")))
    with pytest.raises(DivergenceError) as err:
        watch.check()
    assert (err.value.step, err.value.quantity, err.value.value) == (3, "b", float("-inf"))
    watch.reset()
    watch.add(9, c=torch.tensor(float("nan")))
    with pytest.raises(DivergenceError, match="step 9: non-finite c"):
        watch.check()


def test_the_update_loop_never_reads_a_tensor_on_the_host(monkeypatch):
    """Algorithm 4's updates (l. 7-10), one seed and on the seed axis, and the finiteness
    watch with every way of reading a tensor's value on the host disabled: no update waits
    for the device."""
    from vslbook.srl.dime_updates import actor_update, alpha_update, critic_update, make_agent
    from vslbook.srl.replay import ReplayBuffer

    cfg = DIMEConfig(**{k: v for k, v in TINY.items() if k not in ("total_steps",)})
    agent = make_agent(3, 1, cfg, v_min=-1600.0, v_max=100.0, device=torch.device("cpu"))
    buffer = ReplayBuffer(64, 3, 1)
    rng = np.random.default_rng(0)
    for _ in range(64):
        buffer.add(rng.normal(size=3), rng.uniform(-1, 1, 1), 0.1, rng.normal(size=3), False)
    watch = FiniteWatch(WATCHED, torch.device("cpu"))
    batches = [buffer.sample(16, rng) for _ in range(4)]  # indices drawn on the host
    from vslbook.srl.replay import Batch
    from vslbook.srl.seed_axis import SeedStack

    cpu = torch.device("cpu")
    stack = SeedStack([make_agent(3, 1, cfg, v_min=-1600.0, v_max=100.0, device=cpu)
                       for _ in range(2)])  # fmt: skip
    seed_watch = FiniteWatch(WATCHED, cpu, seeds=2)
    gens = [torch.Generator().manual_seed(s) for s in (0, 1)]
    noises = [(stack.noise(gens, 16), stack.noise(gens, 16)) for _ in batches]

    def refuse(*args, **kwargs):
        raise AssertionError("a host read of a tensor inside the update loop")

    for name in ("item", "tolist", "__bool__", "__float__", "__int__", "__index__", "numpy"):
        monkeypatch.setattr(torch.Tensor, name, refuse)
    for k, batch in enumerate(batches):
        stats = critic_update(agent, batch)
        watch.add(k, critic_loss=stats.loss, q_mean=stats.value)
        actor = actor_update(agent, batch.obs)
        alpha_loss = alpha_update(agent, actor.running_cost)
        watch.add(k, actor_loss=actor.loss, entropy_bound=actor.value, alpha_loss=alpha_loss)
        two = Batch(*[torch.stack([x, x]) for x in batch])  # the seed axis: S = 2
        stats = stack.critic_update(two, noises[k][0])
        seed_watch.add(k, critic_loss=stats.loss, q_mean=stats.value)
        actor = stack.actor_update(two.obs, noises[k][1])
        alpha_loss = stack.alpha_update(actor.running_cost)
        seed_watch.add(k, actor_loss=actor.loss, entropy_bound=actor.value, alpha_loss=alpha_loss)
    monkeypatch.undo()
    watch.check()
    assert seed_watch.failures() == {}
    with pytest.raises(AssertionError, match="host read"):  # the guard itself bites
        monkeypatch.setattr(torch.Tensor, "item", refuse)
        torch.tensor(1.0).item()


def test_a_diverged_policy_stops_the_run_before_it_acts(tmp_path, monkeypatch):
    """Parameters gone non-finite in an update: the next action is non-finite, and the run
    ends FAILED naming the update's quantity and step (not the action), before a simulator
    that refuses non-finite controls (dm_control) would see one."""
    real = dime_loop.critic_update
    count = {"n": 0}

    def update(agent, batch):
        stats = real(agent, batch)
        count["n"] += 1
        if count["n"] == 7:  # in env step 4
            with torch.no_grad():
                agent.policy.score_net.out.bias.fill_(float("nan"))
            return stats._replace(value=torch.tensor(float("nan")))
        return stats

    monkeypatch.setattr(dime_loop, "critic_update", update)
    with pytest.warns(UserWarning, match="diverged at step 4: non-finite q_mean"):
        rd = run("dime", ENV, 0, "smoke", root=tmp_path, overrides=TINY, progress=False)
    assert rd.failure["step"] == 4 and rd.failure["quantity"] == "q_mean"
    assert count["n"] == 8  # step 4's second update ran (its loss NaN); step 5's action stopped it

    def silent(agent, batch):  # the parameters diverge, the losses say nothing
        stats = real(agent, batch)
        count["n"] += 1
        if count["n"] == 4:  # step 2's second update; the next actor update would be the 6th
            with torch.no_grad():
                agent.policy.score_net.out.bias.fill_(float("nan"))
        return stats

    count["n"] = 0
    monkeypatch.setattr(dime_loop, "critic_update", silent)
    with pytest.warns(UserWarning, match="diverged at step 3: non-finite action"):
        rd = run("dime", ENV, 1, "smoke", root=tmp_path, overrides=TINY, progress=False)
    assert rd.failure["quantity"] == "action"
