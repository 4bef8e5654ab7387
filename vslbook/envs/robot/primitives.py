"""θ → desired joint trajectory for the robot tasks: ProDMP with learned duration and start
time, ProMP with a learned duration, and the bounds checks done before simulation.

The parameter layout follows the thesis's counts (Sections 3.4, 4.5.1; Appendices A.3, B.4):
``[τ (if learned), delay (if learned), weights (dof-major, n_basis per dof), goal per dof
(if learned)]``. The trajectory is sampled on the control grid ``0, dt, ..., duration``.
Before the start time (``delay``) the robot holds its initial position; from then on the
ProDMP of :mod:`vslbook.movement` runs with temporal scaling τ, starting at rest from the
initial position, and keeps converging to its goal after τ.

``auto_scale_basis`` divides each weight's basis function by its largest absolute value on
the grid, so weights of different basis functions move the trajectory by similar amounts;
``weights_scale`` and ``goal_scale`` multiply the weights and the goal offsets.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from vslbook.movement import ProDMP, ProMP

GOAL_MODES = ("learned", "relative", "disabled")


@dataclass(frozen=True)
class ProDMPSpec:
    """A task's ProDMP: how θ is laid out and turned into ``(q_d, q̇_d)``.

    Attributes:
        n_dof, n_basis: joints and forcing basis functions per joint.
        dt: control time step (the trajectory grid), duration: episode length in seconds.
        alpha: spring-damper constant, alpha_phase: decay of the canonical phase.
        tau: τ when it is not learned; tau_bounds: (low, high) when it is (θ[0]).
        delay_bounds: (low, high) when the start time is learned (θ after τ).
        goal: ``"learned"`` (absolute goal per joint in θ), ``"relative"`` (goal = q0 + g
            with g in θ) or ``"disabled"`` (goal = q0, no goal parameters).
        width: basis width in units of t/τ (None: the centres' spacing).
    """

    n_dof: int
    n_basis: int
    dt: float
    duration: float
    alpha: float = 25.0
    alpha_phase: float = 3.0
    tau: float = 1.0
    tau_bounds: tuple[float, float] | None = None
    delay_bounds: tuple[float, float] | None = None
    goal: str = "learned"
    weights_scale: float = 1.0
    goal_scale: float = 1.0
    auto_scale_basis: bool = True
    width: float | None = None

    def __post_init__(self) -> None:
        if self.goal not in GOAL_MODES:
            raise ValueError(f"goal must be one of {GOAL_MODES}, got {self.goal!r}")

    @property
    def n_params(self) -> int:
        goal = 0 if self.goal == "disabled" else self.n_dof
        return (
            int(self.tau_bounds is not None)
            + int(self.delay_bounds is not None)
            + self.n_dof * self.n_basis
            + goal
        )

    @property
    def n_steps(self) -> int:
        """Control steps in an episode (the grid has ``n_steps + 1`` points)."""
        return int(round(self.duration / self.dt))

    def split(self, theta: np.ndarray) -> tuple[float, float, np.ndarray, np.ndarray | None]:
        """``(τ, delay, weights (n_dof, n_basis), goal parameters or None)``, unclipped."""
        theta = np.asarray(theta, dtype=np.float64)
        if theta.shape != (self.n_params,):
            raise ValueError(f"theta must have shape ({self.n_params},), got {theta.shape}")
        i = 0
        tau, delay = self.tau, 0.0
        if self.tau_bounds is not None:
            tau, i = float(theta[0]), 1
        if self.delay_bounds is not None:
            delay, i = float(theta[i]), i + 1
        k = self.n_dof * self.n_basis
        weights = theta[i : i + k].reshape(self.n_dof, self.n_basis)
        goal = None if self.goal == "disabled" else theta[i + k :]
        return tau, delay, weights, goal

    def bound_excess(self, theta: np.ndarray) -> tuple[float, float]:
        """How far τ and the delay lie outside their bounds (0 inside)."""
        tau, delay, _, _ = self.split(theta)
        return _excess(tau, self.tau_bounds), _excess(delay, self.delay_bounds)

    def trajectory(
        self, theta: np.ndarray, q0: np.ndarray, dq0: np.ndarray | None = None
    ) -> tuple[np.ndarray, np.ndarray]:
        """Desired positions and velocities, each ``(n_steps + 1, n_dof)``.

        τ and the delay are clipped to their bounds here (the validity check uses the
        unclipped values, :meth:`bound_excess`).
        """
        q0 = np.asarray(q0, dtype=np.float64).reshape(self.n_dof)
        dq0 = (
            np.zeros(self.n_dof)
            if dq0 is None
            else np.asarray(dq0, dtype=np.float64).reshape(self.n_dof)
        )
        tau, delay, w, g = self.split(theta)
        if self.tau_bounds is not None:
            tau = float(np.clip(tau, *self.tau_bounds))
        if self.delay_bounds is not None:
            delay = float(np.clip(delay, *self.delay_bounds))
        n = self.n_steps
        start = int(round(delay / self.dt))
        q = np.repeat(q0[None], n + 1, axis=0)
        dq = np.zeros((n + 1, self.n_dof))
        if start >= n:
            return q, dq
        dmp, peak = _prodmp(
            self.n_basis, self.n_dof, (n - start) * self.dt, self.dt, self.alpha, tau,
            self.alpha_phase, self.width,
        )  # fmt: skip
        w = w * self.weights_scale
        if self.auto_scale_basis:
            w = w / peak
        if self.goal == "learned":
            goal = g * self.goal_scale
        elif self.goal == "relative":
            goal = q0 + g * self.goal_scale
        else:
            goal = q0
        params = np.concatenate([w, goal[:, None]], axis=1).reshape(-1)
        start_vel = dq0 if start == 0 else np.zeros(self.n_dof)
        pos, vel = dmp.trajectory_numpy(params, q0, start_vel)
        q[start:] = pos[: n + 1 - start]
        dq[start:] = vel[: n + 1 - start]
        return q, dq


@lru_cache(maxsize=16)
def _prodmp(
    n_basis: int,
    n_dof: int,
    duration: float,
    dt: float,
    alpha: float,
    tau: float,
    alpha_phase: float,
    width: float | None,
) -> tuple[ProDMP, np.ndarray]:
    """The ProDMP of one (duration, τ) and its basis functions' largest absolute values on
    the grid (1 where a basis function is zero everywhere).

    Building the basis integrates it numerically (about a millisecond); a task whose τ and
    start time are fixed builds it once. A :class:`ProDMP` is not changed by its use.
    """
    dmp = ProDMP(
        n_basis, n_dof, duration=duration, dt=dt, alpha=alpha, tau=tau, alpha_x=alpha_phase,
        width=width,
    )  # fmt: skip
    peak = np.abs(dmp.basis_matrix()[:, :n_basis].numpy()).max(axis=0)
    return dmp, np.where(peak > 0, peak, 1.0)


def promp_trajectory(
    weights: np.ndarray, duration: float, dt: float, q0: np.ndarray, width: float | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """ProMP positions ``q0 + Φ(t/duration)ᵀ w`` and velocities on ``0, dt, ..., duration``.

    ``weights`` is ``(n_dof, n_basis)``; used by the Chapter 3 tasks whose θ holds a
    movement duration and ProMP weights added to the start posture.
    """
    weights = np.asarray(weights, dtype=np.float64)
    n_dof, n_basis = weights.shape
    mp = _promp(n_basis, n_dof, float(duration), float(dt), width)
    pos, vel = mp.trajectory_numpy(weights.reshape(-1))
    return q0 + pos, vel


@lru_cache(maxsize=256)
def _promp(n_basis: int, n_dof: int, duration: float, dt: float, width: float | None) -> ProMP:
    """The ProMP of one duration, built once: a task whose duration lies on the control grid
    (beer pong: n·dt) reuses it; a ProMP is not changed by its use."""
    return ProMP(n_basis, n_dof, duration=duration, dt=dt, width=width)


def _excess(value: float, bounds: tuple[float, float] | None) -> float:
    if bounds is None:
        return 0.0
    return float(max(bounds[0] - value, 0.0) + max(value - bounds[1], 0.0))


def joint_limit_excess(q: np.ndarray, low: np.ndarray, high: np.ndarray) -> tuple[float, float]:
    """Mean excess of a desired trajectory ``(T, n_dof)`` above ``high`` and below ``low``."""
    return float(np.mean(np.maximum(q - high, 0.0))), float(np.mean(np.maximum(low - q, 0.0)))
