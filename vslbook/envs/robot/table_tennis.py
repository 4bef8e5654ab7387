"""Robot table tennis (thesis Section 4.5.1, Appendix B.4.1; reward shape of Appendix A.3.3).

A 7-DoF Barrett WAM with a bat returns a served ball to a goal on the opponent's side.
The model is fancy-gym's ``table_tennis/assets/xml/table_tennis_env.xml`` (MIT), read from
the installed wheel by :func:`vslbook.envs.robot.assets.load_model` (never copied).

Tasks
    :class:`TableTennis4D` ("TT", B.4.1.1) -- context ``[x_ball0, y_ball0, x_goal, y_goal]``,
    x_ball0 ∈ [-1, -0.2], y_ball0 ∈ [-0.65, 0.65], x_goal ∈ [-1, -0.2], y_goal ∈ [-0.6, 0.6].
    :class:`TableTennisHard` ("TT-H", B.4.1.2) -- context
    ``[x_ball0, y_ball0, v_x, x_goal, y_goal]`` with v_x ∈ [1.5, 4] m/s.

Ball serve
    The ball's slide joints start at (x_ball0, y_ball0, 1.75) (world z 1.85: the ball body
    sits 0.1 above its joints' origin) with velocity (v_x, 0, 0.5), v_x = 2.5 in the 4D task,
    so the ball position maps 1:1 to its landing point on the robot's side. A context is valid
    (rejection rules of the authors' code, applied with the sampled v_x in the hard task) when,
    with g = 9.81, z = 1.75 - 0.77 + 0.1, h_net = 0.1, v_z = 0.5,
    ``t_n = v_z/g + sqrt(v_z²/g² + 2(z - h_net)/g)``: x + v_x t_n >= 0.05 (clears the net);
    ``t_l = v_z/g + sqrt(v_z²/g² + 2 z/g)``: x + v_x t_l <= 1.1 (lands before the table's end);
    |y| <= 0.6 (v_y = 0, so y at landing is y_ball0).

Parameters (23) and controller
    θ = [τ, delay, w (7 joints × 3 basis, joint-major)]: a ProDMP (:class:`ProDMPSpec`, basis
    alpha 25, phase alpha 3, weights_scale 0.7, auto-scaled basis, goal disabled, i.e. the
    attractor is the start posture) with learned duration τ ∈ [0.56, 1.5] s and start time
    delay ∈ [0.05, 0.6] s (Di-SkilL's bounds). The robot starts at q0 = [0, 0, 0, 1.5, 0, 0, 1.5]
    at rest. Control step k (dt = 0.002 × 4 = 0.008 s, at most 350 steps = 2.8 s) applies
    ``u = clip(K_p (q_d - q) + K_d (q̇_d - q̇), -1, 1)``, q_d at time (k + 1)·dt, to the motors
    (gears 150, 125, 40, 60, 5, 5, 2), held for the 4 physics sub-steps;
    K_p = 0.5·[1, 4, 2, 4, 1, 4, 1], K_d = 0.1·K_p; no gravity compensation.

Validity (before simulation)
    θ is rejected (not simulated, ``executed=False``) if τ or the delay lie outside their
    bounds or q_d leaves the joint limits low = [-2.6, -2.0, -2.8, -0.9, -4.8, -1.6, -2.2],
    high = [2.6, 2.0, 2.8, 3.1, 1.3, 1.6, 2.2]. Penalty:
    ``-(3 Δτ + 3 Δdelay + mean(max(q_d - high, 0)) + mean(max(low - q_d, 0)))`` (authors' code).
    Interpretation: the thesis's r_traj (B.4.1.1) = -Σ(|τ^d_ij| - |q^b_j|) over entries with
    |τ^d_ij| > |q^b_j| compares magnitudes with the *upper* bound only, which is not a joint
    limit test for the asymmetric limits (joint 4: [-0.9, 3.1]; joint 5: [-4.8, 1.3]) and has
    no term for τ or the delay, so it is not well defined here; the code's penalty is used.

Episode and termination (checked after every physics sub-step)
    The episode ends after 350 control steps; when the ball touches the floor before any
    racket contact; after the first racket contact (``bat`` or ``bat_back``), at the ball's
    first contact with the table or the floor. The landing point is the ball's position at
    that contact. If MuJoCo flags the simulation as unstable (bad accelerations) the episode
    ends with return -25.

Reward (only at the end; A.3.3, = B.4.1.1's f2..f5), with d_r = min_t ‖b_t - r_t‖ (ball centre
to bat centre over all sub-steps), g = goal:
    no racket contact:              0.2 (1 - tanh(d_r²))
    hit, no landing on the table:   2 (1 - tanh(d_r²)) + (1 - tanh(min_t ‖b_t,xy - g‖²))
    hit, then landed on the table:  2 (1 - tanh(d_r²)) + 4 (1 - tanh(‖b_land,xy - g‖²))
                                    + 1[x_land < 0]
    Interpretation: both thesis versions (A.3.3 cond. 3, B.4.1.1 cond. 4) say "table contact"
    for the landing case; the authors' code also scores a first *floor* contact after the hit
    as a landing. The code made Figs. 4.3b and 4.4c, so its rule is the default
    (``settings="code"``); ``settings="thesis"`` (or ``floor_counts_as_landing=False``)
    gives a floor contact after the hit the "no landing" term.
    The function is :func:`~vslbook.envs.robot.table_tennis_reward.staged_reward` (in
    :mod:`vslbook.envs.robot.table_tennis_reward`, re-exported here).

Success: the returned ball lands on the table at x < 0 (opponent's side) and
‖landing_xy - goal‖ < 0.2.

Speed: the loop over control steps and sub-steps runs compiled (:func:`_compiled_loop`,
numba calling MuJoCo's C ``mj_step``, see :mod:`vslbook.envs.robot.native`), with the
contacts read from four contact sensors the model gets in memory (ball with bat, back of
the bat, floor, table); ``compiled=False`` runs the same loop in Python, as do recorded
episodes (:meth:`~vslbook.envs.robot.task.EpisodicTask.path`, :meth:`TableTennis4D.strike`).
Both give the same numbers bit for bit (tested).

Path (:meth:`~vslbook.envs.robot.task.EpisodicTask.path`): ``ball`` (ball centre) and
``racket`` (bat centre) at the start and after every control step, as the reward reads them
(``xpos`` after a physics step); the last row is the sub-step that ended the episode, so
for a landing the ball's last point is the landing point of ``info``.

Other places where the thesis was followed over the code or had to be interpreted
    * Goal y ∈ [-0.65, 0.65], the code's range (``settings="thesis"``: B.4.1.1's ±0.6).
    * The episode stops at the sub-step of the terminating contact (the code finishes the
      control step's remaining sub-steps; only the recorded trajectories differ).
    * Out-of-range contexts (SVSL's punishment, B.4.1.1 and A.3.3): -20 d_c², d_c the distance
      to the valid set (box, and the x/|y| interval the serve rules allow for the context's
      v_x, clipped into its range), one squared excess per entry over the intersected
      intervals (exact in the 4D task; until 2026-11 an entry outside both the box and the
      serve interval counted both excesses). SVSL meets it on the 4D task (Fig. 4.3b);
      Di-SkilL draws valid contexts only.
    * Step k tracks the primitive at (k + 1)·dt (fancy-gym's wrapper drops t = 0); the start
      delay is continuous, as in mp_pytorch. (Until 2026-11 step k tracked k·dt and the
      delay was rounded to the control grid.)
"""

from __future__ import annotations

import math
from typing import Any, ClassVar

import mujoco
import numba
import numpy as np

from vslbook.envs.robot.assets import load_model
from vslbook.envs.robot.native import MJ_STEP
from vslbook.envs.robot.primitives import ProDMPSpec, joint_limit_excess
from vslbook.envs.robot.table_tennis_reward import staged_reward  # noqa: F401  (re-exported)
from vslbook.envs.robot.task import Episode, EpisodicTask

MODEL = "table_tennis/assets/xml/table_tennis_env.xml"
TIMESTEP, FRAME_SKIP, MAX_STEPS = 0.002, 4, 350
DT = TIMESTEP * FRAME_SKIP
Q0 = np.array([0.0, 0.0, 0.0, 1.5, 0.0, 0.0, 1.5])
JOINT_LOW = np.array([-2.6, -2.0, -2.8, -0.9, -4.8, -1.6, -2.2])
JOINT_HIGH = np.array([2.6, 2.0, 2.8, 3.1, 1.3, 1.6, 2.2])
KP = 0.5 * np.array([1.0, 4.0, 2.0, 4.0, 1.0, 4.0, 1.0])
KD = 0.1 * KP
TAU_BOUNDS, DELAY_BOUNDS = (0.56, 1.5), (0.05, 0.6)
#: Where the task's choices come from: the authors' environment (default) or the thesis.
SETTINGS = ("code", "thesis")
#: B.4.1.1's goal-y bound (the authors' code samples ±0.65)
THESIS_GOAL_Y = 0.6
BALL_Z0, BALL_VZ, BALL_VX_4D = 1.75, 0.5, 2.5
GRAVITY, TABLE_HEIGHT, NET_HEIGHT, TABLE_X_END, TABLE_Y_HALF = 9.81, 0.77, 0.1, 1.1, 0.6
UNSTABLE_RETURN = -25.0
#: Contact sensors added to the model in memory, one per geom the ball's contacts are sorted
#: by (bat, back of the bat, floor, table): each reads how many contacts of the ball with
#: that geom the step's contact list holds (``data="found"``). The compiled loop reads these
#: instead of the contact list. Sensors do not change the dynamics.
CONTACT_GEOMS = ("bat", "bat_back", "floor", "table_tennis_table")
_SENSORS = "".join(
    f'<contact name="vslbook_ball_{g}" geom1="target_ball_contact" geom2="{g}" num="1" '
    'data="found"/>'
    for g in CONTACT_GEOMS
)
MODEL_PATCHES = (("</mujoco>", f"<sensor>{_SENSORS}</sensor></mujoco>"),)
SUCCESS_RADIUS = 0.2

SPEC = ProDMPSpec(
    n_dof=7, n_basis=3, dt=DT, duration=MAX_STEPS * DT, alpha=25.0, alpha_phase=3.0, tau=1.5,
    tau_bounds=TAU_BOUNDS, delay_bounds=DELAY_BOUNDS, goal="disabled", weights_scale=0.7,
)  # fmt: skip


def serve_x_interval(v_x: np.ndarray | float) -> tuple[np.ndarray, np.ndarray]:
    """The initial ball x for which a serve with speed ``v_x`` clears the net and lands
    before the table's end: ``(x_min, x_max)`` (the serve rules of the module docstring)."""
    v_x = np.asarray(v_x, dtype=np.float64)
    z = BALL_Z0 - TABLE_HEIGHT + 0.1
    a = BALL_VZ / GRAVITY
    t_net = a + math.sqrt(a * a + 2.0 * (z - NET_HEIGHT) / GRAVITY)
    t_land = a + math.sqrt(a * a + 2.0 * z / GRAVITY)
    return 0.05 - v_x * t_net, TABLE_X_END - v_x * t_land


def serve_valid(x: np.ndarray, y: np.ndarray, v_x: np.ndarray) -> np.ndarray:
    """Mask of initial ball states (x, y, v_x) that pass the serve rules."""
    lo, hi = serve_x_interval(v_x)
    x, y = np.asarray(x, dtype=np.float64), np.asarray(y, dtype=np.float64)
    return (x >= lo) & (x <= hi) & (np.abs(y) <= TABLE_Y_HALF) & (np.asarray(v_x) >= 0)


def trajectory_penalty(theta: np.ndarray, q_d: np.ndarray) -> float:
    """0 for a valid θ, else the (negative) penalty of the module docstring."""
    d_tau, d_delay = SPEC.bound_excess(theta)
    invalid = d_tau > 0 or d_delay > 0 or np.any(q_d > JOINT_HIGH) or np.any(q_d < JOINT_LOW)
    if not invalid:
        return 0.0
    high, low = joint_limit_excess(q_d, JOINT_LOW, JOINT_HIGH)
    return -(3.0 * d_tau + 3.0 * d_delay + high + low)


@numba.njit(cache=False)
def _compiled_loop(
    m_ptr, d_ptr, feedforward, q, dq, ctrl, xpos, xs, found, warnings, bad, ball_xpos, landing
):  # pragma: no cover (numba compiles it; the tests compare it with the Python loop)
    """:meth:`TableTennis4D._python_loop` without the recorders, compiled: the same control
    law, the same ``mj_step`` (MuJoCo's C function on the task's model and data) and the
    same events, read from the contact sensors ``found`` (ball with bat, back of the bat,
    floor, table) instead of the contact list. Writes the body positions of sub-step i to
    ``xs[i]`` and the landing point to ``landing``; returns ``(sub-steps taken, last control
    step, (hit, landed, landed on the table, unstable))``."""
    hit = done = unstable = landed = on_table = False
    i = -1
    k = 0
    for k in range(feedforward.shape[0]):
        for j in range(7):  # (K_p q_d + K_d q̇_d - K_p q) - K_d q̇, as the Python loop
            ctrl[j] = feedforward[k, j] - KP[j] * q[j]
            ctrl[j] = ctrl[j] - KD[j] * dq[j]
        for _ in range(FRAME_SKIP):
            i += 1
            MJ_STEP(m_ptr, d_ptr)
            xs[i] = xpos
            on_bat, on_floor, on_table_now = found[0] + found[1] > 0, found[2] > 0, found[3] > 0
            if not hit:
                hit = on_bat
                if not hit and on_floor:
                    done = True
            if hit and not landed and (on_floor or on_table_now):
                landing[:] = ball_xpos
                landed, on_table, done = True, not on_floor, True
            if done:
                break
        if warnings[bad] > 0:  # MuJoCo reset the state after a divergence
            unstable = True
        if done or unstable:
            break
    return i + 1, k, (hit, landed, on_table, unstable)


class TableTennis4D(EpisodicTask):
    """Table tennis with a 4D context (ball start x/y, goal x/y); see the module docstring."""

    name: ClassVar[str] = "table-tennis-4d"
    context_names: ClassVar[tuple[str, ...]] = ("x_ball0", "y_ball0", "x_goal", "y_goal")
    context_low: ClassVar[np.ndarray] = np.array([-1.0, -0.65, -1.0, -0.65])  # the code's
    context_high: ClassVar[np.ndarray] = np.array([-0.2, 0.65, -0.2, 0.65])
    n_params: ClassVar[int] = SPEC.n_params
    info_keys: ClassVar[tuple[str, ...]] = (
        "hit", "landed", "landing_x", "landing_y", "landing_dist", "min_ball_racket_dist",
        "unstable", "steps",
    )  # fmt: skip
    has_success: ClassVar[bool] = True
    path_names: ClassVar[tuple[str, ...]] = ("ball", "racket")
    spec: ClassVar[ProDMPSpec] = SPEC

    def __init__(
        self, settings: str = "code", floor_counts_as_landing: bool | None = None,
        compiled: bool = True, **kwargs: Any,
    ) -> None:  # fmt: skip
        super().__init__(settings=settings, floor_counts_as_landing=floor_counts_as_landing,
                         compiled=compiled, **kwargs)  # fmt: skip
        if settings not in SETTINGS:
            raise ValueError(f"settings must be one of {SETTINGS}, got {settings!r}")
        #: "code": the authors' goal range and landing rule; "thesis": B.4.1.1's
        self.settings = settings
        if floor_counts_as_landing is None:
            floor_counts_as_landing = settings == "code"
        if not isinstance(floor_counts_as_landing, bool):
            raise TypeError("floor_counts_as_landing must be a bool")
        if settings == "thesis":  # B.4.1.1: goal y in [-0.6, 0.6]
            self.context_low = np.where(np.arange(self.context_dim) == self.context_dim - 1,
                                        -THESIS_GOAL_Y, type(self).context_low)  # fmt: skip
            self.context_high = np.where(np.arange(self.context_dim) == self.context_dim - 1,
                                         THESIS_GOAL_Y, type(self).context_high)  # fmt: skip
        if not isinstance(compiled, bool):
            raise TypeError(f"compiled must be a bool, got {compiled!r}")
        self.floor_counts_as_landing = floor_counts_as_landing
        #: run the sub-step loop compiled (numba) when nothing is recorded; False: in Python
        self.compiled = compiled
        self.model = load_model(MODEL, MODEL_PATCHES)
        if not math.isclose(self.model.opt.timestep, TIMESTEP):
            raise RuntimeError(f"unexpected model timestep {self.model.opt.timestep}")
        self.data = mujoco.MjData(self.model)
        m = self.model

        def gid(name: str) -> int:
            return mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_GEOM, name)

        self._ball_geom = gid("target_ball_contact")
        self._bat_geoms = (gid("bat"), gid("bat_back"))
        self._floor, self._table = gid("floor"), gid("table_tennis_table")
        self._ball_body = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, "target_ball")
        # The bat geom sits at the origin of its body "EE": its centre is that body's xpos.
        self._bat_body = int(m.geom_bodyid[self._bat_geoms[0]])
        assert np.allclose(m.geom_pos[self._bat_geoms[0]], 0.0)
        self._goal_body = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, "target_point")
        self._ball_qadr = int(
            m.jnt_qposadr[mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, "tar_x")]
        )
        if not (
            np.all(m.actuator_ctrllimited[:7])
            and np.allclose(m.actuator_ctrlrange[:7], [-1.0, 1.0])
            and not m.opt.disableflags & mujoco.mjtDisableBit.mjDSBL_CLAMPCTRL
        ):
            raise RuntimeError("the model's motors must clamp ctrl to [-1, 1]")
        adr = [int(m.sensor_adr[m.sensor(f"vslbook_ball_{g}").id]) for g in CONTACT_GEOMS]
        if adr != list(range(adr[0], adr[0] + len(adr))) or m.nu != 7:
            raise RuntimeError(f"{MODEL}: expected 7 motors and the 4 contact sensors in a row")
        self._found = slice(adr[0], adr[0] + len(adr))  # sensordata[self._found]: a view
        self.sim_steps = 0  # physics sub-steps taken by this instance (tests and benchmarks)
        self._xs = np.empty((MAX_STEPS * FRAME_SKIP, m.nbody, 3))  # see simulate()
        self._record: list[np.ndarray] | None = None  # qpos per physics step, see strike()

    # -- contexts -----------------------------------------------------------------------
    def serve(self, context: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(x, y, v_x)`` columns of the initial ball state for contexts ``(n, d)``."""
        c = np.atleast_2d(np.asarray(context, dtype=np.float64))
        return c[:, 0], c[:, 1], np.full(len(c), BALL_VX_4D)

    def goal(self, context: np.ndarray) -> np.ndarray:
        return np.asarray(context, dtype=np.float64)[..., -2:]

    def context_valid(self, contexts: np.ndarray) -> np.ndarray:
        c = np.atleast_2d(np.asarray(contexts, dtype=np.float64))
        ok = super().context_valid(c) & serve_valid(*self.serve(c))
        return ok if np.ndim(contexts) > 1 else ok.reshape(np.shape(contexts)[:-1])

    def context_penalty(self, contexts: np.ndarray) -> np.ndarray:
        """SVSL's guiding punishment R_c(c) = −20 d_c² (B.4.1.1), d_c the Euclidean distance
        of c to the valid contexts: per entry, the excess over the box intersected with
        what the serve rules allow (x ∈ the serve interval of the context's v_x, clipped
        into its range; |y| <= 0.6). With the fixed v_x of the 4D task the valid set is
        this box, so d_c is exact; in the hard task, whose valid (x, v_x) set is not a
        box, it is the distance at the context's own v_x."""
        c = np.atleast_2d(np.asarray(contexts, dtype=np.float64))
        low = np.broadcast_to(self.context_low, c.shape).copy()
        high = np.broadcast_to(self.context_high, c.shape).copy()
        x, _, v_x = self.serve(c)
        ix, iy = self._serve_columns()
        lo, hi = serve_x_interval(np.clip(v_x, 1.5, 4.0))
        low[:, ix], high[:, ix] = np.maximum(low[:, ix], lo), np.minimum(high[:, ix], hi)
        low[:, iy] = np.maximum(low[:, iy], -TABLE_Y_HALF)
        high[:, iy] = np.minimum(high[:, iy], TABLE_Y_HALF)
        excess = np.maximum(low - c, 0.0) + np.maximum(c - high, 0.0)
        out = -20.0 * np.sum(excess**2, axis=-1)
        return out if np.ndim(contexts) > 1 else out.reshape(np.shape(contexts)[:-1])

    def _serve_columns(self) -> tuple[int, int]:
        """The context columns of the ball's initial x and y (``x_ball0``, ``y_ball0``)."""
        return self.context_names.index("x_ball0"), self.context_names.index("y_ball0")

    def describe_contexts(self) -> str:
        return (
            super().describe_contexts()
            + "; the serve must clear the net, land before x = 1.1 and keep |y| <= 0.6"
        )

    # -- episodes -----------------------------------------------------------------------
    def episode(self, theta: np.ndarray, context: np.ndarray) -> Episode:
        theta = np.asarray(theta, dtype=np.float64).reshape(self.n_params)
        context = np.asarray(context, dtype=np.float64).reshape(self.context_dim)
        # control step k tracks the primitive at (k + 1) dt (row 0 is the start state)
        q_d, dq_d = (a[1:] for a in self.spec.trajectory(theta, Q0))
        penalty = trajectory_penalty(theta, q_d)
        if penalty < 0:
            return Episode(penalty, False, False, dict.fromkeys(self.info_keys, math.nan))
        x, y, v_x = (float(a[0]) for a in self.serve(context))
        return self.simulate(q_d, dq_d, np.array([x, y, v_x]), self.goal(context))

    def strike(self, theta: Any, context: Any) -> tuple[Episode, np.ndarray | None]:
        """One episode, and the simulator's ``qpos`` at the moment the ball was closest to the
        racket (``None`` when θ was invalid and nothing was simulated): the frame a picture of
        the strike shows (Fig. 3.3)."""
        theta, context = self.episode_args(theta, context)
        self._record = []
        try:
            episode = self.episode(theta, context)
            frame = self._record[0] if self._record else None
        finally:
            self._record = None
        return episode, frame

    def _start(self, ball0: np.ndarray, goal: np.ndarray) -> None:
        """Robot at rest in q0, the goal marker on the table, the ball served from ``ball0``."""
        m, d = self.model, self.data
        mujoco.mj_resetData(m, d)
        m.body_pos[self._goal_body] = [goal[0], goal[1], TABLE_HEIGHT]
        d.qpos[:7] = Q0
        a = self._ball_qadr
        d.qpos[a : a + 3] = [ball0[0], ball0[1], BALL_Z0]
        d.qvel[a : a + 3] = [ball0[2], 0.0, BALL_VZ]
        mujoco.mj_forward(m, d)

    def scene(self, context: Any) -> tuple[mujoco.MjModel, mujoco.MjData]:
        """The start of an episode in ``context``: ball at its serve, goal marked (see the
        base class)."""
        c = self.one_context(context)
        x, y, v_x = (float(a[0]) for a in self.serve(c))
        self._start(np.array([x, y, v_x]), self.goal(c))
        return self.model, self.data

    def simulate(
        self, q_d: np.ndarray, dq_d: np.ndarray, ball0: np.ndarray, goal: np.ndarray
    ) -> Episode:
        """Track ``(q_d, q̇_d)`` ``(≥350, 7)`` with the ball served from ``ball0`` = (x, y, v_x).

        The sub-step loop runs compiled (:func:`_compiled_loop`); while a path or the strike
        frame is recorded (Python callbacks in the loop) it runs as Python
        (:meth:`_python_loop`), the plain reading the tests hold the compiled loop to.
        """
        self._start(ball0, goal)
        # u = K_p q_d + K_d q̇_d - K_p q - K_d q̇; the clip to [-1, 1] is MuJoCo's own ctrl
        # clamping (ctrlrange of the motors, checked in __init__).
        feedforward = KP * q_d[:MAX_STEPS] + KD * dq_d[:MAX_STEPS]
        if self._record is None and self._recorder is None and self.compiled:
            i, k, hit, landing, landed_on_table, unstable = self._run_compiled(feedforward)
        else:
            i, k, hit, landing, landed_on_table, unstable = self._python_loop(feedforward)
        xs = self._xs
        record = self._record
        self.sim_steps += i
        ball, racket = xs[:i, self._ball_body], xs[:i, self._bat_body]
        diff = ball - racket
        d2 = np.einsum("ij,ij->i", diff, diff)
        if record is not None:  # keep the physics step where ball and racket were closest
            record[:] = [record[int(np.argmin(d2))]]
        counted = landing if landed_on_table or self.floor_counts_as_landing else None
        dist = float(np.linalg.norm(landing[:2] - goal)) if landing is not None else math.nan
        ret = UNSTABLE_RETURN if unstable else staged_reward(ball, racket, goal, hit, counted)
        success = bool(
            not unstable and landed_on_table and landing[0] < 0.0 and dist < SUCCESS_RADIUS
        )
        info = {
            "hit": float(hit),
            "landed": float(landed_on_table),
            "landing_x": float(landing[0]) if landing is not None else math.nan,
            "landing_y": float(landing[1]) if landing is not None else math.nan,
            "landing_dist": dist,
            "min_ball_racket_dist": float(np.sqrt(np.min(d2))),
            "unstable": float(unstable),
            "steps": float(k + 1),
        }
        return Episode(float(ret), success, True, info)

    def _run_compiled(
        self, feedforward: np.ndarray
    ) -> tuple[int, int, bool, np.ndarray | None, bool, bool]:
        """:func:`_compiled_loop` on this task's model and data (see :meth:`_python_loop`)."""
        m, d = self.model, self.data
        landing = np.empty(3)
        n, k, flags = _compiled_loop(
            m._address, d._address, feedforward, d.qpos[:7], d.qvel[:7], d.ctrl, d.xpos,
            self._xs, d.sensordata[self._found], d.warning.number,
            int(mujoco.mjtWarning.mjWARN_BADQACC), d.geom_xpos[self._ball_geom], landing,
        )  # fmt: skip
        hit, landed, on_table, unstable = (bool(f) for f in flags)
        return n, k, hit, landing if landed else None, on_table, unstable

    def _python_loop(
        self, feedforward: np.ndarray
    ) -> tuple[int, int, bool, np.ndarray | None, bool, bool]:
        """The episode's control and sub-step loop in Python, with the path and strike-frame
        recorders: after every sub-step the body positions go to row i of ``self._xs`` and
        the contacts are read from MuJoCo's contact list. Returns ``(sub-steps taken, last
        control step, hit, landing point or None, landed on the table, unstable)``."""
        m, d = self.model, self.data
        xs = self._xs
        xpos, qpos, qvel, ctrl = d.xpos, d.qpos, d.qvel, d.ctrl
        q, dq, tmp = qpos[:7], qvel[:7], np.empty(7)
        warnings, bad = d.warning.number, int(mujoco.mjtWarning.mjWARN_BADQACC)
        ball_geom, bats = self._ball_geom, self._bat_geoms
        floor, table = self._floor, self._table
        hit = unstable = done = False
        landing: np.ndarray | None = None
        landed_on_table = False
        i = k = 0
        record, path = self._record, self._recorder
        step, sub, mul = mujoco.mj_step, np.subtract, np.multiply
        if path is not None:
            path(ball=xpos[self._ball_body], racket=xpos[self._bat_body])
        for k in range(MAX_STEPS):
            sub(feedforward[k], mul(KP, q, tmp), ctrl)  # in place: (K_p q_d + K_d q̇_d - K_p q)
            sub(ctrl, mul(KD, dq, tmp), ctrl)  # - K_d q̇
            for i in range(FRAME_SKIP * k, FRAME_SKIP * (k + 1)):  # rows of xs
                if record is not None:  # the state whose positions mj_step leaves in xpos
                    record.append(qpos.copy())
                step(m, d)
                xs[i] = xpos
                if d.ncon:
                    pairs = d.contact.geom[: d.ncon]
                    rows = pairs[(pairs == ball_geom).any(axis=1)]
                    others = set(rows.ravel().tolist()) - {ball_geom}
                    if not hit:
                        hit = bool(others & set(bats))
                        if not hit and floor in others:
                            done = True
                    if hit and landing is None:
                        if floor in others or table in others:
                            landing = d.geom_xpos[ball_geom].copy()
                            landed_on_table = floor not in others
                            done = True
                    if done:
                        break
            if warnings[bad] > 0:  # MuJoCo reset the state after a divergence
                unstable = True
            elif path is not None:
                path(ball=xpos[self._ball_body], racket=xpos[self._bat_body])
            if done or unstable:
                break
        return i + 1, k, hit, landing, landed_on_table, unstable

class TableTennisHard(TableTennis4D):
    """Table Tennis Hard (B.4.1.2): the context adds the serve speed v_x ∈ [1.5, 4] m/s."""

    name: ClassVar[str] = "table-tennis-hard"
    context_names: ClassVar[tuple[str, ...]] = ("x_ball0", "y_ball0", "v_x", "x_goal", "y_goal")
    context_low: ClassVar[np.ndarray] = np.array([-1.0, -0.65, 1.5, -1.0, -0.65])
    context_high: ClassVar[np.ndarray] = np.array([-0.2, 0.65, 4.0, -0.2, 0.65])

    def serve(self, context: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        c = np.atleast_2d(np.asarray(context, dtype=np.float64))
        return c[:, 0], c[:, 1], c[:, 2]
