"""Robot Mini Golf ("MG", thesis Section 4.5.1 and Appendix B.4.4).

A 7-DoF Franka Panda holding a club (the push rod with a club head) has to hit a ball so
that it rolls past a moving and a static obstacle through a tight goal: two walls on the
line y = −0.7 leave a 5.6 cm gap for the 5 cm ball. Model: built in code on fancy-gym
0.3.0's Panda with push rod (:mod:`vslbook.envs.robot.mini_golf_model`, where every body,
size and contact parameter is listed).

Context ``c = [x_obs, y_obs, x_ball, x_goal]`` (the authors' code's order): the moving
(green) obstacle's position x_obs ∈ [0.3, 0.6], y_obs ∈ [−0.5, −0.1], the ball's start
x_ball ∈ [0.25, 0.6] (it starts at (x_ball, 0.5, 0.005)) and the centre of the goal gap
x_goal ∈ [0.18, 0.67], the authors' range, which made Fig. 4.4d (the channel between the
side walls spans x ∈ [0.155, 0.695]); uniform, no rejection. ``settings="thesis"`` takes
B.4.4's x_goal ∈ [0.25, 0.6].

Parameters θ (29, B.4.4): ``[τ, w (7 joints × 4 basis, joint-major)]``, a ProDMP
(:class:`~vslbook.envs.robot.primitives.ProDMPSpec`) with learned duration τ ∈ [0.45, 1.7] s,
no learned start time, goal disabled (the attractor is the start posture), ``weights_scale``
0.3, basis auto-scaled, spring constant α = 25, phase decay 3, RBF width = centre spacing /
√3 (the code's bandwidth factor 3). The robot always starts at rest at q0 = [0.901, 0.949,
0.152, −1.055, −0.136, 1.995, 1.826] (the club head 0.15 m behind the ball's start line).

Validity (before simulation, B.4.4 and the authors' code): θ is invalid if τ lies outside
[0.45, 1.7] or any desired joint position q_d leaves the Franka limits. An invalid θ is not
simulated (``executed=False``, not counted as a sample) and returns
``−20 (3 Δτ + ē_high + ē_low) − 5`` with Δτ the distance of τ to its bounds and ē the mean
excess of q_d over the upper / under the lower limits over all steps and joints
(:func:`~vslbook.envs.robot.primitives.joint_limit_excess`). This is the authors' code; the
thesis writes ``−20 (r_traj + r_dur) − 5`` with r_dur = −3 Δτ and r_traj the *sum* of
|q_d| − |q_b| over entries whose magnitude exceeds the *upper* bound, whose signs do not
combine into a penalty and which is no joint-limit test for the asymmetric Franka ranges;
the code's form is the consistent reading of it.

Timing and control (as Box Pushing, :mod:`vslbook.envs.robot.box_pushing`): timestep
0.002 s, 10 substeps per control step (dt 0.02 s), T = 100 steps (2 s). During step t the
PD law on the normalised action ``a = clip(K_p (q_d[t+1] − q) + K_d (q̇_d[t+1] − q̇), −1, 1)``
with K_p = 0.01·[120, 120, 120, 120, 50, 30, 10], K_d = 0.01·[10, 10, 10, 10, 6, 5, 3] gives
the motor command ``clip(10 a + qfrc_bias, ±[90, 90, 90, 90, 12, 12, 12])``, held for the 10
substeps.

Events, checked after every substep: **hit**: a contact between the ball and the club
(``rod_contact`` or ``rod_contact2``); **passed**: after the hit, y_ball − 0.025 < −0.75,
i.e. the ball's centre lies more than 2.5 cm behind the goal line (the margin covers MuJoCo's
soft contacts, which may let a ball sink into a wall for a moment). The ball can only
cross the line through the gap: the goal walls close the channel between the side walls and
a ceiling closes the goal line above z = 0.1.

Reward (B.4.4, :func:`step_cost` and :func:`final_reward`): every step t < T costs
``−0.0005 τ_t`` with τ_t = Σ_i (10 a_i)² (the commanded torque without the bias
compensation). The last step instead gives, with minima over all substeps of the episode,

* no hit: ``0.2 − 0.2 tanh(min ‖p_rod_tip − p_ball‖)``;
* hit, not passed (the authors' code, the default ``reward="code"``):
  ``2 − 2 tanh(min ‖p_ball − p_goal‖) + 0.5 (1 − tanh(min y_ball + 0.75))``,
  p_goal the site ``ball_target`` at (x_goal, −0.7, 0.005);
* hit and passed: ``6``.

The return is the sum. ⚠ B.4.4 prints the third case as
``2 − 2 tanh(min ‖p_b − p_g‖) − tanh(‖p_b,y − p_thresh,y‖)`` (``reward="thesis"``; it does
not say at which time p_b,y enters, the minimum over the episode is used as in the code).
The code's y-term has weight 0.5, an offset of +0.5 and no absolute value. The thesis's
form ranks a touched ball that stays put (min y_ball ≈ 0.5: about −0.5) below a miss (about
+0.17), so it punishes hitting the ball at all; the code's form (about +0.33) does not, and
the code's form made Fig. 4.4d, hence the default. Unstable simulation (MuJoCo's
bad-acceleration warning or a non-finite state): that step gives −50 (the code's value)
instead of its reward and the episode ends.

Path (:meth:`~vslbook.envs.robot.task.EpisodicTask.path`): ``ball`` (centre) and ``club``
(the ``rod_tip`` site at the club head) at the start and after every control step, read as
the reward reads them.

Success: the ball passed the goal after the hit (the thesis's fourth case). Info: ``hit``,
``passed`` (0/1), ``min_rod_ball_dist``, ``min_ball_goal_dist``, ``min_ball_y``,
``unstable`` (0/1), ``steps`` (control steps simulated); NaN for invalid θ.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, ClassVar

import mujoco
import numpy as np

# The Panda's PD gains, motor limits, joint limits and timing are box pushing's (B.4.4: "as
# in box pushing").
from vslbook.envs.robot.box_pushing import (  # noqa: F401  (re-exported for the tests)
    ACTION_SCALE,
    D_GAINS,
    DT,
    FRAME_SKIP,
    HORIZON,
    P_GAINS,
    Q_MAX,
    Q_MIN,
    TORQUE_MAX,
)
from vslbook.envs.robot.mini_golf_model import (
    BALL_RADIUS,
    BALL_START_Y,
    BALL_START_Z,
    GOAL_Y,
    OBSTACLE_Z,
    build_model,
)
from vslbook.envs.robot.primitives import ProDMPSpec, joint_limit_excess
from vslbook.envs.robot.task import Episode, EpisodicTask

Q0 = np.array([0.90138834, 0.94911663, 0.15175606, -1.0552696, -0.13568928, 1.99531533, 1.82624438])
TAU_BOUNDS = (0.45, 1.7)
#: The ball has passed the goal once y_ball − radius < PASS_Y (after the hit).
PASS_Y = -0.75
ACTION_COST = 0.0005
UNSTABLE_STEP = -50.0
INVALID_SCALE, INVALID_OFFSET, INVALID_TAU_WEIGHT = 20.0, -5.0, 3.0
PASSED_REWARD = 6.0
#: The third case's variants (module docstring): the authors' code (default) and B.4.4's text.
REWARD_VARIANTS = ("code", "thesis")

SPEC = ProDMPSpec(
    n_dof=7, n_basis=4, dt=DT, duration=HORIZON * DT, alpha=25.0, alpha_phase=3.0,
    tau=1.5, tau_bounds=TAU_BOUNDS, goal="disabled", weights_scale=0.3, auto_scale_basis=True,
)  # fmt: skip


def step_cost(torque: np.ndarray) -> float:
    """Reward of a step before the last: −0.0005 Σ_i torque_i² (torque = 10 a)."""
    torque = np.asarray(torque, dtype=np.float64)
    return -ACTION_COST * float(np.sum(np.square(torque)))


def _step_costs(torques: np.ndarray) -> list[float]:
    """:func:`step_cost` of each row of ``torques`` ``(n, 7)``, as a list of floats."""
    return (-ACTION_COST * np.sum(np.square(torques), axis=1)).tolist()


def final_reward(
    hit: bool,
    passed: bool,
    min_rod_ball: float,
    min_ball_goal: float,
    min_ball_y: float,
    variant: str = "code",
) -> float:
    """Reward of the last step (B.4.4's R_task, cases 2-4; see the module docstring).

    Args:
        hit: the club touched the ball during the episode.
        passed: the ball passed the goal after the hit.
        min_rod_ball: min over the episode of ‖p_rod_tip − p_ball‖.
        min_ball_goal: min over the episode of ‖p_ball − p_goal‖.
        min_ball_y: min over the episode of the ball's y.
        variant: ``"code"`` (the authors' third case, the default) or ``"thesis"`` (B.4.4's
            printed third case).
    """
    if variant not in REWARD_VARIANTS:
        raise ValueError(
            f"variant must be one of {', '.join(map(repr, REWARD_VARIANTS))}, got {variant!r}"
        )
    if not hit:
        return 0.2 - 0.2 * math.tanh(min_rod_ball)
    if passed:
        return PASSED_REWARD
    goal_term = 2.0 - 2.0 * math.tanh(min_ball_goal)
    if variant == "thesis":  # B.4.4: − tanh(|p_b,y − p_thresh,y|)
        return goal_term - math.tanh(abs(min_ball_y - PASS_Y))
    # the authors' code: + 0.5 (1 − tanh(min y_ball − p_thresh,y)), no absolute value
    return goal_term + 0.5 * (1.0 - math.tanh(min_ball_y - PASS_Y))


def invalid_penalty(theta: np.ndarray, q_d: np.ndarray) -> float:
    """0 for a valid θ, else ``−20 (3 Δτ + ē_high + ē_low) − 5`` (module docstring)."""
    d_tau, _ = SPEC.bound_excess(theta)
    q_d = np.asarray(q_d, dtype=np.float64)
    if d_tau <= 0.0 and not np.any(q_d > Q_MAX) and not np.any(q_d < Q_MIN):
        return 0.0
    high, low = joint_limit_excess(q_d, Q_MIN, Q_MAX)
    return -INVALID_SCALE * (INVALID_TAU_WEIGHT * d_tau + high + low) + INVALID_OFFSET


@dataclass
class Trace:
    """What one simulated episode recorded (for the reward and for inspection).

    Attributes:
        ball, rod_tip: positions after every substep, ``(n_substeps, 3)``.
        torque: commanded torque 10 a of every control step, ``(steps, 7)``.
        goal: the goal point (site ``ball_target``).
        hit, passed, unstable: the events of the module docstring.
        steps: control steps simulated (the last one may be the unstable one).
    """

    ball: np.ndarray
    rod_tip: np.ndarray
    torque: np.ndarray
    goal: np.ndarray
    hit: bool
    passed: bool
    unstable: bool
    steps: int

    @property
    def min_rod_ball(self) -> float:
        return float(np.min(np.linalg.norm(self.ball - self.rod_tip, axis=1)))

    @property
    def min_ball_goal(self) -> float:
        return float(np.min(np.linalg.norm(self.ball - self.goal, axis=1)))

    @property
    def min_ball_y(self) -> float:
        return float(np.min(self.ball[:, 1]))


class MiniGolf(EpisodicTask):
    """Robot Mini Golf (MG): see the module docstring for every detail.

    Args:
        settings: ``"code"`` (default): the authors' environment, which made Fig. 4.4d (its
            reward, x_goal ∈ [0.18, 0.67]); ``"thesis"``: B.4.4's reward and box
            (x_goal ∈ [0.25, 0.6]).
        reward: ``"code"`` or ``"thesis"`` (B.4.4's printed third case; see the module
            docstring); None: the one of ``settings``.
        joint_limit_check: reject θ whose τ or q_d leave their bounds without simulating
            (False simulates every θ, τ clipped to its bounds).
    """

    name: ClassVar[str] = "mini-golf"
    context_names: ClassVar[tuple[str, ...]] = ("x_obstacle", "y_obstacle", "x_ball", "x_goal")
    # the authors' box (MiniGolfOneObsEnv): x_goal in [0.18, 0.67]; B.4.4's is [0.25, 0.6]
    context_low: ClassVar[np.ndarray] = np.array([0.3, -0.5, 0.25, 0.18])
    context_high: ClassVar[np.ndarray] = np.array([0.6, -0.1, 0.6, 0.67])
    n_params: ClassVar[int] = SPEC.n_params
    info_keys: ClassVar[tuple[str, ...]] = (
        "hit", "passed", "min_rod_ball_dist", "min_ball_goal_dist", "min_ball_y", "unstable",
        "steps",
    )  # fmt: skip
    has_success: ClassVar[bool] = True
    path_names: ClassVar[tuple[str, ...]] = ("ball", "club")
    mp: ClassVar[ProDMPSpec] = SPEC

    def __init__(
        self, settings: str = "code", reward: str | None = None, joint_limit_check: bool = True
    ) -> None:
        if settings not in REWARD_VARIANTS:
            raise ValueError(f"settings must be one of {REWARD_VARIANTS}, got {settings!r}")
        reward = settings if reward is None else reward
        if reward not in REWARD_VARIANTS:
            raise ValueError(
                f"reward must be one of {', '.join(map(repr, REWARD_VARIANTS))}, got {reward!r}"
            )
        super().__init__(settings=settings, reward=reward, joint_limit_check=joint_limit_check)
        self.settings, self.reward = settings, reward
        if settings == "thesis":  # B.4.4: x_goal in [0.25, 0.6]
            self.context_low = np.array([0.3, -0.5, 0.25, 0.25])
            self.context_high = np.array([0.6, -0.1, 0.6, 0.6])
        self.joint_limit_check = bool(joint_limit_check)
        self.model = build_model()
        self.data = mujoco.MjData(self.model)
        m = self.model
        self._ball_qpos = int(m.jnt_qposadr[m.joint("ball_joint").id])
        self._ball_qvel = int(m.jnt_dofadr[m.joint("ball_joint").id])
        self._ball_body = int(m.body("ball").id)
        self._ball_geom = int(m.geom("ball_contact").id)
        self._club_geoms = (int(m.geom("rod_contact").id), int(m.geom("rod_contact2").id))
        self._rod_tip = int(m.site("rod_tip").id)
        self._goal_site = int(m.site("ball_target").id)
        self._mocap = {n: int(m.body_mocapid[m.body(n).id]) for n in ("obstacle", "goal")}
        #: Physics steps taken by this instance (lets tests see that nothing was simulated).
        self.physics_steps = 0

    # -- simulation ---------------------------------------------------------------------
    def scene(self, context: Any) -> tuple[mujoco.MjModel, mujoco.MjData]:
        """The simulator at the start of an episode in ``context`` (see the base class)."""
        self.reset(self.one_context(context))
        return self.model, self.data

    def reset(self, context: np.ndarray) -> None:
        """Robot at q0 at rest, ball at (x_ball, 0.5, 0.005), obstacle and goal placed."""
        m, d = self.model, self.data
        c = np.asarray(context, dtype=np.float64).reshape(self.context_dim)
        mujoco.mj_resetData(m, d)
        d.qpos[:7] = Q0
        a = self._ball_qpos
        d.qpos[a : a + 7] = [c[2], BALL_START_Y, BALL_START_Z, 1.0, 0.0, 0.0, 0.0]
        d.mocap_pos[self._mocap["obstacle"]] = [c[0], c[1], OBSTACLE_Z]
        d.mocap_pos[self._mocap["goal"]] = [c[3], GOAL_Y, 0.0]
        for name in ("obstacle", "goal"):
            d.mocap_quat[self._mocap[name]] = [1.0, 0.0, 0.0, 0.0]
        mujoco.mj_forward(m, d)

    def _club_contact(self) -> bool:
        """Whether a contact of ``data`` pairs the ball with a club geom: the plain reading of
        the hit event. :meth:`simulate` runs the same test inline (cheaper per substep); the
        tests use this method as its reference."""
        d = self.data
        ball, club = self._ball_geom, self._club_geoms
        for g1, g2 in d.contact.geom[: d.ncon].tolist():
            if (g1 == ball or g2 == ball) and (g1 in club or g2 in club):
                return True
        return False

    def simulate(
        self,
        q_d: np.ndarray,
        dq_d: np.ndarray,
        context: np.ndarray,
        ball_pos: np.ndarray | None = None,
        ball_vel: np.ndarray | None = None,
    ) -> Trace:
        """Track ``(q_d, q̇_d)`` ``(HORIZON + 1, 7)`` in ``context``; returns the :class:`Trace`.

        ``ball_pos`` / ``ball_vel`` (3,) override the ball's start position / linear
        velocity after the reset (a ball placed and pushed by hand, for tests).
        """
        m, d = self.model, self.data
        self.reset(context)
        if ball_pos is not None:
            d.qpos[self._ball_qpos : self._ball_qpos + 3] = ball_pos
        if ball_vel is not None:
            d.qvel[self._ball_qvel : self._ball_qvel + 3] = ball_vel
        if ball_pos is not None or ball_vel is not None:  # (reset ran mj_forward already)
            mujoco.mj_forward(m, d)
        goal = d.site_xpos[self._goal_site].copy()
        start_ball, start_tip = d.xpos[self._ball_body].copy(), d.site_xpos[self._rod_tip].copy()
        # After every substep: qpos (tested for finiteness after the loop), ball and club tip
        n_sub = HORIZON * FRAME_SKIP
        qs, ball, tip = np.empty((n_sub, m.nq)), np.empty((n_sub, 3)), np.empty((n_sub, 3))
        torques = np.empty((HORIZON, 7))
        bad, warnings = int(mujoco.mjtWarning.mjWARN_BADQACC), d.warning.number
        hit = unstable = False
        i = t = 0
        i_hit = n_sub  # the substep of the first ball-club contact
        # Views into MjData (its buffers never move) and scratch arrays: the loop allocates
        # nothing but the contact pairs it reads before the hit. The PD law, in place and in
        # the order of the module docstring:
        # a = clip(K_p (q_d - q) + K_d (q̇_d - q̇), -1, 1), u = clip(10 a + bias, ±limit).
        qpos, q, dq, bias, ctrl = d.qpos, d.qpos[:7], d.qvel[:7], d.qfrc_bias[:7], d.ctrl
        ball_x, tip_x = d.xpos[self._ball_body], d.site_xpos[self._rod_tip]
        contacts = d.contact  # MjData's contact list (its length follows ncon)
        # a contact is a hit iff its (geom1, geom2) is one of these (_club_contact)
        b, (c1, c2) = self._ball_geom, self._club_geoms
        hit0, hit1, hit2, hit3 = [b, c1], [c1, b], [b, c2], [c2, b]
        e, f, neg_max = np.empty(7), np.empty(7), -TORQUE_MAX
        sub, mul, add, mx, mn = np.subtract, np.multiply, np.add, np.maximum, np.minimum
        step, sub_steps = mujoco.mj_step, range(FRAME_SKIP)
        for t in range(HORIZON):
            mul(P_GAINS, sub(q_d[t + 1], q, e), e)
            mul(D_GAINS, sub(dq_d[t + 1], dq, f), f)
            mn(mx(add(e, f, e), -1.0, out=e), 1.0, out=e)  # = np.clip(a, -1, 1)
            tq = torques[t]
            mul(ACTION_SCALE, e, tq)
            mn(mx(add(tq, bias, ctrl), neg_max, out=ctrl), TORQUE_MAX, out=ctrl)
            for _ in sub_steps:
                step(m, d)
                if warnings[bad] > 0:  # MuJoCo reset the state after a bad acceleration
                    unstable = True
                    break
                if not hit and d.ncon:
                    pairs = contacts.geom.tolist()
                    if hit0 in pairs or hit1 in pairs or hit2 in pairs or hit3 in pairs:
                        hit, i_hit = True, i
                qs[i] = qpos
                ball[i] = ball_x
                tip[i] = tip_x
                i += 1
            if unstable:
                break
        # A non-finite state ends the episode at the substep that produced it, as if tested
        # right after that substep (tested here for all substeps at once, cheaper than in the
        # loop): what was simulated after it is dropped. MuJoCo's own checks reset such a
        # state at the next substep, so it never lasts.
        finite = np.isfinite(qs[:i]).all(axis=1)
        if not finite.all():
            i = int(np.argmin(finite))
            t, unstable = i // FRAME_SKIP, True
            if i_hit >= i:
                hit, i_hit = False, n_sub
        self.physics_steps += i + int(unstable)  # the unstable substep was taken as well
        # passed: y_ball - radius < PASS_Y in a substep after the one of the hit
        after_hit = ball[i_hit + 1 : i, 1]
        passed = hit and not unstable and bool(np.any(after_hit - BALL_RADIUS < PASS_Y))
        path = self._recorder
        if path is not None:  # the start and the end of every control step before a breakdown
            path(ball=start_ball, club=start_tip)
            for k in range(FRAME_SKIP - 1, (t if unstable else HORIZON) * FRAME_SKIP, FRAME_SKIP):
                path(ball=ball[k], club=tip[k])
        if i == 0:  # unstable in the very first substep: the start state is all there is
            ball[0], tip[0], i = start_ball, start_tip, 1
        return Trace(
            ball=ball[:i].copy(), rod_tip=tip[:i].copy(), torque=torques[: t + 1].copy(),
            goal=goal, hit=hit, passed=passed, unstable=unstable, steps=t + 1,
        )  # fmt: skip

    def trace_return(self, trace: Trace) -> float:
        """The episode return of a :class:`Trace` (step costs, then the final reward or −50).

        The step costs are :func:`step_cost` of every torque row, computed for all rows at
        once and summed in step order.
        """
        if trace.unstable:
            costs = sum(_step_costs(trace.torque[: trace.steps - 1]))
            return float(costs + UNSTABLE_STEP)
        costs = sum(_step_costs(trace.torque[: HORIZON - 1]))
        final = final_reward(
            trace.hit, trace.passed, trace.min_rod_ball, trace.min_ball_goal,
            trace.min_ball_y, self.reward,
        )  # fmt: skip
        return float(costs + final)

    def episode(self, theta: np.ndarray, context: np.ndarray) -> Episode:
        theta, context = self.episode_args(theta, context)
        q_d, dq_d = self.mp.trajectory(theta, Q0)
        if self.joint_limit_check:
            penalty = invalid_penalty(theta, q_d[1:])  # the tracked rows (not t = 0)
            if penalty < 0.0:
                return Episode(penalty, False, False, dict.fromkeys(self.info_keys, math.nan))
        trace = self.simulate(q_d, dq_d, context)
        success = bool(trace.hit and trace.passed)
        info = {
            "hit": float(trace.hit),
            "passed": float(trace.passed),
            "min_rod_ball_dist": trace.min_rod_ball,
            "min_ball_goal_dist": trace.min_ball_goal,
            "min_ball_y": trace.min_ball_y,
            "unstable": float(trace.unstable),
            "steps": float(trace.steps),
        }
        return Episode(self.trace_return(trace), success, True, info)

    def __repr__(self) -> str:
        return f"MiniGolf(reward={self.reward!r}, joint_limit_check={self.joint_limit_check})"
