"""Robot table tennis of Chapter 3 (thesis Section 3.4.2, Fig. 3.2d / 3.3; Appendix A.3.3).

A 7-DoF Barrett WAM with a bat returns a served ball to a desired landing point on the
opponent's side; θ is a ProMP with a learned movement duration. The simulation (model,
serve, motors, PD law, contacts, termination, staged reward, success) is the one of the
Chapter 4 task :class:`~vslbook.envs.robot.table_tennis.TableTennis4D`, reused by
inheritance; this module changes the context order and ranges, the movement primitive and
the punishments to those of A.3.3.

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
    (:func:`vslbook.envs.robot.table_tennis.staged_reward`). An unstable simulation returns
    -25 (executed, unsuccessful), as in the Chapter 4 task.

Punishments (A.3.3; such samples are not simulated and not counted, ``executed=False``)
    * context outside the valid set (``evaluate(..., out_of_range="penalise")``):
      R_c = -20 d_c², d_c the Euclidean distance of c to the valid box;
    * duration l < 0.1: -3 |l - 0.1|;  l > 5: -3 |l - 5|  (checked first);
    * planned trajectory outside the joint limits low = [-2.6, -2.0, -2.8, -0.9, -4.8, -1.6,
      -2.2], high = [2.6, 2.0, 2.8, 3.1, 1.3, 1.6, 2.2]:
      -(1/T) Σ_t d_qpos,t, d_qpos,t = ‖max(q_d,t - high, 0) + max(low - q_d,t, 0)‖₂ the
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
    * Punishments follow the thesis, not the authors' code (which adds -1 to the duration
      punishment, uses -20 Σ|violation| for the context and the mean per-entry excess for
      the joints). d_qpos,t is read as the Euclidean distance of q_d,t to the joint box.
      When l is out of range only the duration punishment is given (no trajectory exists).
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
    TABLE_Y_HALF,
    TableTennis4D,
    serve_x_interval,
)
from vslbook.envs.robot.task import Episode

N_DOF, N_BASIS = 7, 3
DURATION_BOUNDS = (0.1, 5.0)
DURATION_WEIGHT = 3.0
CONTEXT_WEIGHT = 20.0
SERVE_VX = BALL_VX_4D  # the fixed serve speed (m/s)

_X_INC_MIN, _X_INC_MAX = (float(v) for v in serve_x_interval(SERVE_VX))


def duration_penalty(duration: float) -> float:
    """A.3.3's R_θ: -3|l - 0.1| for l < 0.1, -3|l - 5| for l > 5, else 0."""
    lo, hi = DURATION_BOUNDS
    if duration < lo:
        return -DURATION_WEIGHT * abs(duration - lo)
    if duration > hi:
        return -DURATION_WEIGHT * abs(duration - hi)
    return 0.0


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


def joint_limit_penalty(q_d: np.ndarray) -> float:
    """A.3.3's -(1/T) Σ_t d_qpos,t: minus the mean distance of the planned postures to the
    joint box (0 when every posture is inside)."""
    q_d = np.asarray(q_d, dtype=np.float64)
    excess = np.maximum(q_d - JOINT_HIGH, 0.0) + np.maximum(JOINT_LOW - q_d, 0.0)
    return -float(np.mean(np.linalg.norm(excess, axis=-1)))


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
        floor_counts_as_landing: count a first floor contact after the hit as a landing
            (the authors' code) instead of cond. 2 (the thesis, default).
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

    def __init__(self, floor_counts_as_landing: bool = False, **kwargs: Any) -> None:
        super().__init__(floor_counts_as_landing=floor_counts_as_landing, **kwargs)

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
        """A.3.3's R_c = -20 d_c², d_c the distance of c to the valid box."""
        c = np.asarray(contexts, dtype=np.float64)
        excess = np.maximum(self.valid_low - c, 0.0) + np.maximum(c - self.valid_high, 0.0)
        return -CONTEXT_WEIGHT * np.sum(excess**2, axis=-1)

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
        pen = duration_penalty(duration)
        if pen != 0.0:
            return Episode(pen, False, False, {"duration": duration})
        q_plan, dq_plan = planned_trajectory(theta)
        pen = joint_limit_penalty(q_plan)
        if pen != 0.0:
            return Episode(pen, False, False, {"duration": duration})
        q_d, dq_d = hold_end(q_plan, dq_plan)
        x, y, v_x = (float(a[0]) for a in self.serve(context))
        ep = self.simulate(q_d, dq_d, np.array([x, y, v_x]), self.goal(context))
        ep.info["duration"] = duration
        return ep
