"""The planar 5-link reacher: Chapter 4's 5LR and Chapter 3's SVSL-vs-PPO variant.

Model: fancy-gym 0.3.0's ``reacher/assets/reacher_5links.xml`` (MIT, read from the wheel,
loads unpatched on MuJoCo 3.17): five hinge joints about z (joint 4 limited to ±3 rad), links
of 0.1 m and a fingertip 0.11 m beyond the last joint (reach 0.51 m), five motors with gear
200 and ctrl ∈ [−1, 1], RK4 with timestep 0.01 s, no contacts. Frame skip 2 → control step
dt = 0.02 s; an episode has T = 200 control steps (4 s). The goal is the slide-jointed
``target`` body (qpos[5:7]); the tip is computed by forward kinematics (:func:`tip_position`).
``path(theta, context)`` gives the fingertip's world position over an episode.

**Controller** (both tasks, CH3_CH4_FACTS §1): the movement primitive gives ``(q_d, q̇_d)``
on the grid ``0, dt, ..., T·dt``; at control step t = 0..T−1 the command is
``a_t = clip(K_p (q_d[t+1] − q) + K_d (q̇_d[t+1] − q̇), −1, 1)`` with K_p = 1.0, K_d = 0.1,
held for the two physics steps. The grid point at the *end* of the control interval is what
fancy-gym's black-box wrapper uses (it drops t = 0 from the trajectory).

**Rewards** are evaluated on the state *after* the action of step t (so the last action
moves the final state that the time-sparse terms score). The authors' code (and gym's
Reacher) score the state *before* the action; we follow the thesis's q̇_T, the velocity
at the end of the episode.

:class:`Reacher5` — **5LR**, Chapter 4 (Section 4.5.1, Appendix B.4.3, Fig. 4.2):
    * context c = goal (x, y), uniform in the disk of radius 0.5 (rejection sampling from
      [−0.5, 0.5]²); out-of-range punishment (``evaluate(..., out_of_range="penalise")``)
      −d² with d the distance to the disk (ours; Di-SkilL samples contexts from p(c)).
    * start: all joints 0, the arm straight along +x ("straight to the right"), q̇0 = 0.
    * θ: ProDMP (Appendix B.3) with 5 basis functions per joint, basis alpha 10, phase
      alpha 3, τ fixed at 1.5, weights scale 0.3, auto-scaled basis; **25 parameters**
      (B.4.3: "5 basis functions per joint leading to a 25-dimensional parameter space"),
      layout dof-major, the goal is the start posture. ⚠ The authors' code enables a
      relative goal (goal = q0 + 0.3·g, 5 more parameters, **30**): ``goal_params=True``.
      ⚠ Without goal parameters the ProDMP's goal is the start posture and its forcing term
      has decayed by the end (phase exp(−3·4/1.5) ≈ 3·10⁻⁴): q_d(T) ≈ q0 for moderate θ
      (∂q_d(T)/∂θ ≤ 0.02 rad per unit), so the time-sparse reward can only be earned near
      the start tip (0.51, 0); a 240-episode cross-entropy search reaches 0.06 m for the goal
      (0.35, 0.25) but stays 0.4–0.7 m away from (0, 0.4) or (−0.3, −0.2). With
      ``goal_params=True`` every goal of the disk is reachable (IK posture as goal: < 1 mm).
      **Default: ``goal_params=True`` (30)**, the authors' code's choice, because the task
      cannot be solved without it; ``goal_params=False`` gives the thesis's stated 25.
    * reward (B.4.3, time-sparse): r_t = −Σa_t² for t < T; at t = T additionally
      −200‖p_tip − p_goal‖ − 10Σq̇_T². Return = Σ_t r_t.
    * success: the thesis defines none (``has_success = False``); ``info`` reports
      ``tip_distance`` (final ‖tip − goal‖), ``velocity_cost`` (Σq̇_T²) and ``action_cost``.
    * validity: none (every θ is executed).

:class:`Reacher5Ch3` — Chapter 3's variant (Section 3.4.3, Appendix A.3.3):
    * start: arm horizontal pointing **left** (joint 0 = π, others 0), q̇0 = 0.
    * context c = goal (x, y) on the **right** half disk x ≥ 0, x² + y² ≤ 0.25 (rejection
      from [0, 0.5] × [−0.5, 0.5]); out-of-range punishment −k·d² with d the distance to
      the half disk, k = 1000 (Eqs. 3.8, 3.9) or 50000 (Eq. 3.10) (A.3.3). With
      ``evaluate(..., out_of_range="penalise")`` such a goal is still simulated and the
      punishment is *added* to its return (as A.3.1 does for the planar reacher): A.3.3 does
      not say which, and a punishment that replaces the return lets SVSL's context
      distributions leave the half disk (measured with Eq. 3.10: an untrained expert earns
      about −1200 inside, while d = 0.1 outside costs only −500; the contexts moved out and
      the expert stopped getting episodes).
    * reward (``reward="3.8" | "3.9" | "3.10"``), t = 0..199 the control step:
      Eq. 3.8: r_t = −‖t − g‖ − Σa²; Eq. 3.9: −Σa² and −‖t − g‖ only for t ≥ 190;
      Eq. 3.10: t < 198: −Σa² − Σv², t ≥ 198: −500‖t − g‖ − Σa² − 1000Σv².
    * θ: the thesis states only "we employ ProMPs as controller parameterization"
      (Section 3.4.3), not the basis count. Ours: ProMP with 5 normalised RBFs per joint
      over the whole 4 s, q_d = q0 + Φᵀw (**25 parameters**, dof-major); ``mp="prodmp"``
      uses the 5LR ProDMP instead (also 25).
    * no success metric, no validity check (as for 5LR).
    The step-based version for PPO is :mod:`vslbook.envs.robot.reacher5_step`.

The movement primitives here are affine in θ (τ is fixed, q0 and q̇0 are fixed), so each
task evaluates ``vslbook.envs.robot.primitives`` once per basis vector at construction and
then builds ``(q_d, q̇_d)`` as ``b + θ A`` (checked against the primitive in the tests).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, ClassVar

import mujoco
import numpy as np

from vslbook.envs.robot.assets import load_model
from vslbook.envs.robot.primitives import ProDMPSpec, promp_trajectory
from vslbook.envs.robot.task import Episode, EpisodicTask, Rollouts

MODEL_FILE = "reacher/assets/reacher_5links.xml"
N_LINKS = 5
#: Distances joint i → joint i+1 (the last one: joint 4 → fingertip), metres.
LINK_LENGTHS = np.array([0.1, 0.1, 0.1, 0.1, 0.11])
FRAME_SKIP = 2
DT = 0.02
N_STEPS = 200
RADIUS = 0.5
KP, KD = 1.0, 0.1  # ReacherSim.track hard-codes K_p = 1 in its hot loop
Q0_RIGHT = np.zeros(N_LINKS)
Q0_LEFT = np.array([np.pi, 0.0, 0.0, 0.0, 0.0])
CH3_REWARDS = ("3.8", "3.9", "3.10")
#: Out-of-range context punishment factors of Appendix A.3.3.
CH3_CONTEXT_FACTOR = {"3.8": 1000.0, "3.9": 1000.0, "3.10": 50000.0}


def tip_position(q: np.ndarray) -> np.ndarray:
    """Fingertip (x, y) for joint angles ``q`` of shape ``(..., 5)`` (base at the origin)."""
    phi = np.cumsum(np.asarray(q, dtype=np.float64), axis=-1)
    return np.stack([np.cos(phi) @ LINK_LENGTHS, np.sin(phi) @ LINK_LENGTHS], axis=-1)


def rewards_5lr(
    actions: np.ndarray, tip: np.ndarray, qvel: np.ndarray, goal: np.ndarray
) -> np.ndarray:
    """Per-step rewards of 5LR (Appendix B.4.3) for a whole episode.

    ``actions`` ``(T, 5)`` are the clipped commands; ``tip`` ``(2,)`` and ``qvel`` ``(5,)`` the
    final state. r_t = −Σa_t², and the last step adds −200‖tip − goal‖ − 10Σq̇_T².
    """
    r = -np.sum(np.square(actions), axis=-1)
    r[-1] -= 200.0 * float(np.linalg.norm(tip - goal)) + 10.0 * float(np.sum(np.square(qvel)))
    return r


def rewards_ch3(
    reward: str,
    steps: np.ndarray,
    actions: np.ndarray,
    tip: np.ndarray,
    qvel: np.ndarray,
    goal: np.ndarray,
) -> np.ndarray:
    """Per-step rewards of Eqs. 3.8–3.10.

    ``steps`` ``(n,)`` are the control-step indices t (0..199), ``actions`` ``(n, 5)``,
    ``tip`` ``(n, 2)`` and ``qvel`` ``(n, 5)`` the states after each action, ``goal`` ``(2,)``.
    """
    if reward not in CH3_REWARDS:
        raise ValueError(f"reward must be one of {CH3_REWARDS}, got {reward!r}")
    steps = np.asarray(steps)
    ctrl = np.sum(np.square(actions), axis=-1)
    dist = np.linalg.norm(np.asarray(tip) - goal, axis=-1)
    if reward == "3.8":
        return -dist - ctrl
    if reward == "3.9":
        return -ctrl - np.where(steps >= N_STEPS - 10, dist, 0.0)
    vel = np.sum(np.square(qvel), axis=-1)
    late = steps >= N_STEPS - 2
    return np.where(late, -500.0 * dist - ctrl - 1000.0 * vel, -ctrl - vel)


def check_ch3_reward(reward: Any) -> str:
    """``reward`` as one of "3.8", "3.9", "3.10" (numbers accepted), or a clear error."""
    key = str(reward)
    if key not in CH3_REWARDS:
        raise ValueError(f"reward must be one of {CH3_REWARDS} (Eqs. 3.8-3.10), got {reward!r}")
    return key


class ReacherSim:
    """The MuJoCo model and data with the reacher's reset, PD rollout and step."""

    def __init__(self) -> None:
        self.model = load_model(MODEL_FILE)
        if (self.model.nq, self.model.nu) != (N_LINKS + 2, N_LINKS):
            raise RuntimeError(f"unexpected {MODEL_FILE}: nq={self.model.nq}, nu={self.model.nu}")
        m = self.model
        if not (
            np.all(m.actuator_ctrllimited)
            and np.array_equal(m.actuator_ctrlrange, np.tile([-1.0, 1.0], (N_LINKS, 1)))
            and not m.opt.disableflags & mujoco.mjtDisableBit.mjDSBL_CLAMPCTRL
        ):  # track() leaves the clip of its commands to MuJoCo's ctrl clamping
            raise RuntimeError(f"{MODEL_FILE}: the motors must clamp ctrl to [-1, 1]")
        self.data = mujoco.MjData(self.model)
        self.physics_steps = 0
        self._qpos = self.data.qpos[:N_LINKS]
        self._qvel = self.data.qvel[:N_LINKS]
        self._kd = np.full(N_LINKS, KD)

    def reset(self, q0: np.ndarray, goal: np.ndarray) -> None:
        """Arm at ``q0`` at rest, target at ``goal``."""
        m, d = self.model, self.data
        mujoco.mj_resetData(m, d)
        d.qpos[:N_LINKS] = q0
        d.qpos[N_LINKS:] = goal
        mujoco.mj_forward(m, d)

    @property
    def q(self) -> np.ndarray:
        return self._qpos.copy()

    @property
    def dq(self) -> np.ndarray:
        return self._qvel.copy()

    def step(self, action: np.ndarray) -> None:
        """Hold ``action`` (already clipped) for ``FRAME_SKIP`` physics steps."""
        self.data.ctrl[:] = action
        mujoco.mj_step(self.model, self.data, FRAME_SKIP)
        self.physics_steps += FRAME_SKIP

    def track(
        self, ref: np.ndarray, q0: np.ndarray, goal: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """PD-track ``ref`` = K_p q_d[1:] + K_d q̇_d[1:] (``(T, 5)``) from ``q0`` at rest.

        Returns the clipped commands ``(T, 5)`` and the joint positions and velocities
        ``(T + 1, 5)`` (row 0 the start, row t + 1 the state after command t).
        """
        self.reset(q0, goal)
        n = len(ref)
        qs = np.empty((n + 1, N_LINKS))
        dqs = np.empty((n + 1, N_LINKS))
        qpos, qvel, ctrl, kd = self._qpos, self._qvel, self.data.ctrl, self._kd
        qs[0], dqs[0] = qpos, qvel
        m, d, step = self.model, self.data, mujoco.mj_step
        kdv = np.empty(N_LINKS)
        sub, mul = np.subtract, np.multiply
        # The hot loop: in-place ufuncs straight into data.ctrl. The clip to [-1, 1] is
        # MuJoCo's own ctrl clamping (ctrlrange of the motors, checked in __init__), which
        # gives the physics the same numbers as np.clip; data.ctrl itself stays unclipped.
        for t in range(n):
            sub(ref[t], qpos, ctrl)  # K_p = 1
            mul(kd, qvel, kdv)
            sub(ctrl, kdv, ctrl)
            step(m, d, FRAME_SKIP)
            qs[t + 1] = qpos
            dqs[t + 1] = qvel
        # the same operations again, batched: the commands the loop applied
        act = np.clip(ref - qs[:-1] - KD * dqs[:-1], -1.0, 1.0)
        self.physics_steps += FRAME_SKIP * n
        return act, qs, dqs


def affine_map(
    fn: Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]], n_params: int
) -> tuple[np.ndarray, np.ndarray]:
    """``(b, A)`` with ``K_p q_d[1:] + K_d q̇_d[1:] = b + θ A`` for an affine ``fn``: θ → (q_d, q̇_d).

    ``b`` has shape ``(T, 5)`` and ``A`` ``(n_params, T, 5)``.
    """

    def ref(theta: np.ndarray) -> np.ndarray:
        q, dq = fn(theta)
        return KP * q[1:] + KD * dq[1:]

    b = ref(np.zeros(n_params))
    eye = np.eye(n_params)
    return b, np.stack([ref(eye[i]) - b for i in range(n_params)])


def prodmp_spec_5lr(goal_params: bool = True) -> ProDMPSpec:
    """The 5LR ProDMP (Section 4.5.1, B.3/B.4.3; goal parameters only as in the code)."""
    return ProDMPSpec(
        n_dof=N_LINKS, n_basis=5, dt=DT, duration=N_STEPS * DT, alpha=10.0, alpha_phase=3.0,
        tau=1.5, goal="relative" if goal_params else "disabled",
        weights_scale=0.3, goal_scale=0.3, auto_scale_basis=True,
    )  # fmt: skip


class _ReacherTask(EpisodicTask):
    """Shared machinery: lazy simulator, affine primitive, batch of PD rollouts."""

    context_names: ClassVar[tuple[str, ...]] = ("goal_x", "goal_y")
    info_keys: ClassVar[tuple[str, ...]] = ("tip_distance", "velocity_cost", "action_cost")
    has_success: ClassVar[bool] = False
    path_names: ClassVar[tuple[str, ...]] = ("fingertip",)
    q0: ClassVar[np.ndarray] = Q0_RIGHT

    def __init__(self, **kwargs: Any) -> None:
        super().__init__(**kwargs)
        self._sim: ReacherSim | None = None
        self._b, self._A = affine_map(self.desired_trajectory, self.n_params)

    def desired_trajectory(self, theta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(q_d, q̇_d)`` on the grid ``0, dt, ..., T·dt``, each ``(T + 1, 5)``."""
        raise NotImplementedError

    @property
    def sim(self) -> ReacherSim:
        if self._sim is None:
            self._sim = ReacherSim()
        return self._sim

    def references(self, theta: np.ndarray) -> np.ndarray:
        """``K_p q_d[1:] + K_d q̇_d[1:]`` for a batch ``(n, n_params)`` → ``(n, T, 5)``."""
        return self._b + np.tensordot(theta, self._A, axes=1)

    def rollout(self, theta: np.ndarray, context: np.ndarray) -> tuple[np.ndarray, ...]:
        """Commands ``(T, 5)``, positions and velocities ``(T + 1, 5)`` of one episode."""
        theta = self.check_theta(theta, n=1)
        return self.sim.track(self.references(theta)[0], self.q0, np.asarray(context))

    def step_rewards(
        self, actions: np.ndarray, qs: np.ndarray, dqs: np.ndarray, goal: np.ndarray
    ) -> np.ndarray:
        raise NotImplementedError

    def episodes(self, theta: np.ndarray, contexts: np.ndarray) -> list[Episode]:
        refs = self.references(self.check_theta(theta))
        out = []
        for ref, goal in zip(refs, np.asarray(contexts, dtype=np.float64), strict=True):
            act, qs, dqs = self.sim.track(ref, self.q0, goal)
            r = self.step_rewards(act, qs, dqs, goal)
            info = {
                "tip_distance": float(np.linalg.norm(tip_position(qs[-1]) - goal)),
                "velocity_cost": float(np.sum(np.square(dqs[-1]))),
                "action_cost": float(np.sum(np.square(act))),
            }
            out.append(Episode(float(np.sum(r)), False, True, info))
        return out

    def episode(self, theta: np.ndarray, context: np.ndarray) -> Episode:
        return self.episodes(np.asarray(theta)[None], np.asarray(context)[None])[0]

    def path(self, theta: Any, context: Any) -> dict[str, np.ndarray]:
        """``fingertip``: its world position at the start and after every control step,
        ``(T + 1, 3)``: the joint positions of the PD rollout :meth:`evaluate` runs, put
        through MuJoCo's forward kinematics (see the base class)."""
        c = self.one_context(context)
        _, qs, _ = self.rollout(theta, c)
        m = self.sim.model
        d = mujoco.MjData(m)
        d.qpos[N_LINKS:] = c
        tip = m.body("fingertip").id
        out = np.empty((len(qs), 3))
        for t, q in enumerate(qs):
            d.qpos[:N_LINKS] = q
            mujoco.mj_kinematics(m, d)
            out[t] = d.xpos[tip]
        return {"fingertip": out}

    def scene(self, context: Any) -> tuple[mujoco.MjModel, mujoco.MjData]:
        """The arm at its start, the target at the goal ``context`` (see the base class)."""
        self.sim.reset(self.q0, self.one_context(context))
        return self.sim.model, self.sim.data


class Reacher5(_ReacherTask):
    """5LR of Chapter 4 (Section 4.5.1, Appendix B.4.3); see the module docstring.

    Args:
        goal_params: True (default; the authors' code: ProDMP relative goal per joint,
            30 parameters, needed to reach goals away from the start) or False (the
            thesis's stated 25 parameters).
    """

    name: ClassVar[str] = "reacher5"
    context_low: ClassVar[np.ndarray] = np.array([-RADIUS, -RADIUS])
    context_high: ClassVar[np.ndarray] = np.array([RADIUS, RADIUS])
    n_params: ClassVar[int] = 30
    q0: ClassVar[np.ndarray] = Q0_RIGHT

    def __init__(self, goal_params: bool = True) -> None:
        if not isinstance(goal_params, (bool, np.bool_)):
            raise TypeError(f"goal_params must be a bool, got {goal_params!r}")
        self.spec = prodmp_spec_5lr(bool(goal_params))
        self.n_params = self.spec.n_params  # type: ignore[misc]
        super().__init__(goal_params=bool(goal_params))

    def desired_trajectory(self, theta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return self.spec.trajectory(theta, self.q0, np.zeros(N_LINKS))

    def context_valid(self, contexts: np.ndarray) -> np.ndarray:
        c = np.asarray(contexts, dtype=np.float64)
        return super().context_valid(c) & (np.sum(c**2, axis=-1) <= RADIUS**2)

    def context_penalty(self, contexts: np.ndarray) -> np.ndarray:
        c = np.asarray(contexts, dtype=np.float64)
        return -(np.maximum(np.linalg.norm(c, axis=-1) - RADIUS, 0.0) ** 2)

    def describe_contexts(self) -> str:
        return super().describe_contexts() + f"; goal_x² + goal_y² <= {RADIUS**2:g}"

    def step_rewards(
        self, actions: np.ndarray, qs: np.ndarray, dqs: np.ndarray, goal: np.ndarray
    ) -> np.ndarray:
        return rewards_5lr(actions, tip_position(qs[-1]), dqs[-1], goal)


def half_disk_distance(contexts: np.ndarray) -> np.ndarray:
    """Euclidean distance of goals ``(..., 2)`` to the half disk x ≥ 0, x² + y² ≤ 0.25."""
    c = np.asarray(contexts, dtype=np.float64)
    x, y = c[..., 0], c[..., 1]
    right = np.maximum(np.hypot(x, y) - RADIUS, 0.0)
    left = np.hypot(x, np.maximum(np.abs(y) - RADIUS, 0.0))
    return np.where(x >= 0, right, left)


class Reacher5Ch3(_ReacherTask):
    """Chapter 3's 5-link reacher (Section 3.4.3, A.3.3), episodic; see the module docstring.

    Args:
        reward: "3.8", "3.9" or "3.10" (the equation).
        mp: "promp" (ours by default, Section 3.4.3 names ProMPs) or "prodmp" (5LR's).
    """

    name: ClassVar[str] = "reacher5-ch3"
    context_low: ClassVar[np.ndarray] = np.array([0.0, -RADIUS])
    context_high: ClassVar[np.ndarray] = np.array([RADIUS, RADIUS])
    n_params: ClassVar[int] = 25
    q0: ClassVar[np.ndarray] = Q0_LEFT
    n_basis: ClassVar[int] = 5

    def __init__(self, reward: str = "3.8", mp: str = "promp") -> None:
        self.reward = check_ch3_reward(reward)
        if mp not in ("promp", "prodmp"):
            raise ValueError(f"mp must be 'promp' or 'prodmp', got {mp!r}")
        self.mp = mp
        self.spec = prodmp_spec_5lr(False)
        super().__init__(reward=self.reward, mp=mp)

    def desired_trajectory(self, theta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        if self.mp == "prodmp":
            return self.spec.trajectory(theta, self.q0, np.zeros(N_LINKS))
        w = np.asarray(theta, dtype=np.float64).reshape(N_LINKS, self.n_basis)
        return promp_trajectory(w, N_STEPS * DT, DT, self.q0)

    def context_valid(self, contexts: np.ndarray) -> np.ndarray:
        c = np.asarray(contexts, dtype=np.float64)
        return super().context_valid(c) & (np.sum(c**2, axis=-1) <= RADIUS**2)

    def context_penalty(self, contexts: np.ndarray) -> np.ndarray:
        return -CH3_CONTEXT_FACTOR[self.reward] * half_disk_distance(contexts) ** 2

    def describe_contexts(self) -> str:
        return super().describe_contexts() + f"; goal_x² + goal_y² <= {RADIUS**2:g}"

    def evaluate(
        self,
        theta: Any,
        contexts: Any,
        *,
        workers: int | None = None,
        out_of_range: str = "error",
    ) -> Rollouts:
        """As :meth:`EpisodicTask.evaluate`, except that with ``out_of_range="penalise"`` a
        goal outside the half disk is simulated too and −k·d² is added to its return (see
        the module docstring); such episodes count as executed."""
        if out_of_range != "penalise":
            return super().evaluate(theta, contexts, workers=workers, out_of_range=out_of_range)
        th, c = self.check_batch(theta, contexts, out_of_range)
        out = Rollouts.from_episodes(self._run(th, c, workers), self.info_keys)
        out.returns[:] = out.returns + self.context_penalty(c)  # 0 inside the half disk
        return out

    def step_rewards(
        self, actions: np.ndarray, qs: np.ndarray, dqs: np.ndarray, goal: np.ndarray
    ) -> np.ndarray:
        steps = np.arange(len(actions))
        return rewards_ch3(self.reward, steps, actions, tip_position(qs[1:]), dqs[1:], goal)
