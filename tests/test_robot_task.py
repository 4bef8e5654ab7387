"""The shared parts of the robot tasks: the episodic interface, the model loader, the ProDMP
with learned duration and start time."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from vslbook.envs.robot.assets import asset_path, load_model, read_xml
from vslbook.envs.robot.primitives import ProDMPSpec, joint_limit_excess
from vslbook.envs.robot.task import Episode, EpisodicEnv, EpisodicTask, resolve_workers
from vslbook.movement import ProDMP


class Parabola(EpisodicTask):
    """A task without a simulator: R = -||θ - c||², valid contexts off the diagonal band."""

    name = "parabola"
    context_names = ("a", "b")
    context_low = np.array([-1.0, -1.0])
    context_high = np.array([1.0, 1.0])
    n_params = 2
    info_keys = ("distance",)
    calls = 0

    def context_valid(self, contexts):
        c = np.asarray(contexts, dtype=float)
        return super().context_valid(c) & (np.abs(c[..., 0] - c[..., 1]) > 0.2)

    def episode(self, theta, context):
        type(self).calls += 1
        if np.any(np.abs(theta) > 5):  # "invalid": penalty, not run
            return Episode(-100.0, False, False, {})
        d = float(np.linalg.norm(theta - context))
        return Episode(-(d**2), d < 0.1, True, {"distance": d})


def test_contexts_are_drawn_from_the_box_with_the_rejection_rule():
    task = Parabola()
    c = task.sample_contexts(500, np.random.default_rng(0))
    assert c.shape == (500, 2)
    assert np.all(np.abs(c) <= 1) and np.all(np.abs(c[:, 0] - c[:, 1]) > 0.2)
    again = task.sample_contexts(500, np.random.default_rng(0))
    np.testing.assert_array_equal(c, again)
    with pytest.raises(ValueError, match="n must be an integer >= 1, got 0"):
        task.sample_contexts(0, np.random.default_rng(0))


def test_evaluate_checks_its_input_and_penalises_only_when_asked():
    task = Parabola()
    with pytest.raises(
        ValueError, match=r"contexts must have shape \(n, 2\) \(a, b\), got shape \(3, 3\)"
    ):
        task.evaluate(np.zeros(2), np.zeros((3, 3)))
    with pytest.raises(ValueError, match=r"context \[0.5, 0.5\] \(row 0\) is outside"):
        task.evaluate(np.zeros(2), [[0.5, 0.5]])
    with pytest.raises(ValueError, match=r"theta must have shape \(n, 2\), got \(4,\)"):
        task.evaluate(np.zeros(4), [[0.5, -0.5]])
    with pytest.raises(ValueError, match="3 parameter vectors for 2 contexts"):
        task.evaluate(np.zeros((3, 2)), [[0.5, -0.5], [0.9, 0.1]])
    with pytest.raises(ValueError, match="out_of_range must be"):
        task.evaluate(np.zeros(2), [[0.5, -0.5]], out_of_range="clip")
    out = task.evaluate(np.zeros(2), [[0.5, -0.5], [2.0, 0.0], [0.3, 0.3]], out_of_range="penalise")
    # (2, 0) is 1 outside the box; (0.3, 0.3) is inside it but rejected: penalty 0 by default
    np.testing.assert_allclose(out.returns, [-0.5, -1.0, 0.0])
    assert out.executed.tolist() == [True, False, False]
    assert np.isnan(out.info["distance"][1])


def test_invalid_parameters_count_as_rejected_not_executed():
    task = Parabola()
    out = task.evaluate([[0.5, -0.5], [9.0, 0.0]], [[0.5, -0.5], [0.9, 0.1]], workers=0)
    assert out.returns.tolist() == [0.0, -100.0]
    assert out.success.tolist() == [True, False]
    assert (out.n_executed, out.n_rejected) == (1, 1)


def test_a_worker_pool_gives_the_numbers_of_one_process():
    task = Parabola()
    rng = np.random.default_rng(1)
    c = task.sample_contexts(37, rng)
    th = rng.normal(size=(37, 2))
    alone = task.evaluate(th, c, workers=0)
    pooled = task.evaluate(th, c, workers=2)
    task.close()
    np.testing.assert_array_equal(alone.returns, pooled.returns)
    np.testing.assert_array_equal(alone.info["distance"], pooled.info["distance"])


def test_worker_count_resolution(monkeypatch):
    monkeypatch.setenv("VSLBOOK_WORKERS", "3")
    assert resolve_workers(None) == 3
    monkeypatch.setenv("VSLBOOK_WORKERS", "many")
    with pytest.raises(ValueError, match="VSLBOOK_WORKERS must be an integer, got 'many'"):
        resolve_workers(None)
    with pytest.raises(ValueError, match="workers must be an integer >= 0, got -1"):
        resolve_workers(-1)


def test_one_step_gymnasium_wrapper():
    from gymnasium.utils.env_checker import check_env

    env = EpisodicEnv(Parabola)
    check_env(env, skip_render_check=True)
    obs, _ = env.reset(seed=0, options={"context": [0.5, -0.5]})
    _, ret, term, trunc, info = env.step(np.array([0.5, -0.5]))
    assert obs.tolist() == [0.5, -0.5] and ret == 0.0 and term and not trunc
    assert info["success"] and info["executed"] and info["distance"] == 0.0


def test_model_files_come_from_the_installed_wheel_and_patches_must_apply():
    path = asset_path("reacher/assets/reacher_5links.xml")
    assert "site-packages" in str(path) and "fancy_gym" in str(path)
    with pytest.raises(FileNotFoundError, match="pip install --no-deps fancy-gym==0.3.0"):
        asset_path("reacher/assets/no_such_model.xml")
    with pytest.raises(ValueError, match="patch target 'not in the file' not found"):
        read_xml("reacher/assets/reacher_5links.xml", [("not in the file", "")])
    # includes are inlined and directories made absolute: the table-tennis model compiles
    xml = read_xml("table_tennis/assets/xml/table_tennis_env.xml")
    assert "<include" not in xml
    model = load_model("table_tennis/assets/xml/table_tennis_env.xml")
    assert model.nu == 7 and model.opt.timestep == pytest.approx(0.002)


def _spec(**kw):
    base = dict(n_dof=2, n_basis=3, dt=0.01, duration=1.0, alpha=25.0, alpha_phase=3.0)
    return ProDMPSpec(**{**base, **kw})


def test_prodmp_parameter_layouts():
    assert _spec(goal="disabled").n_params == 6
    assert _spec(goal="learned").n_params == 8
    assert _spec(tau_bounds=(0.5, 1.5), delay_bounds=(0.0, 0.3), goal="disabled").n_params == 8
    # Table tennis (Ch. 4): 7 joints x 3 basis + tau + delay = 23 (thesis B.4.1)
    tt = ProDMPSpec(
        7, 3, 0.008, 2.8, tau_bounds=(0.56, 1.5), delay_bounds=(0.05, 0.6), goal="disabled"
    )
    assert tt.n_params == 23 and tt.n_steps == 350
    with pytest.raises(ValueError, match="goal must be one of"):
        _spec(goal="free")
    with pytest.raises(ValueError, match=r"theta must have shape \(6,\)"):
        _spec(goal="disabled").trajectory(np.zeros(5), np.zeros(2))


def test_prodmp_trajectory_delay_duration_and_goal():
    spec = _spec(
        tau_bounds=(0.5, 1.5), delay_bounds=(0.0, 0.3), goal="relative", auto_scale_basis=False
    )
    q0 = np.array([0.3, -0.2])
    # mp_pytorch's layout: [tau, delay, per joint [w_1, w_2, w_3, g]]
    theta = np.r_[0.8, 0.2, [1.0, -2.0, 0.5, 0.4], [0.0, 3.0, 1.0, -0.1]]
    q, dq = spec.trajectory(theta, q0)
    assert q.shape == dq.shape == (101, 2)
    np.testing.assert_allclose(q[:21], np.repeat(q0[None], 21, axis=0))  # held until t = 0.2
    np.testing.assert_allclose(dq[:21], 0.0)
    # after the delay: the library ProDMP with tau 0.8 (basis grid built for the spec's tau,
    # 1.0) over the remaining 0.8 s, goal q0 + g
    dmp = ProDMP(3, 2, duration=0.8, dt=0.01, alpha=25.0, tau=0.8, alpha_x=3.0, basis_tau=1.0)
    blocks = theta[2:].reshape(2, 4)
    params = np.concatenate([blocks[:, :3], (q0 + blocks[:, 3])[:, None]], axis=1).reshape(-1)
    ref, dref = dmp.trajectory(torch.from_numpy(params), torch.from_numpy(q0), torch.zeros(2))
    np.testing.assert_allclose(q[20:], ref.numpy(), atol=1e-12)
    np.testing.assert_allclose(dq[20:], dref.numpy(), atol=1e-12)
    # the delay is continuous (not rounded to the grid): 0.2049 s starts within step 20..21
    late = theta.copy()
    late[1] = 0.2049
    q_late, _ = spec.trajectory(late, q0)
    np.testing.assert_allclose(q_late[:21], q[:21])
    assert 0 < np.abs(q_late[21:] - q[21:]).max() < np.abs(q[21:] - q0).max()
    dmp_late = ProDMP(
        3, 2, duration=1.0, dt=0.01, alpha=25.0, tau=0.8, alpha_x=3.0, delay=0.2049,
        basis_tau=1.0, relative_goal=True,
    )  # fmt: skip
    want, _ = dmp_late.trajectory_numpy(theta[2:], q0, np.zeros(2))
    np.testing.assert_allclose(q_late, want, atol=1e-12)
    with pytest.raises(ValueError, match=r"dq0 must be zero when the start is delayed"):
        spec.trajectory(theta, q0, np.ones(2))
    # out-of-bounds tau / delay: clipped for the trajectory, reported by bound_excess
    wild = theta.copy()
    wild[0], wild[1] = 2.0, -0.1
    assert spec.bound_excess(wild) == pytest.approx((0.5, 0.1))
    q_clip, _ = spec.trajectory(wild, q0)
    clipped = theta.copy()
    clipped[0], clipped[1] = 1.5, 0.0
    np.testing.assert_allclose(q_clip, spec.trajectory(clipped, q0)[0])


def test_auto_scaled_basis_peaks_at_the_weight():
    spec = _spec(n_dof=1, n_basis=4, goal="disabled", weights_scale=0.5)
    for i in range(4):
        theta = np.zeros(4)
        theta[i] = 1.0
        q, _ = spec.trajectory(theta, np.zeros(1))
        # each scaled basis function peaks at weights_scale (here 0.5) in absolute value
        # of its particular solution; with y0 = 0 the homogeneous part only removes
        # the initial offset, so the peak is at most that.
        assert np.max(np.abs(q)) <= 0.5 + 1e-9
        assert np.max(np.abs(q)) > 0.05


def test_joint_limit_excess():
    q = np.array([[0.0, 2.0], [1.0, -3.0]])
    hi, lo = joint_limit_excess(q, low=np.array([-1.0, -1.0]), high=np.array([0.5, 1.0]))
    assert hi == pytest.approx((0.0 + 1.0 + 0.5 + 0.0) / 4)
    assert lo == pytest.approx((0.0 + 0.0 + 0.0 + 2.0) / 4)


def test_every_task_is_registered_under_its_name_with_a_gymnasium_id():
    import gymnasium as gym

    from vslbook.envs.robot import STEP_IDS, TASKS, make_task, task_class

    for name, (_, env_id) in TASKS.items():
        cls = task_class(name)
        assert cls.name == name and env_id in gym.registry
        assert len(cls.context_names) == len(cls.context_low) == len(cls.context_high)
    assert all(env_id in gym.registry for env_id in STEP_IDS)
    with pytest.raises(ValueError, match="unknown task 'beer-pog'; did you mean beer-pong"):
        make_task("beer-pog")
    # a misspelt option is an error naming it and the options the task has, not ignored
    with pytest.raises(ValueError, match="PlanarReacherTask has no option 'exclude_base_jiont'; "
                       "expected some of exclude_base_joint"):  # fmt: skip
        make_task("planar-reacher", exclude_base_jiont=True)
    assert make_task("planar-reacher", exclude_base_joint=True)._kwargs == {
        "exclude_base_joint": True
    }


def test_the_one_step_env_leaves_numbers_that_do_not_apply_out_of_its_info():
    class Sometimes(Parabola):
        def episode(self, theta, context):
            return Episode(0.0, False, True, {"distance": float("nan")})

    env = EpisodicEnv(Sometimes)
    env.reset(seed=0)
    _, _, _, _, info = env.step(np.zeros(2))
    assert "distance" not in info and info["executed"]


def test_robot_ids_are_known_to_vslbook_make():
    """`vslbook.envs.make` (and so `vslbook run`) finds the robot tasks without the caller
    importing vslbook.envs.robot first; the check runs in a fresh interpreter."""
    import subprocess
    import sys

    code = (
        "import vslbook.envs as E, sys\n"
        "assert 'vslbook.envs.robot' not in sys.modules\n"
        "E.check_env_id('vslbook/MiniGolf-v0')\n"
        "env = E.make('vslbook/BoxPushingObstacleStep-v0')\n"
        "print(env.observation_space.shape)\n"
        "try:\n"
        "    E.check_env_id('vslbook/MiniGolff-v0')\n"
        "except ValueError as e:\n"
        "    assert 'vslbook/MiniGolf-v0' in str(e), e\n"
        "else:\n"
        "    raise SystemExit('a misspelt id was accepted')\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         timeout=120)
    assert out.returncode == 0, out.stderr[-2000:]
    assert out.stdout.strip() == "(30,)"
