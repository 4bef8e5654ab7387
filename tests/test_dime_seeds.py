"""Several DIME seeds in one process (vslbook.training.run_seeds, vslbook.srl.dime_seeds)."""

from __future__ import annotations

import json

import pytest
import torch

from vslbook.cli import main
from vslbook.training import run, run_seeds

ENV = "Pendulum-v1"
TINY = dict(
    total_steps=200_000,  # 400 env steps (two Pendulum episodes) at the smoke budget
    learning_starts=50, critic_hidden=32, actor_hidden=32, n_diffusion_steps=2,
    batch_size=32, eval_every=100_000, eval_episodes=1, checkpoint_every=100_000,
    v_min=-1600.0, v_max=100.0, num_threads=1,
)  # fmt: skip
CLOCKS = {"critic_updates_per_s", "env_steps_per_s"}


def _rows(rd):
    return [json.loads(x) for x in (rd.path / "metrics.jsonl").read_text().splitlines()]


def _no_clocks(rows):
    return [{k: v for k, v in r.items() if k not in CLOCKS} for r in rows]


def test_each_seed_learns_as_it_would_alone(tmp_path):
    alone = [run("dime", ENV, s, "smoke", root=tmp_path / "one", overrides=TINY,
                 progress=False) for s in (0, 1, 2)]  # fmt: skip
    together = run_seeds("dime", ENV, [0, 1, 2], "smoke", root=tmp_path / "three",
                         overrides=TINY, progress=False)  # fmt: skip
    for a, b in zip(alone, together, strict=True):
        assert a.name == b.name and b.done  # the same run directory a single run makes
        ra, rb = _rows(a)[-1], _rows(b)[-1]
        assert ra["critic_updates"] == rb["critic_updates"] and ra["episodes"] == rb["episodes"]
        for key in ("critic_loss", "q_mean", "alpha", "actor_loss", "train_return"):
            assert rb[key] == pytest.approx(ra[key], rel=2e-3, abs=1e-3), key
    # three different seeds, three different runs
    assert len({_rows(b)[-1]["train_return"] for b in together}) == 3


def test_one_seed_and_the_seed_axis_run_the_same_steps(tmp_path, monkeypatch):
    """Both run Algorithm 4 through the one loop (vslbook.srl.dime_loop): the same steps in
    the same order, only the learner differs (one Agent, or a SeedStack over the seeds)."""
    from vslbook.srl import dime_loop, dime_seeds

    assert dime_seeds.run_algorithm4 is dime_loop.run_algorithm4
    calls = []
    for name in ("collect", "update", "evaluate", "end_episodes", "checkpoint"):
        real = getattr(dime_loop.DimeLoop, name)

        def spy(self, *args, _real=real, _name=name, **kwargs):
            calls.append((type(self.learner).__name__, _name, len(self.live)))
            return _real(self, *args, **kwargs)

        monkeypatch.setattr(dime_loop.DimeLoop, name, spy)
    over = dict(TINY, total_steps=100_000)  # 200 env steps, learning from step 50
    run("dime", ENV, 0, "smoke", root=tmp_path / "a", overrides=over, progress=False)
    run_seeds("dime", ENV, [0, 1], "smoke", root=tmp_path / "b", overrides=over, progress=False)
    one = [c[1:] for c in calls if c[0] == "OneSeed"]
    axis = [c[1:] for c in calls if c[0] == "StackedSeeds"]
    assert len(one) + len(axis) == len(calls)
    assert [name for name, _ in one] == [name for name, _ in axis]
    assert {n for _, n in one} == {1} and {n for _, n in axis} == {2}
    steps = [name for name, _ in one]
    assert steps.count("collect") == 200 and steps.count("update") == 151  # steps 50..200
    assert steps.count("evaluate") == 1 and steps[-1] == "checkpoint"


def test_interrupted_mid_episode_resumes_exactly(tmp_path):
    whole = run_seeds("dime", ENV, [3, 4], "smoke", root=tmp_path / "a", overrides=TINY,
                      progress=False)  # fmt: skip
    part = run_seeds("dime", ENV, [3, 4], "smoke", root=tmp_path / "b", overrides=TINY,
                     progress=False, stop_after=130)  # fmt: skip
    assert not any(rd.done for rd in part)  # stopped at step 130, inside the first episode
    part = run_seeds("dime", ENV, [3, 4], "smoke", root=tmp_path / "b", overrides=TINY,
                     progress=False)  # fmt: skip
    for a, b in zip(whole, part, strict=True):
        assert b.done and _no_clocks(_rows(a)) == _no_clocks(_rows(b))


@pytest.mark.parametrize("first", [True, False])
def test_a_crash_between_two_seeds_checkpoints_resumes_exactly(tmp_path, monkeypatch, first):
    """The stack writes its seeds' checkpoints one after another; a crash between two writes
    leaves seed 3 a checkpoint ahead of seed 4. It rolls back to its previous checkpoint
    (or, at the first checkpoint, starts afresh) so the two resume together, exactly."""
    from vslbook.srl.dime_state import SeedState

    # the full budget, so that counts are env steps: a checkpoint every 40 of 400 steps
    over = TINY | {"total_steps": 400, "eval_every": 100, "checkpoint_every": 40}
    whole = run_seeds("dime", ENV, [3, 4], "full", root=tmp_path / "a", overrides=over,
                      progress=False)  # fmt: skip
    original = SeedState.checkpoint
    crash_at = 40 if first else 120  # the first checkpoint of the stack, or the third

    def crashing(self, agent_state, *, final=False, keep_previous=False):
        if self.seed == 4 and self.step >= crash_at and not final:
            raise KeyboardInterrupt("killed between the two seeds' checkpoints")
        return original(self, agent_state, final=final, keep_previous=keep_previous)

    monkeypatch.setattr(SeedState, "checkpoint", crashing)
    with pytest.raises(KeyboardInterrupt):
        run_seeds("dime", ENV, [3, 4], "full", root=tmp_path / "b", overrides=over,
                  progress=False)  # fmt: skip
    monkeypatch.setattr(SeedState, "checkpoint", original)
    states = [rd / "checkpoint" / "state.pt" for rd in sorted((tmp_path / "b").glob("dime-*"))]
    steps = [torch.load(p, weights_only=False)["step"] if p.exists() else 0 for p in states]
    assert steps[0] > steps[1] and (steps[1] == 0) == first  # seed 3 ahead of seed 4
    resumed = run_seeds("dime", ENV, [3, 4], "full", root=tmp_path / "b", overrides=over,
                        progress=False)  # fmt: skip
    for a, b in zip(whole, resumed, strict=True):
        assert b.done and _no_clocks(_rows(a)) == _no_clocks(_rows(b))


def test_a_single_seed_run_resumes_a_stacked_checkpoint(tmp_path):
    """The checkpoint format is the single-seed one (plus the cut episode's actions)."""
    (part,) = run_seeds("dime", ENV, [5], "smoke", root=tmp_path, overrides=TINY,
                        progress=False, stop_after=130)  # fmt: skip
    assert not part.done
    rd = run("dime", ENV, 5, "smoke", root=tmp_path, overrides=TINY, progress=False)
    assert rd.path == part.path and rd.done
    ref = run("dime", ENV, 5, "smoke", root=tmp_path / "ref", overrides=TINY, progress=False)
    got, want = _rows(rd)[-1], _rows(ref)[-1]
    assert got["critic_updates"] == want["critic_updates"]
    assert got["alpha"] == pytest.approx(want["alpha"], rel=2e-3)


def test_bad_requests_are_clear_errors(tmp_path, capsys):
    with pytest.raises(ValueError, match="'erl-pg' trains one seed per process"):
        run_seeds("erl-pg", "vslbook/PointReach-v0", [0, 1], root=tmp_path)
    with pytest.raises(ValueError, match=r"seeds must be distinct.*\[1, 1\]"):
        run_seeds("dime", ENV, [1, 1], root=tmp_path)
    with pytest.raises(ValueError, match=r"seed must be an integer with 0 <= seed < 2\*\*32, got -1"):  # noqa: E501
        run_seeds("dime", ENV, [0, -1], root=tmp_path)
    assert not any(tmp_path.iterdir())
    with pytest.raises(SystemExit):
        main(["run", "dime", "--env", ENV, "--seed", "0", "--seeds", "1", "2"])
    assert "not allowed with argument" in capsys.readouterr().err


def test_target_network_ablation_trains_its_seeds_one_after_the_other(tmp_path):
    over = dict(TINY, total_steps=100_000, use_target_network=True)  # 200 steps
    together = run_seeds("dime", ENV, [0, 1], "smoke", root=tmp_path / "a", overrides=over,
                         progress=False)  # fmt: skip
    alone = run("dime", ENV, 1, "smoke", root=tmp_path / "b", overrides=over, progress=False)
    assert all(rd.done for rd in together)
    assert _no_clocks(_rows(together[1])) == _no_clocks(_rows(alone))  # the same loop


def test_compiled_updates_train_their_seeds_one_after_the_other(tmp_path, monkeypatch):
    """compile=True is honoured with several seeds: each seed goes through the single-seed
    loop, which compiles its updates (torch.compile itself is replaced here: CI has no time
    for inductor)."""
    import torch

    compiled = []
    monkeypatch.setattr(torch, "compile", lambda fn, **kw: compiled.append(fn.__name__) or fn)
    over = dict(TINY, total_steps=100_000, compile=True)
    together = run_seeds("dime", ENV, [0, 1], "smoke", root=tmp_path / "a", overrides=over,
                         progress=False)  # fmt: skip
    assert all(rd.done for rd in together)
    assert compiled == ["critic_update", "actor_update"] * 2


def test_seeds_at_different_steps_train_in_groups(tmp_path):
    """A seed checkpointed earlier alone and a fresh one: each ends as it would alone."""
    run("dime", ENV, 1, "smoke", root=tmp_path / "b", overrides=TINY, progress=False,
        stop_after=150)  # fmt: skip
    both = run_seeds("dime", ENV, [0, 1], "smoke", root=tmp_path / "b", overrides=TINY,
                     progress=False)  # fmt: skip
    alone = run("dime", ENV, 1, "smoke", root=tmp_path / "c", overrides=TINY, progress=False)
    assert all(rd.done for rd in both)
    got, want = _rows(both[1])[-1], _rows(alone)[-1]
    assert got["critic_updates"] == want["critic_updates"]
    assert got["alpha"] == pytest.approx(want["alpha"], rel=2e-3)


def test_device_drawn_replay_indices_resume_exactly_in_either_loop(tmp_path):
    """replay_sampler='device' (the GPU default) on the CPU: an interrupted run resumes to the
    same numbers, the seed axis reproduces the single-seed loop, and the stream is not
    numpy's."""
    dev = {**TINY, "replay_sampler": "device"}
    (whole,) = [run("dime", ENV, 6, "smoke", root=tmp_path / "a", overrides=dev,
                    progress=False)]  # fmt: skip
    part = run("dime", ENV, 6, "smoke", root=tmp_path / "b", overrides=dev, progress=False,
               stop_after=130)  # fmt: skip
    assert not part.done
    part = run("dime", ENV, 6, "smoke", root=tmp_path / "b", overrides=dev, progress=False)
    assert _no_clocks(_rows(whole)) == _no_clocks(_rows(part))
    (stacked,) = run_seeds("dime", ENV, [6], "smoke", root=tmp_path / "c", overrides=dev,
                           progress=False, stop_after=130)  # fmt: skip
    (stacked,) = run_seeds("dime", ENV, [6], "smoke", root=tmp_path / "c", overrides=dev,
                           progress=False)  # fmt: skip
    ra, rb = _rows(whole)[-1], _rows(stacked)[-1]
    for key in ("critic_loss", "q_mean", "alpha", "actor_loss", "train_return"):
        assert rb[key] == pytest.approx(ra[key], rel=2e-3, abs=1e-3), key
    numpy_drawn = run("dime", ENV, 6, "smoke", root=tmp_path / "d", overrides=TINY,
                      progress=False)  # fmt: skip
    assert _rows(numpy_drawn)[-1]["critic_loss"] != ra["critic_loss"]


def test_a_diverged_seed_leaves_the_stack_and_the_others_finish(tmp_path, monkeypatch):
    """Seed 8's policy goes non-finite in the 7th stacked update (env step 53): it is marked
    FAILED naming that update; seeds 7 and 9 finish as they do in an undisturbed stack."""
    from vslbook.srl import seed_axis

    clean = run_seeds("dime", ENV, [7, 8, 9], "smoke", root=tmp_path / "a", overrides=TINY,
                      progress=False)  # fmt: skip
    real = seed_axis.SeedStack.critic_update
    calls = {"n": 0}

    def update(self, batch, noise):
        stats = real(self, batch, noise)
        calls["n"] += 1
        if calls["n"] == 7 and self.n_seeds == 3:
            with torch.no_grad():
                for name, p in self.params.items():
                    if name.startswith("policy."):
                        p[1].fill_(float("nan"))  # seed 8 is position 1
            value = stats.value.clone()
            value[1] = float("nan")
            return stats._replace(value=value)
        return stats

    monkeypatch.setattr(seed_axis.SeedStack, "critic_update", update)
    with pytest.warns(UserWarning, match="diverged at step 53: non-finite q_mean"):
        hit = run_seeds("dime", ENV, [7, 8, 9], "smoke", root=tmp_path / "b", overrides=TINY,
                        progress=False)  # fmt: skip
    assert [rd.status for rd in hit] == ["done", "failed", "done"]
    assert hit[1].failure["step"] == 53 and hit[1].failure["quantity"] == "q_mean"
    for a, b in ((clean[0], hit[0]), (clean[2], hit[2])):
        ra, rb = _rows(a)[-1], _rows(b)[-1]
        assert ra["critic_updates"] == rb["critic_updates"]
        for key in ("critic_loss", "q_mean", "alpha", "actor_loss", "train_return"):
            assert rb[key] == pytest.approx(ra[key], rel=2e-3, abs=1e-3), key

    def loss_only(self, batch, noise):  # a non-finite loss, the policy unharmed: the episode
        stats = real(self, batch, noise)  # end (not an action) must catch it
        calls["n"] += 1
        if calls["n"] == 7 and self.n_seeds == 3:
            value = stats.value.clone()
            value[2] = float("inf")
            return stats._replace(value=value)
        return stats

    calls["n"] = 0
    monkeypatch.setattr(seed_axis.SeedStack, "critic_update", loss_only)
    with pytest.warns(UserWarning, match="diverged at step 53: non-finite q_mean"):
        hit = run_seeds("dime", ENV, [7, 8, 9], "smoke", root=tmp_path / "c", overrides=TINY,
                        progress=False)  # fmt: skip
    assert [rd.status for rd in hit] == ["done", "done", "failed"]
    assert not (hit[2].path / "metrics.jsonl").exists()  # dropped before any evaluation
