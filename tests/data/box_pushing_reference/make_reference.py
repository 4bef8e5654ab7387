"""Step-by-step reference of fancy-gym 0.3.0's box pushing (no obstacle) for
tests/test_box_pushing_reference.py.

Runs OUTSIDE the project, in a throw-away virtual environment with fancy-gym 0.3.0 and the
MuJoCo it was released against (see provenance.json for the exact versions), e.g.

    python3 -m venv /tmp/fg030
    /tmp/fg030/bin/pip install "fancy-gym==0.3.0" "mujoco==2.3.3" "gymnasium==0.29.1" \
        "numpy<2" "mp_pytorch==0.1.3"
    /tmp/fg030/bin/python make_reference.py            # writes box_pushing_steps.npz here

The package and the tests never import this script, fancy-gym or MuJoCo 2.3. It drives
fancy-gym's own step-based environment ``BoxPushingTemporalSparse`` (its reward is the one
the authors' obstacle task uses, ``settings="code"`` in vslbook) through its public
``reset`` and ``step`` and records what the environment's simulator holds after every
control step. Nothing of fancy-gym is copied: only numbers come out.

Episodes (``SEQUENCES``), each of 100 control steps of 10 physics steps from fancy-gym's
own start (the robot posture its reset finds by inverse kinematics, the box at
(0.4, 0.3, -0.01) with yaw pi), with the goal moved to ``GOAL``:

* ``smooth_random``: normalised torques a_t in [-1, 1]^7, a sum of three sinusoids per
  joint (frequencies 0.3-1.5 Hz, random amplitudes and phases, seed ``SEED``) scaled
  by 0.15 on joints 1-4 and 0.05 on the light wrist joints 5-7;
* ``push``: the rod tip driven towards -y at 0.15 m/s from t = 0.2 s, so it runs into the
  box's wall and pushes the box: desired joint velocities from a damped least-squares
  inverse of the rod tip's position Jacobian and the rod's rotation Jacobian (keep the
  rod upright), integrated to desired positions and tracked with the task's PD gains;
  the actions this closed loop chose are recorded and are what the test replays open loop.

Per step t = 0..99 (the state after action t) and for the start (index 0 of ``start_*``):
robot q, q̇ (7), the full qpos (16) and qvel (15), the box's position and quaternion (body
``box_0``), the rod tip (site ``rod_tip``), the rod's quaternion (body ``push_rod``), the
reward fancy-gym returned, and whether a rod-box contact existed after the step
(``contact_end``) or after any of its 10 physics steps (``contact_any``, from a copy of
the simulator stepped one physics step at a time with the same motor command; the copy is
checked to end in the very state the environment reached).
"""

from __future__ import annotations

import copy
import datetime
import json
import platform
import sys
from importlib import metadata
from pathlib import Path

import mujoco
import numpy as np
from fancy_gym.envs.mujoco.box_pushing.box_pushing_env import BoxPushingTemporalSparse

HERE = Path(__file__).parent
SEED = 20261127
STEPS, FRAME_SKIP, DT = 100, 10, 0.02
#: goal (x, y, yaw); the goal quaternion is (cos yaw/2, 0, 0, sin yaw/2)
GOAL = (0.45, -0.25, 1.0)
GOAL_Z = -0.01
#: the task's PD gains on the normalised action (used by the "push" plan only)
KP = 0.01 * np.array([120.0, 120, 120, 120, 50, 30, 10])
KD = 0.01 * np.array([10.0, 10, 10, 10, 6, 5, 3])
TORQUE_MAX = np.array([90.0, 90, 90, 90, 12, 12, 12])
SEQUENCES = ("smooth_random", "push")


def goal_quat(yaw: float) -> np.ndarray:
    return np.array([np.cos(yaw / 2), 0.0, 0.0, np.sin(yaw / 2)])


def make_env() -> BoxPushingTemporalSparse:
    """fancy-gym's environment, reset with a seed, the goal moved to GOAL."""
    env = BoxPushingTemporalSparse()
    env.reset(seed=SEED)
    m, d = env.model, env.data
    for name in ("target_pos", "replan_target_pos"):
        b = m.body(name).id
        m.body_pos[b] = [GOAL[0], GOAL[1], GOAL_Z]
        m.body_quat[b] = goal_quat(GOAL[2])
    mujoco.mj_forward(m, d)
    return env


def rod_box_geoms(m: mujoco.MjModel) -> tuple[set[int], set[int]]:
    rod, box = m.body("push_rod").id, m.body("box_0").id
    geoms = range(m.ngeom)
    return (
        {g for g in geoms if m.geom_bodyid[g] == rod},
        {g for g in geoms if m.geom_bodyid[g] == box},
    )


def touching(d: mujoco.MjData, rod: set[int], box: set[int]) -> bool:
    for i in range(d.ncon):
        g1, g2 = int(d.contact[i].geom1), int(d.contact[i].geom2)
        if (g1 in rod and g2 in box) or (g1 in box and g2 in rod):
            return True
    return False


def smooth_random_actions() -> np.ndarray:
    rng = np.random.default_rng(SEED)
    t = np.arange(STEPS) * DT
    freq = rng.uniform(0.3, 1.5, (3, 7))
    amp = rng.uniform(0.3, 1.0, (3, 7))
    phase = rng.uniform(0, 2 * np.pi, (3, 7))
    a = np.einsum("kj,tkj->tj", amp, np.sin(2 * np.pi * freq[None] * t[:, None, None] + phase))
    scale = np.array([0.15, 0.15, 0.15, 0.15, 0.05, 0.05, 0.05])
    return np.clip(scale * a / 3.0, -1.0, 1.0)


class PushPlan:
    """The closed-loop "push": desired joint state from Jacobian steps, PD on it."""

    def __init__(self, m: mujoco.MjModel, d: mujoco.MjData) -> None:
        self.m = m
        self.q_d = d.qpos[:7].copy()
        self.tip = m.site("rod_tip").id
        self.rod = m.body("push_rod").id
        self.quat0 = d.xquat[self.rod].copy()

    def action(self, d: mujoco.MjData, t: int) -> np.ndarray:
        m = self.m
        v = np.array([0.0, -0.15, 0.0]) if t * DT >= 0.2 else np.zeros(3)
        jp = np.zeros((3, m.nv))
        jr = np.zeros((3, m.nv))
        mujoco.mj_jacSite(m, d, jp, None, self.tip)
        mujoco.mj_jacBody(m, d, None, jr, self.rod)
        # keep the rod's orientation: a rotation-rate command against the drift from quat0
        err = np.zeros(3)
        mujoco.mju_subQuat(err, self.quat0, d.xquat[self.rod])
        jac = np.vstack([jp[:, :7], jr[:, :7]])
        target = np.concatenate([v, 2.0 * err])
        dq_d = jac.T @ np.linalg.solve(jac @ jac.T + 1e-4 * np.eye(6), target)
        self.q_d = self.q_d + dq_d * DT
        a = KP * (self.q_d - d.qpos[:7]) + KD * (dq_d - d.qvel[:7])
        return np.clip(a, -1.0, 1.0)


def run(sequence: str) -> dict[str, np.ndarray]:
    env = make_env()
    m, d = env.model, env.data
    rod, box = rod_box_geoms(m)
    box_body, rod_body, tip = m.body("box_0").id, m.body("push_rod").id, m.site("rod_tip").id
    out: dict[str, list] = {k: [] for k in (
        "action", "q", "dq", "qpos", "qvel", "box_pos", "box_quat", "rod_tip", "rod_quat",
        "reward", "contact_end", "contact_any", "ncon",
    )}  # fmt: skip
    start = {
        "start_qpos": d.qpos.copy(), "start_qvel": d.qvel.copy(),
        "start_box_pos": d.xpos[box_body].copy(), "start_box_quat": d.xquat[box_body].copy(),
        "start_rod_tip": d.site_xpos[tip].copy(), "start_contact": touching(d, rod, box),
        "goal_pos": d.body("replan_target_pos").xpos.copy(),
        "goal_quat": d.body("replan_target_pos").xquat.copy(),
    }  # fmt: skip
    plan = PushPlan(m, d) if sequence == "push" else None
    fixed = smooth_random_actions() if sequence == "smooth_random" else None
    for t in range(STEPS):
        a = plan.action(d, t) if plan is not None else fixed[t]
        # the copy: the same motor command, one physics step at a time, contacts after each
        shadow = copy.copy(d)
        shadow.ctrl[:7] = np.clip(10 * np.clip(a, -1, 1) + d.qfrc_bias[:7], -TORQUE_MAX, TORQUE_MAX)
        any_contact = False
        for _ in range(FRAME_SKIP):
            mujoco.mj_step(m, shadow)
            any_contact |= touching(shadow, rod, box)
        _, r, terminated, truncated, info = env.step(a)
        assert np.array_equal(shadow.qpos, d.qpos) and np.array_equal(shadow.qvel, d.qvel)
        assert (terminated or truncated) == (t == STEPS - 1)
        out["action"].append(np.asarray(a, dtype=np.float64))
        out["q"].append(d.qpos[:7].copy())
        out["dq"].append(d.qvel[:7].copy())
        out["qpos"].append(d.qpos.copy())
        out["qvel"].append(d.qvel.copy())
        out["box_pos"].append(d.xpos[box_body].copy())
        out["box_quat"].append(d.xquat[box_body].copy())
        out["rod_tip"].append(d.site_xpos[tip].copy())
        out["rod_quat"].append(d.xquat[rod_body].copy())
        out["reward"].append(float(r))
        out["contact_end"].append(touching(d, rod, box))
        out["contact_any"].append(any_contact)
        out["ncon"].append(int(d.ncon))
    env.close()
    arrays = {k: np.asarray(v) for k, v in out.items()}
    arrays.update({k: np.asarray(v) for k, v in start.items()})
    return arrays


def main() -> None:
    data = {}
    summary = {}
    for seq in SEQUENCES:
        res = run(seq)
        for k, v in res.items():
            data[f"{seq}/{k}"] = v
        first = np.flatnonzero(res["contact_any"])
        summary[seq] = {
            "first_rod_box_contact_step": int(first[0]) if len(first) else None,
            "box_moved_m": float(np.linalg.norm(res["box_pos"][-1] - res["start_box_pos"])),
            "return": float(res["reward"].sum()),
        }
    np.savez_compressed(HERE / "box_pushing_steps.npz", **data)
    versions = {
        p: metadata.version(p) for p in ("fancy_gym", "mujoco", "gymnasium", "numpy", "mp_pytorch",
                                         "torch")
    }  # fmt: skip
    prov = {
        "what": "fancy-gym 0.3.0 BoxPushingTemporalSparse stepped with fixed actions",
        "script": "make_reference.py",
        "date": datetime.date.today().isoformat(),
        "python": platform.python_version(),
        "platform": platform.platform(),
        **versions,
        "pip": 'pip install "fancy-gym==0.3.0" "mujoco==2.3.3" "gymnasium==0.29.1" '
               '"numpy<2" "mp_pytorch==0.1.3"',
        "seed": SEED,
        "goal": {"x": GOAL[0], "y": GOAL[1], "yaw": GOAL[2], "z": GOAL_Z},
        "steps": STEPS,
        "frame_skip": FRAME_SKIP,
        "sequences": summary,
        "argv": sys.argv,
    }  # fmt: skip
    (HERE / "provenance.json").write_text(json.dumps(prov, indent=1) + "\n")
    print(json.dumps(summary, indent=1))


if __name__ == "__main__":
    main()
