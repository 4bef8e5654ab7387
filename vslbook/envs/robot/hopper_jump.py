"""Hopper Jump (HJ), Chapter 4: jump as high as possible and land on a goal on the x axis.

Thesis Section 4.5.1 ("Hopper Jump (HJ)", after Otto et al., 2023) and Appendix B.4.2
(context, parameters, reward, Fig. B.3); numbers the thesis leaves open come from
``shared/design/CH3_CH4_FACTS.md`` §1.4 (the authors' code, read only).

Model
    fancy-gym 0.3.0's converted ``hopper_jump/assets/hopper_jump.xml`` read from the installed
    wheel (:func:`~vslbook.envs.robot.assets.load_model`; the ``before_convert`` file uses
    global coordinates and does not load on MuJoCo 3). Planar hopper, joints
    ``[rootx, rootz, rooty, thigh, leg, foot]``, three ``general`` actuators (gear 200,
    ctrl in [−1, 1]) on thigh, leg and foot; RK4, physics time step 0.002 s.

Timing
    frame skip 4 → control step dt = 0.008 s; T = 250 control steps (2 s); no early
    termination. Every episode starts at rest with ``rootz = 1.5`` (0.25 m above the model's
    reference 1.25, as the authors' code does), ``rootx = rooty = 0`` and the three actuated
    joints at the context's angles.

Context c (4-D, the thesis's order ``[j3, j4, j5, g]``, B.4.2)
    ``q_thigh ∈ [−0.5, 0]``, ``q_leg ∈ [−0.2, 0]``, ``q_foot ∈ [0, 0.785]`` (rad, initial angles of
    the actuated joints) and ``goal_x ∈ [0.3, 1.35]`` (m), the goal p_goal = (g, 0, 0); the
    model's ``goal_site_body`` is moved there. Uniform on the box, no rejection rule.
    ⚠ The authors' code orders the context ``[goal_x, q_thigh, q_leg, q_foot]``; the thesis's
    order is used here (``context_names``).

Parameters θ (12, B.4.2)
    ProDMP (:class:`~vslbook.envs.robot.primitives.ProDMPSpec`), 3 joints × 3 basis
    functions, per joint its weights then its absolute goal angle (mp_pytorch's layout):
    ``θ = [w_thigh(3), g_thigh, w_leg(3), g_leg, w_foot(3), g_foot]``. τ = 0.8 is fixed
    (not learned), weights_scale = goal_scale = 1, basis auto-scaling on, spring-damper
    α = 10, phase decay 3. The trajectory starts at rest from the context's joint angles.

Controller
    ``a_t = clip(1.0·(q_d − q_t) + 0.1·(q̇_d − q̇_t), −1, 1)`` on the three actuated
    joints (the normalised actuator command, held for the 4 physics steps of control step t),
    with q_d, q̇_d the trajectory at time (t + 1)·dt, as fancy-gym's black-box wrapper.

Reward (non-Markovian, sparse; the return is the sum of the step rewards, B.4.2)
    every step ``−τ_t`` with ``τ_t = 10⁻³ Σ_i (a_t^i)²`` (the clipped command), and after the
    last step ``R_height + R_gdist + R_cdist + R_healthy`` with

    - ``R_height = 10 h_max``, h_max the largest torso centre-of-mass height after any step;
    - ``R_gdist = −3 ‖p_foot,T − p_goal‖``;
    - ``R_cdist = −2 ‖p_foot,contact − p_goal‖``, p_foot,contact the foot site at the first
      foot–floor contact after the foot had touched the floor and then left it; ``−2·5`` if
      that never happens (e.g. the hopper never jumped);
    - ``R_healthy = 2`` if ``z_T ≥ 0.5`` and every entry of ``(qpos[2:], qvel)`` lies in
      (−100, 100) (gymnasium Hopper's check; the angle is unbounded), else 0.

    ⚠ B.4.2 writes R_tot = −Σ τ_t + R_height + R_gdist + R_cdist + R_healthy with the two
    distance terms as *positive* norms and no weights on them; a reward that grows with the
    distance to the goal contradicts "land at a specified position", so the authors' code's
    weights and signs (−3, −2, the fallback 5) are used. The thesis's inclusive ``z ∈ [0.5, ∞]``
    is used (the code's test is strict). p_foot is the ``foot_site`` (the heel), distances
    are 3-D (the site's height counts), as in the code; where the code's ``contact_dist or 5``
    would also give 5 for a contact distance of exactly 0, this module keeps the 0.
    Positions and contacts are read as MuJoCo left them after the 4 physics steps (computed
    at the start of the last physics step, as gymnasium's MuJoCo environments read them).

Path (:meth:`~vslbook.envs.robot.task.EpisodicTask.path`)
    ``foot`` (the ``foot_site``) and ``torso`` (the torso's centre of mass, whose height is
    h) at the start and after every control step, as the reward reads them.

Success and validity
    No success flag (``has_success = False``); ``info`` reports ``max_height``,
    ``goal_distance`` (‖p_foot,T − p_goal‖), ``contact_distance`` (NaN if the foot never
    re-touched the floor) and ``healthy`` (0/1), the quantities of Fig. B.3. τ is not learned,
    so every finite θ is valid and simulated (``executed`` is always True).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import mujoco
import numpy as np

from vslbook.envs.robot.assets import load_model
from vslbook.envs.robot.primitives import ProDMPSpec
from vslbook.envs.robot.task import Episode, EpisodicTask

MODEL = "hopper_jump/assets/hopper_jump.xml"
FRAME_SKIP = 4
N_STEPS = 250
DT = 0.002 * FRAME_SKIP
INIT_ROOTZ = 1.5
P_GAIN, D_GAIN = 1.0, 0.1
CTRL_COST = 1e-3
HEIGHT_WEIGHT, GOAL_WEIGHT, CONTACT_WEIGHT = 10.0, 3.0, 2.0
NO_CONTACT_DISTANCE = 5.0
HEALTHY_REWARD, HEALTHY_MIN_Z, HEALTHY_STATE = 2.0, 0.5, 100.0

SPEC = ProDMPSpec(
    n_dof=3, n_basis=3, dt=DT, duration=N_STEPS * DT, alpha=10.0, alpha_phase=3.0,
    tau=0.8, goal="learned", weights_scale=1.0, goal_scale=1.0, auto_scale_basis=True,
)  # fmt: skip


@dataclass
class JumpRecord:
    """What one simulated jump leaves for the reward (arrays over the T control steps).

    Attributes:
        actions: ``(T, 3)`` clipped commands a_t.
        heights: ``(T,)`` torso centre-of-mass height after each step.
        foot: ``(T, 3)`` position of the foot site after each step.
        contacts: ``(T,)`` whether the foot touched the floor after each step.
        qpos, qvel: the final state (6 entries each).
        goal: p_goal, ``(3,)``.
    """

    actions: np.ndarray
    heights: np.ndarray
    foot: np.ndarray
    contacts: np.ndarray
    qpos: np.ndarray
    qvel: np.ndarray
    goal: np.ndarray


def first_recontact(contacts: np.ndarray) -> int | None:
    """Index of the first foot–floor contact after the foot touched the floor and left it.

    ``contacts`` is a boolean sequence over steps: the foot must touch the floor (the hopper
    starts in the air), then be off it for at least one step, then touch it again.
    """
    c = np.asarray(contacts, dtype=bool)
    if c.ndim != 1:
        raise ValueError(f"contacts must be 1-D, got shape {c.shape}")
    touched = np.flatnonzero(c)
    if len(touched) == 0:
        return None
    left = np.flatnonzero(~c[touched[0] :])
    if len(left) == 0:
        return None
    start = touched[0] + left[0]
    again = np.flatnonzero(c[start:])
    return int(start + again[0]) if len(again) else None


def is_healthy(qpos: np.ndarray, qvel: np.ndarray) -> bool:
    """gymnasium Hopper's health test with HJ's bounds: z ≥ 0.5, |(qpos[2:], qvel)| < 100."""
    qpos, qvel = np.asarray(qpos, dtype=np.float64), np.asarray(qvel, dtype=np.float64)
    state = np.concatenate([qpos[2:], qvel])
    return bool(qpos[1] >= HEALTHY_MIN_Z and np.all(np.abs(state) < HEALTHY_STATE))


def jump_reward(record: JumpRecord) -> tuple[float, dict[str, float]]:
    """The return of one jump (module docstring, B.4.2) and its ``info`` numbers."""
    actions = np.asarray(record.actions, dtype=np.float64)
    heights = np.asarray(record.heights, dtype=np.float64)
    foot = np.asarray(record.foot, dtype=np.float64)
    goal = np.asarray(record.goal, dtype=np.float64)
    n = len(heights)
    if n == 0 or actions.shape != (n, 3) or foot.shape != (n, 3) or len(record.contacts) != n:
        raise ValueError(
            f"a jump record needs T >= 1 steps of actions (T, 3), heights (T,), foot (T, 3) and "
            f"contacts (T,); got {actions.shape}, {heights.shape}, {foot.shape}, "
            f"{np.shape(record.contacts)}"
        )
    ctrl_cost = CTRL_COST * float(np.sum(actions**2))
    max_height = float(max(heights.max(), 0.0))
    goal_distance = float(np.linalg.norm(foot[-1] - goal))
    k = first_recontact(record.contacts)
    contact_distance = float(np.linalg.norm(foot[k] - goal)) if k is not None else np.nan
    healthy = is_healthy(record.qpos, record.qvel)
    final = (
        HEIGHT_WEIGHT * max_height
        - GOAL_WEIGHT * goal_distance
        - CONTACT_WEIGHT * (NO_CONTACT_DISTANCE if k is None else contact_distance)
        + HEALTHY_REWARD * healthy
    )
    info = {
        "max_height": max_height,
        "goal_distance": goal_distance,
        "contact_distance": contact_distance,
        "healthy": float(healthy),
    }
    return final - ctrl_cost, info


class HopperJump(EpisodicTask):
    """Hopper Jump (HJ, thesis 4.5.1 / B.4.2): see the module docstring."""

    name = "hopper-jump"
    context_names = ("q_thigh", "q_leg", "q_foot", "goal_x")
    context_low = np.array([-0.5, -0.2, 0.0, 0.3])
    context_high = np.array([0.0, 0.0, 0.785, 1.35])
    n_params = SPEC.n_params
    info_keys = ("max_height", "goal_distance", "contact_distance", "healthy")
    has_success = False
    path_names = ("foot", "torso")
    spec = SPEC

    def __init__(self, **kwargs: Any) -> None:
        if kwargs:
            raise TypeError(f"HopperJump takes no options, got {sorted(kwargs)}")
        super().__init__()
        self.model = load_model(MODEL)
        self.data = mujoco.MjData(self.model)
        m = self.model
        self._torso = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, "torso")
        self._goal_body = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, "goal_site_body")
        self._foot_site = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_SITE, "foot_site")
        self._floor = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_GEOM, "floor")
        self._foot_geom = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_GEOM, "foot_geom")
        if min(self._torso, self._goal_body, self._foot_site, self._floor, self._foot_geom) < 0:
            raise RuntimeError(f"{MODEL}: a body, site or geom HJ needs is missing")
        if m.nu != 3 or m.nq != 6 or abs(m.opt.timestep - 0.002) > 1e-12:
            raise RuntimeError(f"{MODEL}: unexpected model (nu={m.nu}, nq={m.nq})")
        self._pair = {self._floor, self._foot_geom}

    def scene(self, context: Any) -> tuple[mujoco.MjModel, mujoco.MjData]:
        """The simulator at the start of an episode in ``context`` (see the base class)."""
        self.reset(self.one_context(context))
        return self.model, self.data

    def reset(self, context: np.ndarray) -> None:
        """Put the simulator at the start state of ``context`` (goal moved, at rest)."""
        c = np.asarray(context, dtype=np.float64)
        mujoco.mj_resetData(self.model, self.data)
        self.model.body_pos[self._goal_body] = (c[3], 0.0, 0.0)
        self.data.qpos[:] = (0.0, INIT_ROOTZ, 0.0, c[0], c[1], c[2])
        self.data.qvel[:] = 0.0
        mujoco.mj_forward(self.model, self.data)

    def _foot_contact(self) -> bool:
        """Whether the foot geom touches the floor in MuJoCo's current contact list."""
        if self.data.ncon == 0:
            return False
        floor, foot = self._floor, self._foot_geom
        return any(
            (a == floor and b == foot) or (a == foot and b == floor)
            for a, b in self.data.contact.geom.tolist()
        )

    def simulate(self, theta: np.ndarray, context: np.ndarray) -> JumpRecord:
        """Run the ProDMP of ``theta`` from the start state of ``context``; record the jump."""
        c = np.asarray(context, dtype=np.float64)
        if c.shape != (4,):
            raise ValueError(f"HJ: a context has 4 entries {self.context_names}, got {c.shape}")
        # control step t tracks the primitive at (t + 1) dt (row 0 is the start state)
        q_d, dq_d = (a[1:] for a in self.spec.trajectory(theta, c[:3], np.zeros(3)))
        self.reset(c)
        m, d = self.model, self.data
        # views into MjData, updated in place by mj_step
        q, dq, ctrl = d.qpos[3:6], d.qvel[3:6], d.ctrl
        torso, site = d.xipos[self._torso], d.site_xpos[self._foot_site]
        actions = np.empty((N_STEPS, 3))
        heights = np.empty(N_STEPS)
        foot = np.empty((N_STEPS, 3))
        contacts = np.zeros(N_STEPS, dtype=bool)
        phase = 0  # 0: not yet touched, 1: touching, 2: left the floor, 3: touched again
        feedforward = P_GAIN * q_d + D_GAIN * dq_d
        feedback = np.empty(3)
        path = self._recorder
        if path is not None:
            path(foot=site, torso=torso)
        for t in range(N_STEPS):
            # u = clip(P (q_d - q) + D (dq_d - dq), -1, 1), without temporaries
            u = actions[t]
            np.multiply(q, P_GAIN, out=u)
            np.multiply(dq, D_GAIN, out=feedback)
            u += feedback
            np.subtract(feedforward[t], u, out=u)
            np.minimum(u, 1.0, out=u)
            np.maximum(u, -1.0, out=u)
            ctrl[:] = u
            mujoco.mj_step(m, d, nstep=FRAME_SKIP)
            heights[t] = torso[2]
            foot[t] = site
            if path is not None:
                path(foot=site, torso=torso)
            if phase < 3:  # after the re-contact the contacts no longer matter
                touch = self._foot_contact()
                contacts[t] = touch
                if touch and phase in (0, 2):
                    phase += 1
                elif not touch and phase == 1:
                    phase = 2
        return JumpRecord(
            actions, heights, foot, contacts, d.qpos.copy(), d.qvel.copy(), np.array([c[3], 0, 0])
        )

    def episode(self, theta: np.ndarray, context: np.ndarray) -> Episode:
        ret, info = jump_reward(self.simulate(theta, context))
        return Episode(ret, False, True, info)
