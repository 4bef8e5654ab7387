"""θ → desired joint trajectory for the robot tasks: ProDMP with learned duration and start
time, ProMP with a learned duration, and the bounds checks done before simulation.

The parameter layout is mp_pytorch's, so a θ of the authors' code runs here unchanged:
``[τ (if learned), delay (if learned), then per joint [w_1 … w_B, g (if the goal is not
disabled)]]`` (the thesis's counts, Sections 3.4, 4.5.1; Appendices A.3, B.4). The trajectory
is the ProDMP of :class:`vslbook.movement.ProDMP` built as the fancy-gym black-box wrapper
builds it: the phase is ``s = max(t − delay, 0) / τ`` with a continuous delay (the robot's
desired state is its start state until then), the initial conditions ``(q0, q̇0)`` hold at
t = 0, the basis grid is built for the construction-time τ (``tau``, also when τ is learned),
and ``auto_scale_basis`` divides each basis column by its largest value on that grid;
``weights_scale`` and ``goal_scale`` multiply the weights' and the goal's columns.

:meth:`ProDMPSpec.trajectory` samples the grid ``0, dt, …, duration``; row 0 is the start
state and control step k tracks row k + 1, i.e. ``q_d((k + 1)·dt)`` (the wrapper drops t = 0).
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
        tau: τ when it is not learned; when it is (θ[0], tau_bounds = (low, high)), the
            construction-time τ for which the basis grid is built (1.5 in Di-SkilL).
        delay_bounds: (low, high) when the start time is learned (θ after τ).
        goal: ``"learned"`` (absolute goal per joint in θ), ``"relative"`` (goal = q0 + g
            with g in θ; mp_pytorch's ``relative_goal``) or ``"disabled"`` (goal = q0, no goal
            parameters; ``disable_goal`` with ``relative_goal``).
        bandwidth_factor: of the phase-space Gaussians (3 in every task).
        rule: the last Gaussian's bandwidth, ``"di-skill"`` (default: the code behind the
            thesis's runs) or ``"mp_pytorch-0.1.3"`` (fancy-gym 0.3.0's pinned release).
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
    bandwidth_factor: float = 3.0
    rule: str = "di-skill"

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
        """``(τ, delay, weights (n_dof, n_basis), goal parameters (n_dof,) or None)``,
        unclipped; the weights and goal of joint j are θ's block ``[w_1 … w_B, g]``."""
        theta = np.asarray(theta, dtype=np.float64)
        if theta.shape != (self.n_params,):
            raise ValueError(f"theta must have shape ({self.n_params},), got {theta.shape}")
        i = 0
        tau, delay = self.tau, 0.0
        if self.tau_bounds is not None:
            tau, i = float(theta[0]), 1
        if self.delay_bounds is not None:
            delay, i = float(theta[i]), i + 1
        if self.goal == "disabled":
            return tau, delay, theta[i:].reshape(self.n_dof, self.n_basis), None
        blocks = theta[i:].reshape(self.n_dof, self.n_basis + 1)
        return tau, delay, blocks[:, :-1], blocks[:, -1]

    def bound_excess(self, theta: np.ndarray) -> tuple[float, float]:
        """How far τ and the delay lie outside their bounds (0 inside)."""
        tau, delay, _, _ = self.split(theta)
        return _excess(tau, self.tau_bounds), _excess(delay, self.delay_bounds)

    def trajectory(
        self, theta: np.ndarray, q0: np.ndarray, dq0: np.ndarray | None = None
    ) -> tuple[np.ndarray, np.ndarray]:
        """Desired positions and velocities on ``0, dt, …, duration``, each
        ``(n_steps + 1, n_dof)``; row 0 is ``(q0, q̇0)``, control step k tracks row k + 1.

        τ and the delay are clipped to their bounds here (the validity check uses the
        unclipped values, :meth:`bound_excess`). As in mp_pytorch, a start velocity is
        refused when the start is delayed.
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
        if delay > 0 and np.any(dq0 != 0):
            raise ValueError(f"dq0 must be zero when the start is delayed ({delay=}), got {dq0}")
        dmp = _prodmp(self, tau, delay)
        goal = np.zeros(self.n_dof) if g is None else g
        params = np.concatenate([w, goal[:, None]], axis=1).reshape(-1)
        return dmp.trajectory_numpy(params, q0, dq0)


@lru_cache(maxsize=16)
def _prodmp(spec: ProDMPSpec, tau: float, delay: float) -> ProDMP:
    """The ProDMP of one task and one (τ, delay). A task whose τ and start time are fixed
    builds it once (the basis grid itself is shared through ``prodmp_basis``'s cache).
    A :class:`ProDMP` is not changed by its use."""
    return ProDMP(
        spec.n_basis, spec.n_dof, duration=spec.n_steps * spec.dt, dt=spec.dt, alpha=spec.alpha,
        tau=tau, alpha_x=spec.alpha_phase, bandwidth_factor=spec.bandwidth_factor, delay=delay,
        basis_tau=spec.tau, rule=spec.rule, auto_scale_basis=spec.auto_scale_basis,
        weights_scale=spec.weights_scale, goal_scale=spec.goal_scale,
        relative_goal=spec.goal in ("relative", "disabled"),
    )


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
