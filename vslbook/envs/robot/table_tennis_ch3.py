"""Robot table tennis of Chapter 3 (thesis Section 3.4.2, Fig. 3.2d / 3.3; Appendix A.3.3).

A 7-DoF Barrett WAM with a bat returns a served ball to a desired landing point on the
opponent's side; θ is a ProMP with a learned movement duration. The simulation (model,
serve, motors, PD law, contacts, termination, staged reward, success) is the one of the
Chapter 4 task :class:`~vslbook.envs.robot.table_tennis.TableTennis4D`, reused by
inheritance; this module changes the context order and ranges and the movement primitive to
those of A.3.3, and the punishments to the authors' SVSL code's (A.3.3's with
``settings="thesis"``).

Context (A.3.3, in this order: goal first)
    c = [b_des, b_inc] = [x_des, y_des, x_inc, y_inc], with x_des ∈ [-1.2, -0.2],
    y_des ∈ [-0.6, 0.6], x_inc ∈ [-1.2, -0.2], y_inc ∈ [-0.65, 0.65]. b_des is the desired
    landing point of the returned ball, b_inc the incoming ball's initial x/y position
    (the Chapter 4 task puts the ball first). The serve is fixed, so b_inc maps 1:1 to the
    ball's landing point on the robot's side. A context is valid when it lies in the box and
    the serve clears the net and lands on the robot's side (the rules of
    :func:`~vslbook.envs.robot.table_tennis.serve_valid`): with the serve below this leaves
    x_inc ∈ [-1.2, -0.2074] and |y_inc| <= 0.6. The valid set is therefore itself a box
    (:attr:`TableTennisCh3.valid_low`, :attr:`TableTennisCh3.valid_high`).

Parameters (22 = 1 + 7 × 3)
    θ = [l, w_1,1, w_1,2, w_1,3, ..., w_7,3]: the movement duration l in seconds first (the
    package's layout, as in :mod:`vslbook.envs.robot.beer_pong`), then three ProMP weights per
    joint, joint-major, in radians. The planned trajectory on the control grid
    t_k = k·dt, k = 0, ..., n = round(l / dt), is (Eq. 2.46)

        q_d(t) = q0 + (Φ(t / l) - Φ(0))ᵀ w_j   for each joint j,

    Φ the three normalised RBFs of :class:`vslbook.movement.ProMP` (centres 0, ½, 1 on the
    phase s = t / l, width ½), so q_d(0) = q0 = [0, 0, 0, 1.5, 0, 0, 1.5], the robot's rest
    posture; q̇_d = Φ'(t / l)ᵀ w / l. After t_n the end posture q_d(t_n) is held with
    q̇_d = 0 until the episode ends (at most 350 control steps, 2.8 s).

Controller and simulation (as the Chapter 4 task)
    fancy-gym's ``table_tennis_env.xml`` with its motors (ctrl ∈ [-1, 1], gears 150, 125,
    40, 60, 5, 5, 2), ``u = clip(K_p (q_d - q) + K_d (q̇_d - q̇), -1, 1)`` with
    K_p = 0.5·[1, 4, 2, 4, 1, 4, 1], K_d = 0.1·K_p, dt = 0.008 s (4 physics steps of 2 ms).
    The ball starts at (x_inc, y_inc, 1.75) (joint coordinates) with velocity (2.5, 0, 0.5).
    The episode ends after 350 control steps, when the ball touches the floor before any
    racket contact, or, after a racket contact, at the ball's first table or floor contact.

Reward (A.3.3; only for an executed episode), d_r = min_t ‖b_t - r_t‖, g = b_des:
    cond. 1, no racket contact:                0.2 (1 - tanh(d_r²))
    cond. 2, racket contact, no table contact: 2 (1 - tanh(d_r²)) + (1 - tanh(min_t ‖b_t,xy - g‖²))
    cond. 3, racket contact, then table:       2 (1 - tanh(d_r²)) + 4 (1 - tanh(‖b_land - g‖²))
                                               + 1[x_land < 0]
    (:func:`vslbook.envs.robot.table_tennis_reward.staged_reward`). An unstable simulation returns
    -25 (executed, unsuccessful), as in the Chapter 4 task.

Punishments (such samples are not simulated and not counted, ``executed=False``; A.3.3)
    ``settings="code"`` (default) gives the authors' SVSL_LMOE code's, which drew Fig. 3.2b, d
    and Fig. 3.3 (``util/table_tennis/utils/hierarchical_reward.py``; CH3_CH4_FACTS §1.1);
    ``settings="thesis"`` gives A.3.3's; ``punishments="code"|"thesis"`` overrides the
    settings for the punishments alone. With e = max(low - x, 0) + max(x - high, 0) the
    excess of x over a box [low, high], entry by entry:

    * context outside the valid set (``evaluate(..., out_of_range="penalise")``), checked
      first: code -20 Σ_i e_i (``context_invalid_punishment``: -20 × the summed absolute
      violations); thesis R_c = -20 d_c², d_c the Euclidean distance to the valid box;
    * duration l outside [0.1, 5] s (both bounds allowed), checked second: code
      -3 |l - b| - 1 (``action_durations_valid_upper_lower_bound_valid``), thesis R_θ =
      -3 |l - b|, b the violated bound;
    * planned trajectory outside the joint limits low = [-2.6, -2.0, -2.8, -0.9, -4.8, -1.6,
      -2.2], high = [2.6, 2.0, 2.8, 3.1, 1.3, 1.6, 2.2], checked last: code
      -(mean of (q_d,t,j - high_j) over the entries above high + mean of (low_j - q_d,t,j)
      over the entries below low), each mean 0 where no entry violates
      (``joint_motion_mean_minus_penalty``); thesis -(1/T) Σ_t d_qpos,t, d_qpos,t = ‖e_t‖₂ the
      Euclidean distance of the planned posture at t_k to the joint box, averaged over the
      T = n + 1 points of the planned trajectory on [0, t_n].

Success (as the Chapter 4 task defines it; the thesis gives no success rule for Ch. 3): the
returned ball lands on the table at x < 0 (the opponent's side) within 0.2 m of b_des.

What had to be interpreted
    * Simulator and constants. The authors' Chapter 3 environment (mujoco-py, their own
      model with position actuators) is not used. The model, motors, PD gains, time step,
      episode length (2.8 s), termination and the -25 for an unstable simulation are the
      Chapter 4 task's, so both chapters' table tennis share one simulation.
    * Serve. The authors' Chapter 3 code starts the ball at z = 1.76 with velocity
      (2.5, 0, 1). We keep the Chapter 4 serve, z = 1.75 and (2.5, 0, 0.5): with it the serve
      rules accept x_inc ∈ [-1.2021, -0.2074], i.e. almost exactly the thesis's range
      [-1.2, -0.2], whereas v_z = 1 would reject every x_inc > -0.36 (the ball would fly
      past the table's end). Contexts in the thesis's box that the serve rules reject
      (x_inc > -0.2074 or |y_inc| > 0.6) are not part of p(c).
    * Movement primitive. Three normalised RBFs per joint over [0, l] (the authors' count),
      offset so the plan starts at q0 (the thesis says only "ProMPs"; the authors blend from
      q0 with a sigmoid). After l the end posture is held; the authors' code instead
      decelerates uniformly for 2 s. Holding keeps the planned trajectory (and its joint
      check) on [0, l]. Weights are in radians (no weight scaling). The phase uses the exact
      l; the grid's last point t_n = round(l / dt)·dt may differ from l by up to dt/2.
    * Punishments. The authors' code is the default (see above); where our task differs
      from theirs, their formula is applied to ours: the context's excess is measured to the
      valid box (the code measures it to the A.3.3 box, which its serve does not narrow; in
      ours the serve rules narrow it by 7.4 mm in x_inc and 0.05 in |y_inc|), and the joint
      check sees the planned trajectory on [0, t_n] (the code checks its whole reference,
      the sigmoid-blended plan on [0, l) followed by its 2 s deceleration tail). The facts
      file names the code's formulas but not these two points; they were read in the code
      (SVSL_LMOE@52b5404). For the thesis's version d_qpos,t is read as the Euclidean
      distance of q_d,t to the joint box. In both, when l is out of range only the duration
      punishment is given (no trajectory exists), as in the code.
    * A planned trajectory longer than the episode (l > 2.8 s) is checked on all of [0, l]
      but executed only for 2.8 s.
    * cond. 3 requires table contact (thesis); a first floor contact after the hit falls in
      cond. 2 (``floor_counts_as_landing=True`` gives the Chapter 4 code's rule).
"""

from __future__ import annotations

import math
from typing import Any, ClassVar

import numpy as np

from vslbook.envs.robot.primitives import promp_trajectory
from vslbook.envs.robot.table_tennis import (
    BALL_VX_4D,
    DT,
    JOINT_HIGH,
    JOINT_LOW,
    MAX_STEPS,
    Q0,
    SETTINGS,
    TABLE_Y_HALF,
    TableTennis4D,
    serve_x_interval,
)
from vslbook.envs.robot.task import Episode

N_DOF, N_BASIS = 7, 3
DURATION_BOUNDS = (0.1, 5.0)
DURATION_WEIGHT = 3.0
#: the constant the authors' code adds to the duration punishment (A.3.3 has none)
DURATION_OFFSET = 1.0
CONTEXT_WEIGHT = 20.0
#: Where the punishments come from: the authors' SVSL code (default) or A.3.3.
PUNISHMENTS = SETTINGS
SERVE_VX = BALL_VX_4D  # the fixed serve speed (m/s)

_X_INC_MIN, _X_INC_MAX = (float(v) for v in serve_x_interval(SERVE_VX))


def check_punishments(punishments: str) -> str:
    """``punishments`` if it is one of :data:`PUNISHMENTS`, else a ValueError naming both."""
    if not isinstance(punishments, str) or punishments not in PUNISHMENTS:
        raise ValueError(f"punishments must be one of {PUNISHMENTS}, got {punishments!r}")
    return punishments


def duration_penalty(duration: float, punishments: str = "code") -> float:
    """R_θ for l outside [0.1, 5] s, b the violated bound: -3|l - b| - 1 (the authors' code,
    ``"code"``) or -3|l - b| (A.3.3, ``"thesis"``); 0 inside (bounds included)."""
    check_punishments(punishments)
    lo, hi = DURATION_BOUNDS
    if duration < lo:
        pen = -DURATION_WEIGHT * abs(duration - lo)
    elif duration > hi:
        pen = -DURATION_WEIGHT * abs(duration - hi)
    else:
        return 0.0
    return pen - DURATION_OFFSET if punishments == "code" else pen


def planned_trajectory(theta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The ProMP plan (Eq. 2.46) ``(q_d, q̇_d)``, each ``(n + 1, 7)`` on t_k = k·dt, k <= n.

    ``q_d(t) = q0 + (Φ(t/l) - Φ(0))ᵀ w`` with n = round(l / dt); ``theta = [l, w (7 × 3)]``
    must hold a positive duration (see :func:`duration_penalty`).
    """
    theta = np.asarray(theta, dtype=np.float64)
    if theta.shape != (1 + N_DOF * N_BASIS,):
        raise ValueError(f"theta must have shape ({1 + N_DOF * N_BASIS},), got {theta.shape}")
    duration = float(theta[0])
    if not (math.isfinite(duration) and duration >= DT):
        raise ValueError(f"the duration theta[0] must be at least dt = {DT} s, got {duration}")
    w = theta[1:].reshape(N_DOF, N_BASIS)
    q, dq = promp_trajectory(w, duration, DT, Q0)
    return q - (q[0] - Q0), dq


def joint_limit_penalty(q_d: np.ndarray, punishments: str = "code") -> float:
    """The punishment of planned postures ``q_d`` ``(T, 7)`` outside the joint box, 0 when
    every posture is inside.

    ``"code"`` (the authors'): -(mean of q - high over the entries above high + mean of
    low - q over the entries below low), each mean 0 without such entries. ``"thesis"``
    (A.3.3): -(1/T) Σ_t d_qpos,t, d_qpos,t the Euclidean distance of posture t to the box.
    """
    check_punishments(punishments)
    q_d = np.asarray(q_d, dtype=np.float64)
    high = np.maximum(q_d - JOINT_HIGH, 0.0)
    low = np.maximum(JOINT_LOW - q_d, 0.0)
    if punishments == "thesis":
        return -float(np.mean(np.linalg.norm(high + low, axis=-1)))
    return -sum(float(np.mean(e[e > 0])) if np.any(e > 0) else 0.0 for e in (high, low))


def hold_end(
    q_d: np.ndarray, dq_d: np.ndarray, n_steps: int = MAX_STEPS
) -> tuple[np.ndarray, np.ndarray]:
    """The executed reference: the plan, then its end posture held (q̇_d = 0), at least
    ``n_steps + 1`` rows."""
    extra = max(n_steps + 1 - len(q_d), 0)
    q = np.concatenate([q_d, np.repeat(q_d[-1:], extra, axis=0)])
    dq = np.concatenate([dq_d, np.zeros((extra, q_d.shape[1]))])
    return q, dq


class TableTennisCh3(TableTennis4D):
    """Table tennis of Section 3.4.2 / A.3.3 (see the module docstring for every detail).

    Args:
        settings: ``"code"`` (default): the authors' SVSL code's punishments, which drew
            Fig. 3.2b, d; ``"thesis"``: A.3.3's.
        punishments: ``"code"`` or ``"thesis"``; None: the one of ``settings``.
        floor_counts_as_landing: count a first floor contact after the hit as a landing
            (the Chapter 4 authors' code) instead of cond. 2 (default: A.3.3 and the SVSL
            code both score it without a landing). Not tied to ``settings``.
    """

    name: ClassVar[str] = "table-tennis-ch3"
    context_names: ClassVar[tuple[str, ...]] = ("x_des", "y_des", "x_inc", "y_inc")
    context_low: ClassVar[np.ndarray] = np.array([-1.2, -0.6, -1.2, -0.65])
    context_high: ClassVar[np.ndarray] = np.array([-0.2, 0.6, -0.2, 0.65])
    #: The valid contexts: the box intersected with the serve rules (a box, v_x is fixed).
    valid_low: ClassVar[np.ndarray] = np.array([-1.2, -0.6, max(-1.2, _X_INC_MIN), -TABLE_Y_HALF])
    valid_high: ClassVar[np.ndarray] = np.array([-0.2, 0.6, min(-0.2, _X_INC_MAX), TABLE_Y_HALF])
    n_params: ClassVar[int] = 1 + N_DOF * N_BASIS
    info_keys: ClassVar[tuple[str, ...]] = TableTennis4D.info_keys + ("duration",)
    spec: ClassVar[None] = None  # type: ignore[assignment]  # a ProMP, not the ProDMP spec

    def __init__(
        self, settings: str = "code", punishments: str | None = None,
        floor_counts_as_landing: bool = False, **kwargs: Any,
    ) -> None:  # fmt: skip
        if not isinstance(settings, str) or settings not in SETTINGS:
            raise ValueError(f"settings must be one of {SETTINGS}, got {settings!r}")
        punishments = check_punishments(settings if punishments is None else punishments)
        super().__init__(settings=settings, punishments=punishments,
                         floor_counts_as_landing=floor_counts_as_landing, **kwargs)  # fmt: skip
        # TableTennis4D's settings="thesis" narrows B.4.1.1's goal y (its last context
        # entry); here the last entry is y_inc, whose range A.3.3 and the code agree on.
        self.context_low, self.context_high = type(self).context_low, type(self).context_high
        #: "code": the authors' punishments (default); "thesis": A.3.3's
        self.settings, self.punishments = settings, punishments

    # -- contexts -----------------------------------------------------------------------
    def serve(self, context: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(x, y, v_x)`` of the initial ball state for contexts ``(n, 4)`` (b_inc is last)."""
        c = np.atleast_2d(np.asarray(context, dtype=np.float64))
        return c[:, 2], c[:, 3], np.full(len(c), SERVE_VX)

    def goal(self, context: np.ndarray) -> np.ndarray:
        """b_des, the first two context entries."""
        return np.asarray(context, dtype=np.float64)[..., :2]

    def context_valid(self, contexts: np.ndarray) -> np.ndarray:
        c = np.asarray(contexts, dtype=np.float64)
        return np.all((c >= self.valid_low) & (c <= self.valid_high), axis=-1)

    def context_penalty(self, contexts: np.ndarray) -> np.ndarray:
        """The punishment of contexts outside the valid box: -20 Σ_i e_i (the authors' code)
        or A.3.3's R_c = -20 d_c² = -20 Σ_i e_i² (``punishments="thesis"``), e the entries'
        excess over the box."""
        c = np.asarray(contexts, dtype=np.float64)
        excess = np.maximum(self.valid_low - c, 0.0) + np.maximum(c - self.valid_high, 0.0)
        if self.punishments == "thesis":
            excess = excess**2
        return -CONTEXT_WEIGHT * np.sum(excess, axis=-1)

    def describe_contexts(self) -> str:
        return (
            super().describe_contexts()
            + f"; the serve must clear the net and land on the table (x_inc <= {_X_INC_MAX:.4f}"
            f", |y_inc| <= {TABLE_Y_HALF})"
        )

    # -- episodes -----------------------------------------------------------------------
    def episode(self, theta: np.ndarray, context: np.ndarray) -> Episode:
        theta, context = self.episode_args(theta, context)
        duration = float(theta[0])
        pen = duration_penalty(duration, self.punishments)
        if pen != 0.0:
            return Episode(pen, False, False, {"duration": duration})
        q_plan, dq_plan = planned_trajectory(theta)
        pen = joint_limit_penalty(q_plan, self.punishments)
        if pen != 0.0:
            return Episode(pen, False, False, {"duration": duration})
        q_d, dq_d = hold_end(q_plan, dq_plan)
        x, y, v_x = (float(a[0]) for a in self.serve(context))
        ep = self.simulate(q_d, dq_d, np.array([x, y, v_x]), self.goal(context))
        ep.info["duration"] = duration
        return ep
