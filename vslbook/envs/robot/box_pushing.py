"""Box Pushing with Obstacle ("BPO", thesis Section 4.5.1 and Appendix B.4.2.1).

A 7-DoF Franka Panda with a push rod pushes a box (start (0.4, 0.3), yaw π) past an
obstacle to a goal position and orientation on the table. Model: fancy-gym 0.3.0's
``box_pushing.xml`` read from the wheel, with the obstacle added in code
(:mod:`vslbook.envs.robot.box_pushing_model`; the obstacle is a mocap body moved to the
context's position at reset). The authors' environment is Di-SkilL's vendored
``fancy_gym/envs/mujoco/box_pushing/box_pushing_obstacle_env.py``
(``BoxPushingObstacleTemporalSparse``, registered as
``VSLBoxPushingObstacleTemporalSparseProDMP-v0`` in ``diskill/contextual_envs/__init__.py``).

Settings. The authors' code drew Figs. 4.4b and 4.5, so it decides by default
(``settings="code"``); ``settings="thesis"`` gives the text of B.4.2.1 wherever the two
differ. Each difference is also an option of its own, and an explicit option wins over
the settings:

=====================  ==================================  ==================================
option                 ``settings="code"`` (default)       ``settings="thesis"``
=====================  ==================================  ==================================
``goal``               ``"learned"``: 35 parameters        ``"disabled"``: 28 parameters
``reward``             ``"code"``: BoxPushingObstacle-     ``"thesis"``: B.4.2.1's R_tot
                       TemporalSparse's reward
``distance_rule``      ``"y"``: |y_o − y| ≥ 0.15           ``"euclidean"``: ‖o − ·‖ ≥ 0.15
``joint_limit_check``  False: every θ is simulated         True: θ whose q_d leaves the
                                                           joint limits is rejected
=====================  ==================================  ==================================

Context ``c = [x_g, y_g, φ_g, x_o, y_o]`` (the authors' code's order): goal x_g ∈ [0.3, 0.6],
y_g ∈ [−0.7, 0.45], goal yaw φ_g ∈ [0, 2π], obstacle x_o ∈ [0.3, 0.6], y_o ∈ [−0.3, 0.15]
(B.4.2.1, the same box in the code). Rejection rules (:meth:`BoxPushingObstacle.context_valid`):

* ‖g_xy − (0.4, 0.3)‖ > 0.3 (goal at least 0.3 m from the box's start; kept from the
  original task of Otto et al. (2023), as the code does);
* the obstacle at least 0.15 m from the box's start and from the goal:
  ``distance_rule="y"`` (the code's ``reset_model``): in y only, |y_o − 0.3| ≥ 0.15 and
  |y_o − y_g| ≥ 0.15; ``distance_rule="euclidean"`` (B.4.2.1, "a distance of at least
  0.15m"): ‖o − (0.4, 0.3)‖ ≥ 0.15 and ‖o − g_xy‖ ≥ 0.15. |Δy| ≤ ‖Δ‖, so every context the
  y-rule accepts the Euclidean rule accepts too, not the other way round (an obstacle
  beside the goal in x, close in y). The start-distance test holds for every obstacle in
  the box (y_o ≤ 0.15) under both rules; it is checked for the record;
* y_g < y_o: the obstacle lies "between the initial box and the box's goal" (B.4.2.1; the
  start is at y = 0.3 > y_o always), read as the y-ordering the code also uses.

The goal quaternion is the rotation by φ_g about z, (cos φ_g/2, 0, 0, sin φ_g/2) (⚠ the
code's ``rot_to_quat`` gives (sin φ/2, 0, 0, cos φ/2), the yaw π − φ: the same uniform
distribution of goal poses, relabelled; kept under both settings).

Parameters θ: ProDMP (:class:`~vslbook.envs.robot.primitives.ProDMPSpec`) with 4 basis
functions per joint, τ fixed at 1.5, no learned start time, ``weights_scale`` 0.3, basis
auto-scaled, spring constant α = 10, phase decay 3, RBF width = centre spacing / √3 (the
code's bandwidth factor 3). ``goal="learned"`` (the code: ``disable_goal=False``,
``relative_goal=False``, ``goal_scale`` 0.3) gives **35 parameters** in mp_pytorch's
per-joint layout ``[w_1 … w_4, g]`` × 7 with the absolute goal attractor 0.3·g;
``goal="disabled"`` gives B.4.2.1's **28** ("four basis functions per DoF"), the attractor
being the start posture (a 28-parameter θ equals the 35-parameter θ with g_j = q0_j / 0.3).

Timing and control: timestep 0.002 s, 10 substeps per control step (dt 0.02 s), T = 100
steps (2 s). Start posture q0 = [0.387, 0.176, 0.250, −2.399, −0.080, 2.569, 1.480] (rod tip
in the box; the code's ``desired_qpos_robot`` rounded to 1e-3 rad). During step t the PD
law on the normalised action
``a = clip(K_p (q_d[t+1] − q) + K_d (q̇_d[t+1] − q̇), −1, 1)`` with K_p = 0.01·[120, 120, 120,
120, 50, 30, 10], K_d = 0.01·[10, 10, 10, 10, 6, 5, 3] tracks the desired state at the end of
the step; the motor command is ``clip(10 a + qfrc_bias, ±[90, 90, 90, 90, 12, 12, 12])``
(gravity/Coriolis compensation from the state at the start of the step, held for the 10
substeps). The model's motors have gear 1 and ``forcerange`` ±87 / ±12, so MuJoCo clips the
first four joints further to ±87 N m, as in the authors' simulation of the same file.

Reward (:func:`step_reward` for one step, :func:`step_rewards` for all steps of an episode
at once), per step t = 1..T of the state after the step, with the torque τ_t = 10 a_t (the
code's ``action``; B.4.2.1 calls it the "action (torque)"), the joint-limit error
err = Σ(q − q_max)₊ + Σ(q_min − q)₊ + Σ(|q̇| − q̇_max)₊ with the Franka limits
(``box_pushing_utils.py``; the thesis writes |q_i| > |q_i^b|, which for the asymmetric
Franka ranges means these per-side bounds), p the box's position, r its quaternion, h_pos
the rod tip, h_rot the rod's quaternion, h_0 = (0, 1, 0, 0), and the rotation distance
d(a, b) = 2 arccos|a · b|:

* ``reward="code"`` (``BoxPushingObstacleTemporalSparse._get_reward``):
  ``−err − 2 clip(‖p − h_pos‖, 0.05, 100) − 0.02 Σ τ_t² − [d(h_rot, h_0) > π/4] d(h_rot, h_0)/π``;
  at t = T add ``−350 ‖p − p_goal‖ − 100 d(r, r_goal)/π − 50 ‖q̇_T‖``.
* ``reward="thesis"`` (B.4.2.1's R_tot): ``−R_rod − R_rod_rotation − 0.02 Σ τ_t² − err`` with
  R_rod = clip(‖p − h_pos‖, 0.05, 10), R_rod_rotation = clip((2/π) arccos|h_rot · h_0|,
  0.25, 2); at t = T add ``−350 R_goal − 200 R_rotation`` with R_goal = ‖p − p_goal‖ and
  R_rotation = (1/π) arccos|r · r_goal| (the same as the code's −100 d(r, r_goal)/π).

The return is the sum over the T steps. The two differ in the rod–box weight (2, clip at
100, against 1, clip at 10), the rod's tilt and the code's final −50 ‖q̇_T‖ (a push that
ends at rest). The tilt terms agree above π/4: B.4.2.1's (2/π) arccos|h_rot · h_0| is
d(h_rot, h_0)/π, and its lower clip 0.25 is reached exactly at d = π/4, so below π/4 the
thesis charges 0.25 per step where the code charges nothing (its upper clip 2 never binds).

Path (:meth:`~vslbook.envs.robot.task.EpisodicTask.path`): ``box`` (the box body's centre)
and ``rod_tip`` at the start and after every control step, the positions the reward reads.

Success (both): at the end ‖p − p_goal‖ < 0.05 m and the rotation error d(r, r_goal) <
0.5 rad. Info: ``pos_error``, ``rot_error`` (at the end), ``success`` (0/1).

Validity. The code has none: every θ is simulated (``joint_limit_check=False``, the
default). ``joint_limit_check=True`` (``settings="thesis"``; asked of this
re-implementation, the thesis gives no rule): if any desired joint position q_d leaves the
Franka limits the episode is **not simulated** and returns
``−1000 − 1000 (ē_high + ē_low)``, ē the mean excess over all steps and joints
(:func:`~vslbook.envs.robot.primitives.joint_limit_excess`). −1000 lies well below what
standing still earns for any context (at least about −(350·1.02 + 100 + 25 + 5) ≈ −490,
farthest goal, worst orientation) and below the returns of random θ ~ N(0, I) (we saw
−250 to −600), so leaving the limits never pays, and the excess term points back into the
valid region.

Unstable simulation (MuJoCo's bad-acceleration, -velocity or -position warning, or a
non-finite state): every remaining step gets −50 (the code's per-step value) and the
episode stops there (both settings).

``obstacle=False`` builds the scene without the obstacle (fancy-gym 0.3.0's box pushing
scene; the context's x_o, y_o are then only checked, not placed): the step-by-step physics
check against fancy-gym 0.3.0 (``tests/test_box_pushing_reference.py``) runs on it.
"""

from __future__ import annotations

import math
from typing import Any

import mujoco
import numpy as np

from vslbook.envs.robot.box_pushing_model import OBSTACLE_Z, build_model
from vslbook.envs.robot.box_pushing_reward import (
    Q_MAX,
    Q_MIN,
    REWARDS,
    rotation_distance,
    step_reward,
    step_rewards,
)
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
DT, FRAME_SKIP, HORIZON = 0.02, 10, 100
SUCCESS_POS, SUCCESS_ROT = 0.05, 0.5
INVALID_BASE, INVALID_SCALE = -1000.0, 1000.0
UNSTABLE_STEP = -50.0
#: Where the task's choices come from: the authors' environment (default) or B.4.2.1's text.
SETTINGS = ("code", "thesis")
#: How far the obstacle must be from the box's start and the goal: in y (the code) or in
#: the plane (B.4.2.1).
DISTANCE_RULES = ("y", "euclidean")
OBSTACLE_DISTANCE = 0.15
GOAL_START_DISTANCE = 0.3
#: What each setting means for each option.
SETTING_OPTIONS: dict[str, dict[str, Any]] = {
    "code": {"goal": "learned", "reward": "code", "distance_rule": "y",
             "joint_limit_check": False},
    "thesis": {"goal": "disabled", "reward": "thesis", "distance_rule": "euclidean",
               "joint_limit_check": True},
}  # fmt: skip
def goal_quat(phi: float) -> np.ndarray:
    """Unit quaternion (w, x, y, z) of the yaw ``phi`` about the world z-axis."""
    return np.array([math.cos(phi / 2), 0.0, 0.0, math.sin(phi / 2)])


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


def prodmp_spec(goal: str = "learned") -> ProDMPSpec:
    """BPO's ProDMP (Di-SkilL's registration, ``diskill/contextual_envs/__init__.py``): 4 basis
    per joint, alpha 10, τ 1.5, weights and goal scaled by 0.3, auto-scaled basis; ``goal``
    ``"learned"`` (35 parameters, the code: an absolute goal per joint, mp_pytorch's
    ``disable_goal=False``, ``relative_goal=False``) or ``"disabled"`` (28, B.4.2.1)."""
    return ProDMPSpec(
        n_dof=7, n_basis=4, dt=DT, duration=HORIZON * DT, alpha=10.0, alpha_phase=3.0,
        tau=1.5, goal=goal, weights_scale=0.3, goal_scale=0.3, auto_scale_basis=True,
    )  # fmt: skip


def is_success(pos_error: float, rot_error: float) -> bool:
    """B.4.2.1: position error below 0.05 m and rotation error below 0.5 rad at the end."""
    return bool(pos_error < SUCCESS_POS and rot_error < SUCCESS_ROT)


def _choice(name: str, value: Any, default: Any, allowed: tuple[Any, ...]) -> Any:
    """``value`` if given (checked against ``allowed``), else the settings' ``default``."""
    if value is None:
        return default
    if value not in allowed or type(value) is not type(default):
        raise ValueError(
            f"{name} must be one of {', '.join(map(repr, allowed))} (or None: the settings'), "
            f"got {value!r}"
        )
    return value


class BoxPushingObstacle(EpisodicTask):
    """Box Pushing with Obstacle (BPO): see the module docstring for every detail.

    Args:
        settings: ``"code"`` (default): the authors' environment, which made Figs. 4.4b and
            4.5 (35 parameters, its reward, the y-distance rule, every θ simulated);
            ``"thesis"``: B.4.2.1's text (28 parameters, its reward, Euclidean distances,
            θ outside the joint limits rejected before simulation).
        goal: ProDMP goal mode, ``"learned"`` (35 parameters) or ``"disabled"`` (28); None:
            the one of ``settings``.
        reward: ``"code"`` or ``"thesis"`` (see the module docstring); None: the settings'.
        distance_rule: the obstacle's distance to the box's start and the goal, ``"y"`` or
            ``"euclidean"``; None: the settings'.
        joint_limit_check: reject θ whose q_d leaves the Franka limits without simulating;
            None: the settings' (False for the code, True for the thesis).
        obstacle: False builds the scene without the obstacle (the physics check against
            fancy-gym 0.3.0's box pushing; the context's obstacle entries are only checked).
    """

    name = "box-pushing-obstacle"
    context_names = ("x_goal", "y_goal", "phi_goal", "x_obstacle", "y_obstacle")
    context_low = np.array([0.3, -0.7, 0.0, 0.3, -0.3])
    context_high = np.array([0.6, 0.45, 2 * math.pi, 0.6, 0.15])
    n_params = 35
    info_keys = ("pos_error", "rot_error", "success")
    has_success = True
    path_names = ("box", "rod_tip")

    def __init__(
        self, settings: str = "code", goal: str | None = None, reward: str | None = None,
        distance_rule: str | None = None, joint_limit_check: bool | None = None,
        obstacle: bool = True,
    ) -> None:  # fmt: skip
        if settings not in SETTINGS:
            raise ValueError(f"settings must be one of {SETTINGS}, got {settings!r}")
        chosen = SETTING_OPTIONS[settings]
        goal = _choice("goal", goal, chosen["goal"], ("learned", "disabled"))
        reward = _choice("reward", reward, chosen["reward"], REWARDS)
        distance_rule = _choice("distance_rule", distance_rule, chosen["distance_rule"],
                                DISTANCE_RULES)  # fmt: skip
        joint_limit_check = _choice(
            "joint_limit_check", joint_limit_check, chosen["joint_limit_check"], (True, False)
        )
        if not isinstance(obstacle, bool):
            raise TypeError(f"obstacle must be a bool, got {obstacle!r}")
        super().__init__(
            settings=settings, goal=goal, reward=reward, distance_rule=distance_rule,
            joint_limit_check=joint_limit_check, obstacle=obstacle,
        )  # fmt: skip
        #: "code": the authors' environment; "thesis": B.4.2.1's text (module docstring)
        self.settings = settings
        self.reward = reward
        self.distance_rule = distance_rule
        self.joint_limit_check = joint_limit_check
        self.obstacle = obstacle
        self.mp = prodmp_spec(goal)
        self.n_params = self.mp.n_params  # type: ignore[misc]
        self.model = build_model(obstacle=obstacle)
        self.data = mujoco.MjData(self.model)
        m = self.model
        self._box_qpos = m.jnt_qposadr[m.joint("box_joint").id]
        self._box_body = m.body("box_0").id
        self._rod_body = m.body("push_rod").id
        self._rod_tip = m.site("rod_tip").id
        names = ("obstacle", "target_pos", "replan_target_pos") if obstacle else (
            "target_pos", "replan_target_pos")  # fmt: skip
        self._mocap = {n: int(m.body_mocapid[m.body(n).id]) for n in names}
        #: Physics steps taken by this instance (lets tests see that nothing was simulated).
        self.physics_steps = 0

    # -- contexts -----------------------------------------------------------------------
    def context_valid(self, contexts: np.ndarray) -> np.ndarray:
        c = np.asarray(contexts, dtype=np.float64)
        ok = super().context_valid(c)
        g, o = c[..., 0:2], c[..., 3:5]
        start = BOX_START[:2]
        ok &= np.linalg.norm(g - start, axis=-1) > GOAL_START_DISTANCE
        if self.distance_rule == "y":  # the code: |y_o − 0.3| >= 0.15, |y_o − y_g| >= 0.15
            ok &= np.abs(o[..., 1] - start[1]) >= OBSTACLE_DISTANCE
            ok &= np.abs(o[..., 1] - g[..., 1]) >= OBSTACLE_DISTANCE
        else:  # B.4.2.1: Euclidean distances
            ok &= np.linalg.norm(o - start, axis=-1) >= OBSTACLE_DISTANCE
            ok &= np.linalg.norm(o - g, axis=-1) >= OBSTACLE_DISTANCE
        ok &= c[..., 1] < c[..., 4]
        return ok

    def describe_contexts(self) -> str:
        if self.distance_rule == "y":
            rule = "|y_obstacle - 0.3| >= 0.15, |y_obstacle - y_goal| >= 0.15"
        else:
            rule = "|obstacle - (0.4, 0.3)| >= 0.15, |obstacle - goal_xy| >= 0.15"
        return (
            super().describe_contexts()
            + f"; with |goal_xy - (0.4, 0.3)| > 0.3, {rule} and y_goal < y_obstacle"
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
        if self.obstacle:
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
            d.xquat[self._rod_body], d.qpos[:7], d.qvel[:7], torque, final, self.reward,
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
            dqs[:n], torques[:n], final=not broken, variant=self.reward,
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
            f"BoxPushingObstacle(settings={self.settings!r}, goal={self.mp.goal!r}, "
            f"reward={self.reward!r}, distance_rule={self.distance_rule!r}, "
            f"joint_limit_check={self.joint_limit_check}, obstacle={self.obstacle})"
        )
