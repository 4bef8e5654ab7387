"""SVSL (Algorithm 1) on the planar reacher: schedule, bounds, determinism, resume, learning."""

from dataclasses import replace

import numpy as np
import pytest

from vslbook.envs.robot import make_task
from vslbook.erl.svsl import SVSL, svsl_config, train


def _tiny(**kw):
    base = dict(
        n_experts=3, iterations_per_expert=6, fine_tune_every=3, weight_iterations=4,
        test_every=3, test_contexts=20, delete_local_optima=False,
    )  # fmt: skip
    return svsl_config("planar-reacher", **(base | kw))


@pytest.fixture(scope="module")
def task():
    return make_task("planar-reacher")


def _gauss_kl(m1, s1, m0, s0):
    """KL(N(m1, s1) ‖ N(m0, s0)), written out here."""
    d = len(m1)
    s0i = np.linalg.inv(s0)
    diff = m0 - m1
    return 0.5 * (
        np.trace(s0i @ s1) + diff @ s0i @ diff - d
        + np.linalg.slogdet(s0)[1] - np.linalg.slogdet(s1)[1]
    )  # fmt: skip


def test_schedule_follows_algorithm_1(task, monkeypatch):
    cfg = _tiny()
    sizes = []
    orig = SVSL.update_experts

    def spy(self, experts):
        sizes.append((self.iteration, len(experts), int(experts[-1])))
        return orig(self, experts)

    monkeypatch.setattr(SVSL, "update_experts", spy)
    s = train(task, cfg, seed=0)
    # N·K adding iterations; every H-th iteration of each expert updates all of them
    assert len(sizes) == cfg.n_experts * cfg.iterations_per_expert
    for t, n, last in sizes:
        k, i = divmod(t, cfg.iterations_per_expert)
        assert last == k  # the newest expert is always among the updated ones
        assert n == (k + 1 if (i + 1) % cfg.fine_tune_every == 0 else 1)
    assert s.iteration == cfg.total_iterations
    w = np.exp(s.model.log_w)
    assert w.sum() == pytest.approx(1.0)
    assert s.model.n_experts <= cfg.n_experts


def test_updates_respect_their_kl_bounds(task):
    cfg = _tiny(kl_expert=0.05, kl_context=0.02)
    s = train(task, cfg, seed=1, until=2)
    m = s.model
    old = m.arrays()
    e = np.array([0])
    s.update_experts(e)
    c = s.buffers.c[0]  # the contexts the expected KL is taken over
    kls = [
        _gauss_kl(m.gain[0] @ ci + m.offset[0], m.cov[0],
                  old["gain"][0] @ ci + old["offset"][0], old["cov"][0])
        for ci in c
    ]  # fmt: skip
    assert 0 < np.mean(kls) <= cfg.kl_expert * 1.01
    s.update_contexts(e)
    kl = _gauss_kl(m.ctx_mean[0], m.ctx_cov[0], old["ctx_mean"][0], old["ctx_cov"][0])
    assert 0 < kl <= cfg.kl_context * 1.01


def test_responsibilities_switch(task):
    s = train(task, _tiny(), seed=2, until=14)  # three experts exist
    e = np.arange(s.model.n_experts)
    with_resp = s.expert_targets(e)
    assert not np.allclose(with_resp, s.buffers.ret[e])
    s.config = replace(s.config, responsibilities=False)
    np.testing.assert_array_equal(s.expert_targets(e), s.buffers.ret[e])
    h = s.model.expert_entropy()[:, None]
    np.testing.assert_allclose(s.context_targets(e), s.buffers.ret[e] + s.config.alpha * h)


def test_responsibility_terms_are_bayes_rule(task):
    s = train(task, _tiny(), seed=3, until=14)
    m = s.model
    c, th = s.buffers.c[1][:5], s.buffers.theta[1][:5]
    log_resp, log_gate = m.log_responsibilities(c, th)
    # by hand: Gaussian densities of every factor
    from scipy.stats import multivariate_normal as mvn

    w = np.exp(m.log_w)
    pc = np.stack([mvn(m.ctx_mean[o], m.ctx_cov[o]).pdf(c) for o in range(m.n_experts)], 1)
    pt = np.stack(
        [[mvn(m.gain[o] @ ci + m.offset[o], m.cov[o]).pdf(ti) for ci, ti in zip(c, th, strict=True)]
         for o in range(m.n_experts)], 1,
    )  # fmt: skip
    gate = pc * w / (pc * w).sum(1, keepdims=True)
    resp = pt * gate / (pt * gate).sum(1, keepdims=True)
    np.testing.assert_allclose(np.exp(log_gate), gate, rtol=1e-8)
    np.testing.assert_allclose(np.exp(log_resp), resp, rtol=1e-6, atol=1e-300)


@pytest.mark.parametrize("line_13", [False, True])
def test_deterministic_and_resumes_exactly(task, line_13):
    # with line 13 and factor 1 the newest expert goes whenever it is worse than the others'
    # mean; the split at 11 falls before the check after expert 2 (iteration 12)
    cfg = _tiny(delete_local_optima=line_13, local_optimum_factor=1.0)
    rows_a, rows_b = [], []
    a = train(task, cfg, seed=4, callback=lambda i, m: rows_a.append((i, m)))
    half = train(task, cfg, seed=4, until=11, callback=lambda i, m: rows_b.append((i, m)))
    state = half.state_dict()
    fresh = SVSL(task, cfg, 4)
    fresh.load_state_dict(state)
    b = train(task, cfg, seed=4, state=fresh, callback=lambda i, m: rows_b.append((i, m)))

    def strip(rows):
        return [(i, {k: v for k, v in m.items() if k != "iteration_seconds"}) for i, m in rows]

    assert strip(rows_a) == strip(rows_b)
    for k, v in a.model.arrays().items():
        np.testing.assert_array_equal(v, b.model.arrays()[k])


PLANAR = "vslbook/PlanarReacher-v0"
#: `vslbook run svsl --env vslbook/PlanarReacher-v0 --set ...`: the _tiny() configuration
TINY_SETS = dict(
    n_experts=3, iterations_per_expert=6, fine_tune_every=3, weight_iterations=4,
    test_every=3, test_contexts=20, delete_local_optima=False,
)  # fmt: skip


def _metrics(rd):
    return [{k: v for k, v in m.items() if k != "iteration_seconds"} for m in rd.metrics()]


def test_run_directory_resumes(tmp_path):
    """A run directory of `vslbook run svsl` (vslbook.training.run) that crashed after
    logging two iterations past its last checkpoint resumes to the uninterrupted run."""
    from vslbook.training import run

    kwargs = dict(overrides=TINY_SETS, progress=False)
    full = run("svsl", PLANAR, 5, "smoke", root=tmp_path / "a", **kwargs)
    assert full.done and len(full.metrics()) == 3 * 6 + 4
    assert full.config["n_experts"] == 3 and full.config["alpha"] == _tiny().alpha
    part = run("svsl", PLANAR, 5, "smoke", root=tmp_path / "b", stop_after=10, **kwargs)
    assert not part.done and part.load_checkpoint()["svsl"]["iteration"] == 10
    lines = full.metrics_path.read_text().splitlines(keepends=True)
    with open(part.metrics_path, "a") as f:  # iterations 11 and 12 logged, then the crash
        f.writelines(lines[10:12])
    resumed = run("svsl", PLANAR, 5, "smoke", root=tmp_path / "b", **kwargs)
    assert resumed.done and _metrics(resumed) == _metrics(full)


def test_finished_run_made_by_other_code_is_redone_only_if_it_replays_otherwise(tmp_path):
    import json

    from vslbook.training import run

    kwargs = dict(root=tmp_path, progress=False,
                  overrides=TINY_SETS | dict(n_experts=1, iterations_per_expert=3,
                                             weight_iterations=0, test_every=1))  # fmt: skip
    first = run("svsl", PLANAR, 6, "smoke", **kwargs)
    assert run("svsl", PLANAR, 6, "smoke", **kwargs).path == first.path  # same code: reused
    env = json.loads((first.path / "env.json").read_text())
    env["code_hash"] = "0" * 64  # made by other code ...
    (first.path / "env.json").write_text(json.dumps(env))
    assert run("svsl", PLANAR, 6, "smoke", **kwargs).path == first.path  # ... same numbers
    assert not (tmp_path / "_stale").exists()
    env = json.loads((first.path / "env.json").read_text())
    env["code_hash"], env["code_hashes_verified"] = "0" * 64, []
    (first.path / "env.json").write_text(json.dumps(env))
    lines = first.metrics_path.read_text().splitlines(keepends=True)
    row = json.loads(lines[0])
    row["test_return"] += 1.0  # ... other numbers
    first.metrics_path.write_text(json.dumps(row) + "\n" + "".join(lines[1:]))
    again = run("svsl", PLANAR, 6, "smoke", **kwargs)
    assert again.path == first.path and again.done and again.code_matches
    assert len(list((tmp_path / "_stale").iterdir())) == 1  # the old one moved aside


def test_line_13_deletes_the_newest_expert_by_the_authors_rule(task):
    s = SVSL(task, _tiny(delete_local_optima=True), 0)
    for _ in range(3):
        s.add_expert()
    n = s.config.buffer_size
    s.buffers.theta[:] = np.arange(3)[:, None, None]  # tells the experts' buffers apart
    s.buffers.ret[0], s.buffers.ret[1] = np.linspace(-0.5, -1.5, n), -3.0  # means -1, -3
    before = {k: v.copy() for k, v in s.model.arrays().items()}
    s.buffers.ret[2] = -9.9  # the others' mean is -2: -9.9 >= 5 * -2, kept
    assert not s.delete_if_local_optimum() and s.model.n_experts == 3
    s.buffers.ret[2] = -10.1  # below 5 * -2: a local optimum
    assert s.delete_if_local_optimum()
    assert s.model.n_experts == 2 and s.buffers.ret.shape == (2, n)
    np.testing.assert_array_equal(s.buffers.theta[:, 0, 0], [0, 1])
    for k in ("ctx_mean", "ctx_cov", "gain", "offset", "cov"):
        np.testing.assert_array_equal(getattr(s.model, k), before[k][:2])
    np.testing.assert_allclose(np.exp(s.model.log_w), [0.5, 0.5])
    s.buffers.ret[0] = 2.0  # the others' mean is not negative: the rule deletes nothing
    s.buffers.ret[1] = -1.0
    assert not s.delete_if_local_optimum()
    one = SVSL(task, _tiny(delete_local_optima=True), 0)
    one.add_expert()
    one.buffers.ret[0] = -100.0
    assert not one.delete_if_local_optimum()  # nothing to compare with


@pytest.mark.parametrize(("factor", "kept"), [(1e-9, 1), (1e9, 3)])
def test_line_13_runs_after_each_expert_s_k_iterations(task, factor, kept):
    """A tiny factor deletes every expert after the first (returns are costs); a huge none."""
    cfg = _tiny(delete_local_optima=True, local_optimum_factor=factor, weight_iterations=0)
    rows = {}
    s = train(task, cfg, seed=7, callback=lambda i, m: rows.setdefault(i, m))
    key = "deleted_local_optimum"
    checked = {i: m[key] for i, m in rows.items() if key in m}
    K = cfg.iterations_per_expert
    assert sorted(checked) == [K, 2 * K, 3 * K]  # after each expert's K iterations
    assert checked[K] == 0.0  # the first expert has nobody to be compared with
    assert [checked[2 * K], checked[3 * K]] == [float(kept == 1)] * 2
    assert s.model.n_experts == kept and s.iteration == cfg.total_iterations


def test_line_13_is_off_only_for_beer_pong_and_table_tennis():
    """A.2: "For the Beer Pong and Table Tennis task, we have disabled the deletion step"."""
    on = [svsl_config("planar-reacher")] + [
        svsl_config("reacher5-ch3", reward=r) for r in ("3.8", "3.9", "3.10")
    ]
    assert all(c.delete_local_optima and c.local_optimum_factor == 5.0 for c in on)
    assert not svsl_config("beer-pong").delete_local_optima
    assert not svsl_config("table-tennis-ch3").delete_local_optima


@pytest.mark.slow
def test_svsl_learns_the_planar_reacher(task):
    """Test return of the mixture rises well above the initial one (seed 0)."""
    cfg = _tiny(n_experts=2, iterations_per_expert=60, fine_tune_every=20, weight_iterations=0,
                test_every=10)  # fmt: skip
    rows = []
    train(task, cfg, seed=0, callback=lambda i, m: rows.append(m))
    tests = [m["test_return"] for m in rows if "test_return" in m]
    assert tests[-1] > tests[0] + 20, tests


def test_bad_configuration(task):
    with pytest.raises(ValueError, match="no SVSL configuration"):
        svsl_config("cartpole")
    with pytest.raises(ValueError, match="reward"):
        svsl_config("reacher5-ch3", reward="3.7")
    with pytest.raises(ValueError, match="alpha"):
        svsl_config("planar-reacher", alpha=-1.0)
    with pytest.raises(ValueError, match="context_init_cov"):
        SVSL(task, svsl_config("planar-reacher", context_init_cov=(1.0,)), 0)
    with pytest.raises(ValueError, match="buffer_size"):
        svsl_config("planar-reacher", buffer_size=10)
    with pytest.raises(ValueError, match="local_optimum_factor must be a positive number, got 0"):
        svsl_config("planar-reacher", local_optimum_factor=0)


def test_mixture_densities_agree_with_the_dists_mixture():
    """SVSL's batched densities against vslbook.dists.LinearGaussianMoE (torch, Eq. 2.48)."""
    import torch

    from vslbook.erl.svsl_model import MixtureModel

    rng = np.random.default_rng(7)
    m = MixtureModel.empty(2, 3)
    for _ in range(5):
        a = rng.normal(size=(2, 2))
        b = rng.normal(size=(3, 3))
        m.add_expert(rng.normal(size=2), a @ a.T + 0.3 * np.eye(2), rng.normal(size=(3, 2)),
                     rng.normal(size=3), b @ b.T + 0.2 * np.eye(3))  # fmt: skip
    m.log_w = np.log(rng.dirichlet(np.ones(5)))
    m.changed()
    c, th = rng.normal(size=(3000, 2)), rng.normal(size=(3000, 3))
    log_resp, log_gate = m.log_responsibilities(c, th)
    moe = m.moe
    tc, tt = torch.from_numpy(c), torch.from_numpy(th)
    ref_gate = moe.log_gating(tc).numpy()
    joint = moe.expert_log_prob(tt, tc).numpy() + ref_gate
    ref_resp = joint - np.logaddexp.reduce(joint, axis=1, keepdims=True)
    np.testing.assert_allclose(log_gate, ref_gate, rtol=1e-10, atol=1e-10)
    np.testing.assert_allclose(log_resp, ref_resp, rtol=1e-10, atol=1e-10)
    np.testing.assert_allclose(m.log_prob(c, th), moe.log_prob(tt, tc).numpy(), rtol=1e-10)


def test_table_tennis_preset_is_table_a1_and_runs():
    cfg = svsl_config("table-tennis-ch3")
    assert (cfg.alpha, cfg.beta, cfg.beta_w, cfg.n_experts, cfg.iterations_per_expert) == (
        1e-5, 0.2, 0.2, 50, 1000,
    )  # Table A.1 with the authors' K = 1000 (the thesis: 800)  # fmt: skip
    assert (cfg.buffer_size, cfg.new_samples_expert, cfg.new_samples_context) == (567, 226, 8)
    tt = make_task("table-tennis-ch3")
    small = replace(cfg, n_experts=1, iterations_per_expert=1, weight_iterations=0,
                    buffer_size=40, new_samples_expert=8, test_contexts=4)  # fmt: skip
    s = train(tt, small, seed=0)
    assert s.iteration == 1 and s.episodes == 40 + 8 + 8 + 0
    tt.close()
