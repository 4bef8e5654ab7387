"""Beer Pong (thesis Section 3.4, Fig. 3.2; Appendix A.3.2): a Barrett WAM throws a ball
into a cup whose position on the table is the context.

**Model.** fancy-gym 0.3.0's ``beerpong/assets/beerpong_wo_cup.xml`` (MIT), read from the
installed wheel with its broken ``meshdir`` patched in memory (``../../meshes/wam/`` →
``./meshes/wam/``). Timestep 0.005 s, Euler (as in the file). The ball is a sphere on three
slide joints (``qpos[7:10]`` is its position); the cup body ``cup_table`` carries the sites
``cup_goal_table`` (top edge, p_c,top) and ``cup_goal_final_table`` (cup ground,
p_c,bottom) and the geom ``cup_base_table_contact`` lying on the cup's floor.

**Context** c = (cup_x, cup_y) ∈ [−0.32, 0.32] × [−2.2, −1.2] (A.3.2), uniform, no further
rejection. The cup body is placed at (cup_x, cup_y, 0.840) (the authors' code); because the
cup mesh is rotated, its axis lies 0.134 m further along −y than the body origin.

**Parameters** θ ∈ ℝ¹⁵ (Section 3.4: "weights and the length of the trajectory"):
``θ = [l, w_1,1, w_1,2, w_2,1, ..., w_7,2]`` — the movement duration l in seconds first (as
the package's ProDMP layout puts τ first; the authors' code puts it last), then two ProMP
weights per joint, dof-major. The desired trajectory is a ProMP (Eq. 2.46) with four
normalised RBFs per joint on the phase s = t / l (centres 0, ⅓, ⅔, 1, width 0.1 in phase
units): the weights of the first two RBFs are fixed to zero and the learned ones are
multiplied by ``weights_scale`` (default √0.02, the authors' scaling), and the result is
added to the start posture q0 = [0, 1.35, 0, 1.18, 0, −0.786, −1.59]. With the two leading
zero weights q_d(0) = q0 (to 1e−9) and the arm rests during the first part of the movement,
as in the authors' construction (their centres are −0.01 … 1.01 with variance 0.01, i.e.
the same width; our velocities are the exact time derivatives ∂q_d/∂t, theirs are scaled
by a fixed 3.5 s instead of l).

**Timing and controller** (authors' code; the thesis gives none). l is rounded to the
control grid, n = round(l / 0.005) steps. At each step the joint torque is
u = K_p (q_d − q) + K_d (q̇_d − q̇) + qfrc_bias (gravity and Coriolis compensation) with
K_p = [200, 300, 100, 100, 10, 10, 2.5], K_d = 0.5·[7, 15, 5, 2.5, 0.3, 0.3, 0.05], not
clipped, q and q̇ the state of the step. The ball is pinned to the hand site
``init_ball_pos`` (position and linear velocity) up to and including the state at
t = n·0.005 s (the release time = the end of the trajectory); then the robot holds q_d(l)
with q̇_d = 0 (the authors keep the last desired velocity: an interpretation) for
``extra_steps`` = 500 more steps while the ball flies. Each step is ``mj_step1`` → pin the
ball → torque → ``mj_step2``, so the ball takes the hand's *current* position and velocity
(``mj_step`` followed by pinning, as in the authors' code, lags one step).

How the law is applied: MuJoCo's actuators compute its feedback part. The file's seven arm
motors (ctrl ∈ [−1, 1] with gears) are turned in memory (:func:`use_pd_actuators`, in
:mod:`vslbook.envs.robot.beer_pong_model` with the model file and the gains; the file is not
changed) into actuators on their joints with gear 1, gain 1 on ctrl and the affine
bias −K_p q − K_d q̇, without ctrl or force limits. ``mj_step2`` computes their force from the
joint positions and velocities that ``mj_step1`` found for the step, and the Euler
integrator (the file's) applies it explicitly, like any applied force. With ctrl =
K_p q_d + K_d q̇_d (computed for all steps beforehand; after the release the constant
K_p q_d(l), written once) and qfrc_applied = qfrc_bias, actuator force + qfrc_applied is u:
the same law. Only the order of the sum differs, so results agree with a per-step evaluation
of the law in Python to rounding (up to about 3e−10 relative seen), not bit for bit. Why:
per step the loop then only pins the ball, writes ctrl (until the release), copies qfrc_bias
and records the step; with the law evaluated in numpy everything around the physics cost
35–45 % of it, now about 15 % (``benchmarks/robot_tasks.py beer-pong``). The torques u of the steps
(``torque_path``, τ̄) are actuator force + qfrc_applied, the force evaluated after the loop
from the recorded q, q̇ as MuJoCo evaluates it. So ``model``'s actuators are these PD
actuators: ctrl = 0 is not "no torque".

**Reward** (A.3.2; the episode return): :mod:`vslbook.envs.robot.beer_pong_reward` gives it
(:func:`~vslbook.envs.robot.beer_pong_reward.beer_pong_reward`) and what "in the cup" and
"contact" mean for each ``reward`` variant. The contacts are looked up after the loop: for
each recorded state with the ball near one of the geoms in question, its contact list is
recomputed.

**Validity before simulation** (A.3.2; not simulated, ``executed=False``):
l < 0.1: −30 − 10 (l − 0.1)²; l > 1.3: −30 − 10 (l − 1.3)²; any q_d outside the joint
limits j_min = [−2.6, −1.985, −2.8, −0.9, −4.55, −1.5707, −2.7], j_max = [2.6, 1.985, 2.8,
3.14159, 1.25, 1.5707, 2.7] (the model's ranges): −30. A context outside the box gets
:meth:`BeerPong.context_penalty` = −30 − d_c² (d_c: Euclidean distance to the box).

**Path** (:meth:`~vslbook.envs.robot.task.EpisodicTask.path`): ``ball``, the ball's position
at 0, dt, ..., T (the rows of ``ball_path``, recorded by the loop; an unstable episode stops
at its last step).

**Success**: the ball is in the cup at the end (see ``reward`` in
:mod:`vslbook.envs.robot.beer_pong_reward`). Info: ``in_cup`` (cond. 3 as the reward judged
it), ``table_contact`` (the contact of cond. 2 as the reward judged it: under ``"code"``
with the table top, the wall or the cup), ``min_dist_top`` (min_t ‖p_c,top − p_b,t‖),
``final_dist_bottom`` (‖p_c,bottom − p_b,T‖), ``release_time`` (s), ``duration`` (l as
given), ``torque_cost`` (τ̄). A rejected θ reports only ``duration``
(:class:`~vslbook.envs.robot.task.Rollouts` fills NaN for the rest; leaving the keys out
keeps NaN out of the one-step environment's info, which gymnasium's checker compares with
``==``).
"""

from __future__ import annotations

import math
from typing import Any, ClassVar

import mujoco
import numpy as np

from vslbook.envs.robot.assets import load_model
from vslbook.envs.robot.beer_pong_model import (
    D_GAINS,
    MODEL,
    MODEL_PATCHES,
    N_DOF,
    P_GAINS,
    use_pd_actuators,
)
from vslbook.envs.robot.beer_pong_reward import (
    CODE_CONTACT_GEOMS,
    CUP_BODY,
    CUP_FLOOR_GEOM,
    REWARD_VARIANTS,
    TABLE_GEOMS,
    UNSTABLE_PENALTY,
    UNSTABLE_WARNINGS,
    beer_pong_reward,
)
from vslbook.envs.robot.primitives import promp_trajectory
from vslbook.envs.robot.task import Episode, EpisodicTask

DT = 0.005
Q0 = np.array([0.0, 1.35, 0.0, 1.18, 0.0, -0.786, -1.59])
J_MIN = np.array([-2.6, -1.985, -2.8, -0.9, -4.55, -1.5707, -2.7])
J_MAX = np.array([2.6, 1.985, 2.8, 3.14159, 1.25, 1.5707, 2.7])
DURATION_BOUNDS = (0.1, 1.3)
CUP_Z = 0.840
N_LEARNED = 2  # learned weights per joint
N_ZERO = 2  # leading basis functions with weight fixed to zero
BASIS_WIDTH = 0.1
WEIGHTS_SCALE = math.sqrt(0.02)
EXTRA_STEPS = 500
INVALID_PENALTY = -30.0


def duration_penalty(duration: float) -> float:
    """A.3.2's R_θ for a duration outside [0.1, 1.3] s; 0 inside."""
    lo, hi = DURATION_BOUNDS
    if duration < lo:
        return INVALID_PENALTY - 10.0 * (duration - lo) ** 2
    if duration > hi:
        return INVALID_PENALTY - 10.0 * (duration - hi) ** 2
    return 0.0


def desired_trajectory(
    theta: np.ndarray, weights_scale: float = WEIGHTS_SCALE
) -> tuple[np.ndarray, np.ndarray]:
    """``(q_d, q̇_d)``, each ``(n + 1, 7)`` on 0, dt, ..., n·dt with n = round(l / dt).

    ``theta`` must hold a duration inside the bounds (checked by the caller). Valid durations
    give n = 20 ... 260, so the ProMP of each n is built once (``promp_trajectory``'s cache).
    """
    n = int(round(float(theta[0]) / DT))
    w = np.zeros((N_DOF, N_ZERO + N_LEARNED))
    w[:, N_ZERO:] = np.reshape(theta[1:], (N_DOF, N_LEARNED)) * weights_scale
    return promp_trajectory(w, n * DT, DT, Q0, width=BASIS_WIDTH)


class BeerPong(EpisodicTask):
    """Beer Pong of Section 3.4 / A.3.2 (see the module docstring for every detail).

    Args:
        extra_steps: simulation steps after the release (default 500, the authors' code).
        weights_scale: factor on the learned ProMP weights (default √0.02).
        reward: what "in the cup" and "contact" mean in the reward: ``"code"`` (default, the
            authors' code) or ``"thesis"`` (A.3.2's text); see the module docstring.
    """

    name: ClassVar[str] = "beer-pong"
    context_names: ClassVar[tuple[str, ...]] = ("cup_x", "cup_y")
    context_low: ClassVar[np.ndarray] = np.array([-0.32, -2.2])
    context_high: ClassVar[np.ndarray] = np.array([0.32, -1.2])
    n_params: ClassVar[int] = 1 + N_DOF * N_LEARNED
    info_keys: ClassVar[tuple[str, ...]] = (
        "in_cup", "table_contact", "min_dist_top", "final_dist_bottom", "release_time",
        "duration", "torque_cost",
    )  # fmt: skip
    has_success: ClassVar[bool] = True
    path_names: ClassVar[tuple[str, ...]] = ("ball",)

    def __init__(
        self,
        extra_steps: int = EXTRA_STEPS,
        weights_scale: float = WEIGHTS_SCALE,
        reward: str = "code",
        **kwargs: Any,
    ) -> None:
        if isinstance(extra_steps, bool) or not isinstance(extra_steps, (int, np.integer)):
            raise ValueError(f"extra_steps must be an integer >= 1, got {extra_steps!r}")
        if extra_steps < 1:
            raise ValueError(f"extra_steps must be an integer >= 1, got {extra_steps!r}")
        if not (isinstance(weights_scale, (int, float)) and math.isfinite(weights_scale)):
            raise ValueError(f"weights_scale must be a finite number, got {weights_scale!r}")
        if weights_scale <= 0:
            raise ValueError(f"weights_scale must be positive, got {weights_scale!r}")
        if not isinstance(reward, str) or reward not in REWARD_VARIANTS:
            raise ValueError(
                f"reward must be one of {', '.join(map(repr, REWARD_VARIANTS))}, got {reward!r}"
            )
        super().__init__(
            extra_steps=int(extra_steps), weights_scale=float(weights_scale), reward=reward,
            **kwargs,
        )  # fmt: skip
        self.extra_steps = int(extra_steps)
        self.weights_scale = float(weights_scale)
        self.reward = reward
        self.model = load_model(MODEL, MODEL_PATCHES)
        if abs(self.model.opt.timestep - DT) > 1e-12:
            raise RuntimeError(f"{MODEL}: expected timestep {DT}, got {self.model.opt.timestep}")
        use_pd_actuators(self.model)
        self.data = mujoco.MjData(self.model)
        m = self.model
        self._hand = m.site("init_ball_pos").id
        self._top = m.site("cup_goal_table").id
        self._bottom = m.site("cup_goal_final_table").id
        self._cup = m.body("cup_table").id
        self._ball_geom = m.geom("ball_geom").id
        self._floor_geom = m.geom(CUP_FLOOR_GEOM).id
        cup = m.body(CUP_BODY).id
        cup_geoms = [
            g for g in range(m.ngeom)
            if m.geom_bodyid[g] == cup and (m.geom_contype[g] or m.geom_conaffinity[g])
        ]  # fmt: skip
        #: The geoms whose contact with the ball is cond. 2's "contact" (``reward``).
        self.contact_geoms = np.array(
            [m.geom(g).id for g in CODE_CONTACT_GEOMS] + cup_geoms
            if reward == "code" else [m.geom(g).id for g in TABLE_GEOMS]
        )  # fmt: skip
        # The recorded states whose contact lists are recomputed after an episode (a costly
        # step) are those with the ball inside a box around one of these geoms, grown by the
        # ball's radius + 1 cm (boxes of the episode's cup position, :meth:`_near_boxes`).
        self._near_geoms = np.unique(np.r_[self.contact_geoms, self._floor_geom])
        # geom id -> whether it is one of contact_geoms: a lookup per contact list instead of
        # np.isin, which cost more than the contact recomputation it follows
        self._is_contact_geom = np.zeros(m.ngeom, dtype=bool)
        self._is_contact_geom[self.contact_geoms] = True
        self._near_grow = m.geom_rbound[self._ball_geom] + m.geom_margin[self._ball_geom] + 0.01
        self._vel = np.zeros(6)
        self._probe = mujoco.MjData(m)  # recomputes the contacts of recorded states
        # What the loop records of every step (mj_getState, one call): qpos, qvel and
        # qfrc_applied, in this order (the order of the mjtState bits).
        state = mujoco.mjtState
        self._row_spec = int(state.mjSTATE_QPOS | state.mjSTATE_QVEL | state.mjSTATE_QFRC_APPLIED)
        self._row_size = mujoco.mj_stateSize(m, self._row_spec)
        self.n_physics_steps = 0  # mj_step1/mj_step2 pairs run by this instance
        self.ball_path = np.empty((0, 3))  # ball positions of the last executed episode
        self.torque_path = np.empty((0, N_DOF))  # its applied torques

    # -- contexts -----------------------------------------------------------------------
    def context_penalty(self, contexts: np.ndarray) -> np.ndarray:
        """A.3.2's R_c = −30 − d_c², d_c the distance of c to the context box."""
        c = np.asarray(contexts, dtype=np.float64)
        excess = np.maximum(self.context_low - c, 0) + np.maximum(c - self.context_high, 0)
        return INVALID_PENALTY - np.sum(excess**2, axis=-1)

    def scene(self, context: Any) -> tuple[mujoco.MjModel, mujoco.MjData]:
        """The simulator at the start of an episode in ``context`` (see the base class)."""
        self.reset(self.one_context(context))
        return self.model, self.data

    # -- simulator helpers ----------------------------------------------------------------
    def reset(self, context: np.ndarray) -> None:
        """Robot at rest in q0, cup at (c_x, c_y, 0.840), ball on the hand site."""
        m, d = self.model, self.data
        mujoco.mj_resetData(m, d)
        m.body_pos[self._cup] = (float(context[0]), float(context[1]), CUP_Z)
        d.qpos[:N_DOF] = Q0
        mujoco.mj_kinematics(m, d)  # the hand site's position: kinematics suffice
        d.qpos[7:10] = d.site_xpos[self._hand]
        mujoco.mj_forward(m, d)

    def cup_sites(self) -> tuple[np.ndarray, np.ndarray]:
        """(p_c,top, p_c,bottom) of the current model state (after a forward pass)."""
        return self.data.site_xpos[self._top].copy(), self.data.site_xpos[self._bottom].copy()

    def ball_contacts(self, data: mujoco.MjData | None = None) -> tuple[bool, bool]:
        """(ball touches the cup floor, ball has cond. 2's contact) in ``data``'s contact
        list; the second is a contact with one of :attr:`contact_geoms` (``reward``)."""
        d = self.data if data is None else data
        if d.ncon == 0:
            return False, False
        g = d.contact.geom[: d.ncon]
        ball = (g == self._ball_geom).any(axis=1)
        other = np.where(g[:, 0] == self._ball_geom, g[:, 1], g[:, 0])[ball]
        return bool((other == self._floor_geom).any()), bool(self._is_contact_geom[other].any())

    # -- episodes -----------------------------------------------------------------------
    def episode(self, theta: np.ndarray, context: np.ndarray) -> Episode:
        return self._episode(theta, context)

    def episode_with_ball(self, theta: Any, context: Any, ball_pos: Any, ball_vel: Any) -> Episode:
        """:meth:`episode`, except that at the release the ball does not leave the hand but is
        put at ``ball_pos`` with linear velocity ``ball_vel`` (both (3,), world frame): a ball
        placed and thrown by hand, for tests. The ball is placed in the state of the release
        step after MuJoCo found its contacts, so during that one step it flies freely; it is
        the state the step records (the path, the distances and the contact tests see it).
        """
        ball = []
        for name, v in (("ball_pos", ball_pos), ("ball_vel", ball_vel)):
            a = np.asarray(v, dtype=np.float64)
            if a.shape != (3,) or not np.isfinite(a).all():
                raise ValueError(f"{name} must be 3 finite numbers, got {v!r}")
            ball.append(a)
        return self._episode(theta, context, (ball[0], ball[1]))

    def _episode(
        self, theta: Any, context: Any, placed: tuple[np.ndarray, np.ndarray] | None = None
    ) -> Episode:
        """The validity checks before simulation (A.3.2), then :meth:`_simulate`."""
        theta, context = self.episode_args(theta, context)
        duration = float(theta[0])
        pen = duration_penalty(duration)
        if pen != 0.0:
            return Episode(pen, False, False, {"duration": duration})
        q_d, dq_d = desired_trajectory(theta, self.weights_scale)
        if np.any(q_d < J_MIN) or np.any(q_d > J_MAX):
            return Episode(INVALID_PENALTY, False, False, {"duration": duration})
        return self._simulate(q_d, dq_d, context, duration, placed)

    def _simulate(
        self,
        q_d: np.ndarray,
        dq_d: np.ndarray,
        context: np.ndarray,
        duration: float,
        placed: tuple[np.ndarray, np.ndarray] | None = None,
    ) -> Episode:
        """One executed episode (A.3.2): the control law and ball pin of the module docstring,
        with the PD part in MuJoCo's actuators (:func:`use_pd_actuators`); ``placed``: the
        ball's (position, velocity) put in at the release (:meth:`episode_with_ball`)."""
        m, d = self.model, self.data
        self.reset(context)
        top, bottom = self.cup_sites()
        near_lo, near_hi = self._near_boxes()
        n = len(q_d) - 1
        n_total = n + self.extra_steps
        nq, nv = m.nq, m.nv
        # ctrl of every step (the PD actuators' force is ctrl − K_p q − K_d q̇, see
        # use_pd_actuators): K_p q_d + K_d q̇_d before the release step n, then K_p q_d(l) (hold).
        ctrls = np.empty((n_total, N_DOF))
        ctrls[:n] = P_GAINS * q_d[:n] + D_GAINS * dq_d[:n]
        ctrls[n:] = P_GAINS * q_d[n]
        # Row k: qpos, qvel and qfrc_applied of step k as mj_step2 gets them (one mj_getState).
        # The ball's positions, the torques and the table contact follow from them after the
        # loop, which only pins the ball, sets the inputs, records and steps.
        rows = np.empty((n_total, self._row_size))
        # Views into MjData (its buffers never move), so the loop allocates nothing; ``[...] =``
        # is numpy's cheapest copy into a view.
        ctrl, bias, applied = d.ctrl, d.qfrc_bias[:N_DOF], d.qfrc_applied[:N_DOF]
        ball_q, ball_dq = d.qpos[7:10], d.qvel[7:10]
        hand_x, hand_v, vel = d.site_xpos[self._hand], self._vel[3:], self._vel
        step1, step2, objvel = mujoco.mj_step1, mujoco.mj_step2, mujoco.mj_objectVelocity
        record, spec = mujoco.mj_getState, self._row_spec
        site_type, hand = int(mujoco.mjtObj.mjOBJ_SITE), self._hand  # an int: faster than the enum
        held = n + 1 if placed is None else n  # steps with the ball in the hand
        for row, ctrl_k in zip(rows[:held], ctrls[:held], strict=True):  # to release step n
            step1(m, d)
            # the ball held at the hand: its position and linear velocity
            ball_q[...] = hand_x
            objvel(m, d, site_type, hand, vel, 0)
            ball_dq[...] = hand_v
            ctrl[...] = ctrl_k  # at k = n the hold, left in place after the release
            applied[...] = bias  # gravity and Coriolis compensation, qfrc_bias of this step
            record(m, d, row, spec)
            step2(m, d)
        if placed is not None:  # the release step with the ball put in by hand
            step1(m, d)
            ball_q[...], ball_dq[...] = placed
            ctrl[...] = ctrls[n]
            applied[...] = bias
            record(m, d, rows[n], spec)
            step2(m, d)
        for row in rows[n + 1 :]:  # the ball flies
            step1(m, d)
            applied[...] = bias
            record(m, d, row, spec)
            step2(m, d)
        self.n_physics_steps += n_total
        balls = np.empty((n_total + 1, 3))  # the ball's positions at 0, dt, ..., T
        balls[:n_total] = rows[:, 7:10]
        path = self._recorder
        if path is not None:
            for ball in balls[:n_total]:
                path(ball=ball)
        release_time = n * DT
        warnings = d.warning.number
        if any(warnings[w] for w in UNSTABLE_WARNINGS) or not np.isfinite(d.qpos).all():
            info = {"duration": duration, "release_time": release_time}
            return Episode(UNSTABLE_PENALTY, False, True, info)
        # The applied torque u = actuator force + qfrc_applied, the force evaluated as MuJoCo
        # does (ctrl + (−K_p q − K_d q̇), the affine bias), so u is what mj_step2 applied.
        torques = np.multiply(rows[:, :N_DOF], -P_GAINS)
        torques -= np.multiply(rows[:, nq : nq + N_DOF], D_GAINS)
        torques += ctrls
        torques += rows[:, nq + nv : nq + nv + N_DOF]
        mujoco.mj_forward(m, d)  # the final state (and its contacts)
        balls[n_total] = ball_q
        if path is not None:
            path(ball=ball_q)
        self.ball_path = balls  # Fig. 3.2g
        self.torque_path = torques  # the applied joint torques u of every step
        qpos = rows[:, :nq]
        if self.reward == "code":  # the states the steps start from but the last (module doc)
            in_cup, table_contact = self._touches(qpos[:-1], near_lo, near_hi, floor=True)
            success = self._touches(qpos[-1:], near_lo, near_hi, floor=True)[0]
        else:  # "thesis": the final state, and table contact after release
            in_cup, last_table = self.ball_contacts()
            success = in_cup
            table = np.isin(self._near_geoms, self.contact_geoms)
            table_contact = (
                last_table
                or self._touches(qpos[n + 1 :], near_lo[table], near_hi[table], floor=False)[1]
            )
        x, y, z = (balls - top).T
        min_dist_top = math.sqrt((x * x + y * y + z * z).min())
        final_dist_bottom = math.dist(balls[-1], bottom)
        torque_cost = float((torques * torques).sum()) / n_total
        ret = beer_pong_reward(in_cup, table_contact, min_dist_top, final_dist_bottom, torque_cost)
        info = {
            "in_cup": float(in_cup),
            "table_contact": float(table_contact),
            "min_dist_top": min_dist_top,
            "final_dist_bottom": final_dist_bottom,
            "release_time": release_time,
            "duration": duration,
            "torque_cost": torque_cost,
        }
        return Episode(float(ret), bool(success), True, info)

    def _near_boxes(self) -> tuple[np.ndarray, np.ndarray]:
        """(lo, hi), ``(k, 3)`` each: world boxes around the geoms whose contacts with the ball
        the reward reads (the cup floor and :attr:`contact_geoms`, in the order of
        ``_near_geoms``), in ``data``'s current state, grown by the ball's radius, the contact
        margin and 1 cm. Outside all of them the ball touches none of these geoms."""
        m, d = self.model, self.data
        ids = self._near_geoms
        rot = d.geom_xmat[ids].reshape(-1, 3, 3)
        centre = d.geom_xpos[ids] + np.einsum("kij,kj->ki", rot, m.geom_aabb[ids, :3])
        half = np.einsum("kij,kj->ki", np.abs(rot), m.geom_aabb[ids, 3:])
        half += self._near_grow + m.geom_margin[ids, None]
        return centre - half, centre + half

    def _touches(
        self, qpos: np.ndarray, lo: np.ndarray, hi: np.ndarray, floor: bool
    ) -> tuple[bool, bool]:
        """(the ball touches the cup floor, the ball has cond. 2's contact) in any of the
        recorded states ``qpos`` (rows of qpos, each the state that a step's ``mj_step1``
        found its contacts in; ``floor=False``: the first is not looked for).

        Only states with the ball inside one of the boxes ``lo``/``hi``
        (:meth:`_near_boxes`) are looked at; their contacts are recomputed on a second
        MjData by MuJoCo's position stage (a function of qpos alone), which gives the
        contact list that ``mj_step1`` had.
        """
        b = qpos[:, None, 7:10]
        inside = ((b >= lo) & (b <= hi)).all(axis=2).any(axis=1)
        m, probe = self.model, self._probe
        in_cup = contact = False
        for k in np.flatnonzero(inside):
            probe.qpos[:] = qpos[k]
            mujoco.mj_fwdPosition(m, probe)
            f, c = self.ball_contacts(probe)
            in_cup, contact = in_cup or (floor and f), contact or c
            if contact and (in_cup or not floor):
                break
        return in_cup, contact
