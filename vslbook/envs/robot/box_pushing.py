"""Box Pushing with Obstacle ("BPO", thesis Section 4.5.1 and Appendix B.4.2.1).

A 7-DoF Franka Panda with a push rod pushes a box (start (0.4, 0.3), yaw π) past an
obstacle to a goal position and orientation on the table. Model: fancy-gym 0.3.0's
``box_pushing.xml`` read from the wheel, with the obstacle added in code
(:mod:`vslbook.envs.robot.box_pushing_model`; the obstacle is a mocap body moved to the
context's position at reset).

Context ``c = [x_g, y_g, φ_g, x_o, y_o]`` (the authors' code's order): goal x_g ∈ [0.3, 0.6],
y_g ∈ [−0.7, 0.45], goal yaw φ_g ∈ [0, 2π], obstacle x_o ∈ [0.3, 0.6], y_o ∈ [−0.3, 0.15]
(B.4.2.1). Rejection rules (:meth:`BoxPushingObstacle.context_valid`):

* ‖g_xy − (0.4, 0.3)‖ > 0.3 (goal at least 0.3 m from the box's start; kept from the
  original task of Otto et al. (2023) as the authors' code does);
* ‖o − (0.4, 0.3)‖ ≥ 0.15 and ‖o − g_xy‖ ≥ 0.15: **the thesis's Euclidean distances**
  (⚠ the authors' code checks only the y-distances |y_o − 0.3| and |y_o − y_g|); the first
  holds for every obstacle in the box (y_o ≤ 0.15), it is checked for the record;
* y_g < y_o: the obstacle lies "between the initial box and the box's goal" (B.4.2.1; the
  start is at y = 0.3 > y_o always), read as the y-ordering the code also uses.

The goal quaternion is the rotation by φ_g about z, (cos φ_g/2, 0, 0, sin φ_g/2) (⚠ the
code's ``rot_to_quat`` gives (sin φ/2, 0, 0, cos φ/2), the yaw π − φ: the same uniform
distribution of goal poses, relabelled).

Parameters θ: ProDMP (:class:`~vslbook.envs.robot.primitives.ProDMPSpec`) with 4 basis
functions per joint, τ fixed at 1.5, no learned start time, ``weights_scale`` 0.3, basis
auto-scaled, spring constant α = 10, phase decay 3, RBF width = centre spacing / √3 (the
code's bandwidth factor 3). The thesis counts **28 parameters** (B.4.2.1), i.e. the goal
attractor is the start posture (``goal="disabled"``, the default here); ``goal="learned"``
gives the code's **35** (absolute goal per joint, ``goal_scale`` 0.3).

Timing and control: timestep 0.002 s, 10 substeps per control step (dt 0.02 s), T = 100
steps (2 s). Start posture q0 = [0.387, 0.176, 0.250, −2.399, −0.080, 2.569, 1.480] (rod tip
in the box). During step t the PD law on the normalised action
``a = clip(K_p (q_d[t+1] − q) + K_d (q̇_d[t+1] − q̇), −1, 1)`` with K_p = 0.01·[120, 120, 120,
120, 50, 30, 10], K_d = 0.01·[10, 10, 10, 10, 6, 5, 3] tracks the desired state at the end of
the step; the motor command is ``clip(10 a + qfrc_bias, ±[90, 90, 90, 90, 12, 12, 12])``
(gravity/Coriolis compensation from the state at the start of the step, held for the 10
substeps). The model's motors have gear 1 and ``forcerange`` ±87 / ±12, so MuJoCo clips the
first four joints further to ±87 N m, as in the authors' simulation of the same file.

Reward (B.4.2.1, time-sparse; :func:`step_reward` for one step, :func:`step_rewards` for all
steps of an episode at once), per step t ≤ T:
``−R_rod − R_rod_rotation − 0.02 τ_t − err(q, q̇)`` with R_rod = clip(‖p − h_pos‖, 0.05, 10)
(box to rod tip), R_rod_rotation = clip((2/π) arccos|h_rot · (0, 1, 0, 0)|, 0.25, 2),
τ_t = Σ_i (10 a_i)² (the thesis calls it the "action (torque)" cost; the torque is 10 a,
as in the code), err = Σ(q − q_max)₊ + Σ(q_min − q)₊ + Σ(|q̇| − q̇_max)₊ with the Franka
limits (the thesis writes |q_i| > |q_i^b|, which for the asymmetric Franka ranges means
the per-side bounds used here). At t = T add ``−350 R_goal − 200 R_rotation`` with
R_goal = ‖p − p_goal‖ and R_rotation = (1/π) arccos|r · r_goal|. The return is the sum.
⚠ Followed the thesis over the code: the code weighs R_rod by 2 (clip at 100), gives no
rod-rotation cost below π/4 tilt (the thesis's clip at 0.25 costs 0.25 per step there) and
adds −50‖q̇_T‖ at the end.

Path (:meth:`~vslbook.envs.robot.task.EpisodicTask.path`): ``box`` (the box body's centre)
and ``rod_tip`` at the start and after every control step, the positions the reward reads.

Success: at the end ‖p − p_goal‖ < 0.05 m and the rotation error 2 arccos|r · r_goal| <
0.5 rad. Info: ``pos_error``, ``rot_error`` (at the end), ``success`` (0/1).

Validity (asked of this re-implementation; the authors' BPO has none): if any desired
joint position q_d leaves the Franka limits the episode is **not simulated** and returns
``−1000 − 1000 (ē_high + ē_low)``, ē the mean excess over all steps and joints
(:func:`~vslbook.envs.robot.primitives.joint_limit_excess`). −1000 lies well below what
standing still earns for any context (at least about −(350·1.02 + 100 + 25 + 5) ≈ −490,
farthest goal, worst orientation) and below the returns of random θ ~ N(0, I) (we saw
−250 to −600), so leaving the limits never pays, and the
excess term points back into the valid region. ``joint_limit_check=False`` simulates
every θ as the authors' code does.

Unstable simulation (MuJoCo's bad-acceleration, -velocity or -position warning, or a
non-finite state): every
remaining step gets −50 (the code's per-step value) and the episode stops there.
"""

from __future__ import annotations

import math
from typing import Any

import mujoco
import numpy as np

from vslbook.envs.robot.box_pushing_model import OBSTACLE_Z, build_model
from vslbook.envs.robot.primitives import ProDMPSpec, joint_limit_excess
from vslbook.envs.robot.task import Episode, EpisodicTask

Q0 = np.array([0.387, 0.176, 0.250, -2.399, -0.080, 2.569, 1.480])
BOX_START = np.array([0.4, 0.3, -0.01])
BOX_START_QUAT = np.array([0.0, 0.0, 0.0, 1.0])  # (w, x, y, z): yaw π
GOAL_Z = -0.01
P_GAINS = 0.01 * np.array([120.0, 120.0, 120.0, 120.0, 50.0, 30.0, 10.0])
D_GAINS = 0.01 * np.array([10.0, 10.0, 10.0, 10.0, 6.0, 5.0, 3.0])
TORQUE_MAX = np.array([90.0, 90.0, 90.0, 90.0, 12.0, 12.0, 12.0])
ACTION_SCALE = 10.0
Q_MAX = np.array([2.8973, 1.7628, 2.8973, -0.0698, 2.8973, 3.7525, 2.8973])
Q_MIN = np.array([-2.8973, -1.7628, -2.8973, -3.0718, -2.8973, -0.0175, -2.8973])
QD_MAX = np.array([2.175, 2.175, 2.175, 2.175, 2.61, 2.61, 2.61])
ROD_QUAT_DESIRED = np.array([0.0, 1.0, 0.0, 0.0])
DT, FRAME_SKIP, HORIZON = 0.02, 10, 100
SUCCESS_POS, SUCCESS_ROT = 0.05, 0.5
INVALID_BASE, INVALID_SCALE = -1000.0, 1000.0
UNSTABLE_STEP = -50.0


def rotation_distance(p: np.ndarray, q: np.ndarray) -> float:
    """Angle (rad, in [0, π]) of the rotation between unit quaternions ``p`` and ``q``."""
    return 2.0 * math.acos(min(abs(float(np.dot(p, q))), 1.0))


def goal_quat(phi: float) -> np.ndarray:
    """Unit quaternion (w, x, y, z) of the yaw ``phi`` about the world z-axis."""
    return np.array([math.cos(phi / 2), 0.0, 0.0, math.sin(phi / 2)])


def step_reward(
    box_pos: np.ndarray, box_quat: np.ndarray, goal_pos: np.ndarray, goal_quat: np.ndarray,
    rod_tip: np.ndarray, rod_quat: np.ndarray, q: np.ndarray, dq: np.ndarray,
    torque: np.ndarray, final: bool,
) -> float:  # fmt: skip
    """One step's reward of B.4.2.1 (see the module docstring); ``final`` adds the goal terms.

    ``torque`` is the commanded torque 10 a (without the bias compensation). The plain
    reading of the formula: the step-based environment's reward, and the reference the tests
    hold :func:`step_rewards` (what the episodes use) to.
    """
    r_rod = float(np.clip(np.linalg.norm(box_pos - rod_tip), 0.05, 10.0))
    cos_rod = min(abs(float(np.dot(rod_quat, ROD_QUAT_DESIRED))), 1.0)
    r_rod_rot = float(np.clip(2.0 / math.pi * math.acos(cos_rod), 0.25, 2.0))
    err = float(
        np.sum(np.maximum(q - Q_MAX, 0.0))
        + np.sum(np.maximum(Q_MIN - q, 0.0))
        + np.sum(np.maximum(np.abs(dq) - QD_MAX, 0.0))
    )
    r = -r_rod - r_rod_rot - 0.02 * float(np.sum(np.square(torque))) - err
    if final:
        r_goal = float(np.linalg.norm(box_pos - goal_pos))
        r_rot = math.acos(min(abs(float(np.dot(box_quat, goal_quat))), 1.0)) / math.pi
        r += -350.0 * r_goal - 200.0 * r_rot
    return r


def step_rewards(
    box_pos: np.ndarray, box_quat: np.ndarray, goal_pos: np.ndarray, goal_quat: np.ndarray,
    rod_tip: np.ndarray, rod_quat: np.ndarray, q: np.ndarray, dq: np.ndarray,
    torque: np.ndarray, final: bool,
) -> np.ndarray:  # fmt: skip
    """:func:`step_reward` of T steps at once: row t of every ``(T, ·)`` argument is step t's
    state (positions ``(T, 3)``, quaternions ``(T, 4)``, ``q``, ``dq``, ``torque`` ``(T, 7)``);
    ``goal_pos`` (3,) and ``goal_quat`` (4,) are the context's. ``final`` adds the goal terms
    to the last row. Returns the T rewards; the same numbers as :func:`step_reward` row by
    row, up to rounding (one numpy expression per term instead of one call per step).
    """
    n = len(torque)
    for name, a, width in (
        ("box_pos", box_pos, 3), ("box_quat", box_quat, 4), ("rod_tip", rod_tip, 3),
        ("rod_quat", rod_quat, 4), ("q", q, 7), ("dq", dq, 7), ("torque", torque, 7),
    ):  # fmt: skip
        if a.shape != (n, width):
            raise ValueError(f"{name} must have shape ({n}, {width}) (T steps), got {a.shape}")
    if np.shape(goal_pos) != (3,) or np.shape(goal_quat) != (4,):
        raise ValueError(
            f"goal_pos and goal_quat must have shapes (3,) and (4,), got "
            f"{np.shape(goal_pos)} and {np.shape(goal_quat)}"
        )
    # R_rod = clip(‖p − h_pos‖, 0.05, 10), R_rod_rotation = clip((2/π) arccos|h_rot · (0,1,0,0)|,
    # 0.25, 2), τ_t = Σ (10 a)², err = Σ(q − q_max)₊ + Σ(q_min − q)₊ + Σ(|q̇| − q̇_max)₊
    r_rod = np.clip(np.linalg.norm(box_pos - rod_tip, axis=1), 0.05, 10.0)
    cos_rod = np.minimum(np.abs(rod_quat @ ROD_QUAT_DESIRED), 1.0)
    r_rod_rot = np.clip(2.0 / math.pi * np.arccos(cos_rod), 0.25, 2.0)
    err = (
        np.sum(np.maximum(q - Q_MAX, 0.0), axis=1)
        + np.sum(np.maximum(Q_MIN - q, 0.0), axis=1)
        + np.sum(np.maximum(np.abs(dq) - QD_MAX, 0.0), axis=1)
    )
    r = -r_rod - r_rod_rot - 0.02 * np.sum(np.square(torque), axis=1) - err
    if final and n > 0:  # −350 R_goal − 200 R_rotation at t = T
        r_goal = float(np.linalg.norm(box_pos[-1] - goal_pos))
        r_rot = math.acos(min(abs(float(np.dot(box_quat[-1], goal_quat))), 1.0)) / math.pi
        r[-1] += -350.0 * r_goal - 200.0 * r_rot
    return r


_BAD_STATE = (
    mujoco.mjtWarning.mjWARN_BADQACC,
    mujoco.mjtWarning.mjWARN_BADQVEL,
    mujoco.mjtWarning.mjWARN_BADQPOS,
)


def apply_torque(m: mujoco.MjModel, d: mujoco.MjData, action: np.ndarray) -> np.ndarray:
    """One control step of the Panda: the normalised ``action`` (clipped to [-1, 1]) becomes
    the torque ``10 a`` plus gravity/Coriolis compensation, clipped to the motor limits, held
    for ``FRAME_SKIP`` physics steps. Returns ``10 a`` (what the action cost is taken of)."""
    torque = ACTION_SCALE * np.clip(action, -1.0, 1.0)
    d.ctrl[:] = np.clip(torque + d.qfrc_bias[:7], -TORQUE_MAX, TORQUE_MAX)
    mujoco.mj_step(m, d, nstep=FRAME_SKIP)
    return torque


def unstable(d: mujoco.MjData) -> bool:
    """Whether the simulation broke down: MuJoCo warned of a bad acceleration, velocity or
    position (it then resets the state to the model's default silently), or the state is
    not finite."""
    return any(d.warning[w].number > 0 for w in _BAD_STATE) or not bool(np.all(np.isfinite(d.qpos)))


def prodmp_spec(goal: str = "disabled") -> ProDMPSpec:
    """BPO's ProDMP (Di-SkilL's registration): 4 basis per joint, alpha 10, τ 1.5, weights and
    goal scaled by 0.3, auto-scaled basis; ``goal`` ``"disabled"`` (28 parameters, thesis) or
    ``"learned"`` (35, the code: an absolute goal, mp_pytorch's ``relative_goal=False``)."""
    return ProDMPSpec(
        n_dof=7, n_basis=4, dt=DT, duration=HORIZON * DT, alpha=10.0, alpha_phase=3.0,
        tau=1.5, goal=goal, weights_scale=0.3, goal_scale=0.3, auto_scale_basis=True,
    )  # fmt: skip


def is_success(pos_error: float, rot_error: float) -> bool:
    """B.4.2.1: position error below 0.05 m and rotation error below 0.5 rad at the end."""
    return bool(pos_error < SUCCESS_POS and rot_error < SUCCESS_ROT)


class BoxPushingObstacle(EpisodicTask):
    """Box Pushing with Obstacle (BPO): see the module docstring for every detail.

    Args:
        goal: ProDMP goal mode, ``"disabled"`` (thesis, 28 parameters) or ``"learned"``
            (authors' code, 35 parameters).
        joint_limit_check: reject θ whose q_d leaves the Franka limits without simulating.
    """

    name = "box-pushing-obstacle"
    context_names = ("x_goal", "y_goal", "phi_goal", "x_obstacle", "y_obstacle")
    context_low = np.array([0.3, -0.7, 0.0, 0.3, -0.3])
    context_high = np.array([0.6, 0.45, 2 * math.pi, 0.6, 0.15])
    n_params = 28
    info_keys = ("pos_error", "rot_error", "success")
    has_success = True
    path_names = ("box", "rod_tip")

    def __init__(self, goal: str = "disabled", joint_limit_check: bool = True) -> None:
        if goal not in ("disabled", "learned"):
            raise ValueError(f"goal must be 'disabled' (28 params) or 'learned' (35), got {goal!r}")
        super().__init__(goal=goal, joint_limit_check=joint_limit_check)
        self.mp = prodmp_spec(goal)
        self.n_params = self.mp.n_params  # type: ignore[misc]
        self.joint_limit_check = bool(joint_limit_check)
        self.model = build_model()
        self.data = mujoco.MjData(self.model)
        m = self.model
        self._box_qpos = m.jnt_qposadr[m.joint("box_joint").id]
        self._box_body = m.body("box_0").id
        self._rod_body = m.body("push_rod").id
        self._rod_tip = m.site("rod_tip").id
        self._mocap = {
            n: int(m.body_mocapid[m.body(n).id])
            for n in ("obstacle", "target_pos", "replan_target_pos")
        }
        #: Physics steps taken by this instance (lets tests see that nothing was simulated).
        self.physics_steps = 0

    # -- contexts -----------------------------------------------------------------------
    def context_valid(self, contexts: np.ndarray) -> np.ndarray:
        c = np.asarray(contexts, dtype=np.float64)
        ok = super().context_valid(c)
        g, o = c[..., 0:2], c[..., 3:5]
        start = BOX_START[:2]
        ok &= np.linalg.norm(g - start, axis=-1) > 0.3
        ok &= np.linalg.norm(o - start, axis=-1) >= 0.15
        ok &= np.linalg.norm(o - g, axis=-1) >= 0.15
        ok &= c[..., 1] < c[..., 4]
        return ok

    def describe_contexts(self) -> str:
        return (
            super().describe_contexts()
            + "; with |goal_xy - (0.4, 0.3)| > 0.3, |obstacle - (0.4, 0.3)| >= 0.15, "
            "|obstacle - goal_xy| >= 0.15 and y_goal < y_obstacle"
        )

    # -- simulation ---------------------------------------------------------------------
    def scene(self, context: Any) -> tuple[mujoco.MjModel, mujoco.MjData]:
        """The simulator at the start of an episode in ``context`` (see the base class)."""
        self.reset(self.one_context(context))
        return self.model, self.data

    def reset(self, context: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Put robot, box, goal and obstacle at their start; returns (goal pos, goal quat)."""
        m, d = self.model, self.data
        mujoco.mj_resetData(m, d)
        d.qpos[:7] = Q0
        d.qpos[self._box_qpos : self._box_qpos + 3] = BOX_START
        d.qpos[self._box_qpos + 3 : self._box_qpos + 7] = BOX_START_QUAT
        gpos = np.array([context[0], context[1], GOAL_Z])
        gquat = goal_quat(float(context[2]))
        for name in ("target_pos", "replan_target_pos"):
            d.mocap_pos[self._mocap[name]] = gpos
            d.mocap_quat[self._mocap[name]] = gquat
        d.mocap_pos[self._mocap["obstacle"]] = [context[3], context[4], OBSTACLE_Z]
        d.mocap_quat[self._mocap["obstacle"]] = [1.0, 0.0, 0.0, 0.0]
        mujoco.mj_forward(m, d)
        return gpos, gquat

    def state_reward(
        self, goal_pos: np.ndarray, goal_q: np.ndarray, torque: np.ndarray, final: bool
    ) -> tuple[float, float, float]:
        """Reward of the current simulator state, with the final position/rotation errors."""
        d = self.data
        box_pos, box_quat = d.xpos[self._box_body].copy(), d.xquat[self._box_body].copy()
        r = step_reward(
            box_pos, box_quat, goal_pos, goal_q, d.site_xpos[self._rod_tip],
            d.xquat[self._rod_body], d.qpos[:7], d.qvel[:7], torque, final,
        )  # fmt: skip
        return r, float(np.linalg.norm(box_pos - goal_pos)), rotation_distance(box_quat, goal_q)

    def episode(self, theta: np.ndarray, context: np.ndarray) -> Episode:
        theta = np.asarray(theta, dtype=np.float64)
        context = np.asarray(context, dtype=np.float64)
        q_d, dq_d = self.mp.trajectory(theta, Q0)
        if self.joint_limit_check:
            hi, lo = joint_limit_excess(q_d[1:], Q_MIN, Q_MAX)  # the tracked rows
            if hi > 0.0 or lo > 0.0:
                pen = INVALID_BASE - INVALID_SCALE * (hi + lo)
                nan = math.nan
                return Episode(
                    pen, False, False, {"pos_error": nan, "rot_error": nan, "success": 0.0}
                )
        m, d = self.model, self.data
        gpos, gquat = self.reset(context)
        # The loop only controls, steps, checks for a breakdown and copies what the reward
        # reads (the state after each control step) into these arrays; the rewards of all
        # steps follow at once (step_rewards). Views into MjData (its buffers never move):
        qpos, q, dq, bias, ctrl = d.qpos, d.qpos[:7], d.qvel[:7], d.qfrc_bias[:7], d.ctrl
        box_x, box_r = d.xpos[self._box_body], d.xquat[self._box_body]
        tip_x, rod_r = d.site_xpos[self._rod_tip], d.xquat[self._rod_body]
        box_pos, box_quat = np.empty((HORIZON, 3)), np.empty((HORIZON, 4))
        tip_pos, rod_quat = np.empty((HORIZON, 3)), np.empty((HORIZON, 4))
        qs, dqs, torques = np.empty((HORIZON, 7)), np.empty((HORIZON, 7)), np.empty((HORIZON, 7))
        warnings = d.warning.number
        w_pos, w_vel, w_acc = (int(w) for w in _BAD_STATE)
        e, f, neg_max = np.empty(7), np.empty(7), -TORQUE_MAX
        sub, mul, add, mx, mn = np.subtract, np.multiply, np.add, np.maximum, np.minimum
        dot, step = qpos.dot, mujoco.mj_step
        path = self._recorder
        if path is not None:
            path(box=box_x, rod_tip=tip_x)
        n, broken = HORIZON, False  # n: steps whose state and reward count
        for t in range(HORIZON):
            # a = clip(K_p (q_d − q) + K_d (q̇_d − q̇), −1, 1), torque 10 a,
            # ctrl = clip(10 a + bias, ±limit) (apply_torque, in place)
            mul(P_GAINS, sub(q_d[t + 1], q, e), e)
            mul(D_GAINS, sub(dq_d[t + 1], dq, f), f)
            mn(mx(add(e, f, e), -1.0, out=e), 1.0, out=e)
            tq = torques[t]
            mul(ACTION_SCALE, e, tq)
            mn(mx(add(tq, bias, ctrl), neg_max, out=ctrl), TORQUE_MAX, out=ctrl)
            step(m, d, FRAME_SKIP)
            # unstable(d): a MuJoCo warning, or a non-finite qpos (q·q is finite unless an
            # entry is not, or the sum overflows, which the exact test then clears)
            v = dot(qpos)
            if (
                warnings[w_pos] > 0 or warnings[w_vel] > 0 or warnings[w_acc] > 0
                or (v - v != 0.0 and not np.all(np.isfinite(qpos)))
            ):  # fmt: skip
                n, broken = t, True
                break
            box_pos[t], box_quat[t], tip_pos[t], rod_quat[t] = box_x, box_r, tip_x, rod_r
            qs[t], dqs[t] = q, dq
            if path is not None:
                path(box=box_x, rod_tip=tip_x)
        self.physics_steps += FRAME_SKIP * (n + broken)  # the breaking step was taken too
        rewards = step_rewards(
            box_pos[:n], box_quat[:n], gpos, gquat, tip_pos[:n], rod_quat[:n], qs[:n],
            dqs[:n], torques[:n], final=not broken,
        )  # fmt: skip
        ret = float(np.sum(rewards))
        if broken:  # −50 for every remaining step, the breaking one included
            ret += UNSTABLE_STEP * (HORIZON - n)
            pos_err = rot_err = math.nan
        else:
            pos_err = float(np.linalg.norm(box_pos[-1] - gpos))
            rot_err = rotation_distance(box_quat[-1], gquat)
        success = is_success(pos_err, rot_err)
        info = {"pos_error": pos_err, "rot_error": rot_err, "success": float(success)}
        return Episode(ret, success, True, info)

    def __repr__(self) -> str:
        return (
            f"BoxPushingObstacle(goal={self.mp.goal!r}, joint_limit_check={self.joint_limit_check})"
        )
