"""The MuJoCo model of Beer Pong (thesis Section 3.4, Appendix A.3.2) and its PD actuators.

Holds the model file and its in-memory patch (:data:`MODEL`, :data:`MODEL_PATCHES`), the arm's
PD gains (:data:`P_GAINS`, :data:`D_GAINS`) and :func:`use_pd_actuators`, which turns the
file's seven arm motors into MuJoCo's form of the PD law's feedback part. How the task applies
the law, and everything else about the task, is in :mod:`vslbook.envs.robot.beer_pong`, which
re-exports these names.
"""

from __future__ import annotations

import mujoco
import numpy as np

__all__ = ["D_GAINS", "MODEL", "MODEL_PATCHES", "N_DOF", "P_GAINS", "use_pd_actuators"]

MODEL = "beerpong/assets/beerpong_wo_cup.xml"
MODEL_PATCHES = (("../../meshes/wam/", "./meshes/wam/"),)
N_DOF = 7
P_GAINS = np.array([200.0, 300.0, 100.0, 100.0, 10.0, 10.0, 2.5])
D_GAINS = 0.5 * np.array([7.0, 15.0, 5.0, 2.5, 0.3, 0.3, 0.05])


def use_pd_actuators(model: mujoco.MjModel) -> None:
    """Make the model's 7 arm motors (in memory) MuJoCo's form of the PD law's feedback part.

    Each becomes a ``general`` actuator on its arm joint with gear 1, gain 1 on ctrl and the
    affine bias [0, −K_p,j, −K_d,j], no activation and no ctrl or force limits, so its force is
    ``ctrl_j − K_p,j q_j − K_d,j q̇_j`` (q, q̇ of the step, from ``mj_step1``); with
    ctrl = K_p q_d + K_d q̇_d that is the PD part of the control law (module docstring). Raises
    if the model has anything else that would change that force (actuator plugins, delays,
    activations, actuator damping or armature, joint-level actuator force limits or gravity
    compensation, disabled actuation) or is not integrated with Euler, which treats actuator
    forces explicitly (``implicitfast`` would take K_d implicitly).
    """
    m = model
    arm = np.arange(N_DOF)
    if (
        m.nu != N_DOF
        or not np.all(m.actuator_trntype == mujoco.mjtTrn.mjTRN_JOINT)
        or not np.array_equal(m.actuator_trnid[:, 0], arm)
        or not np.array_equal(m.jnt_dofadr[arm], arm)
        or not np.all(m.jnt_type[arm] == mujoco.mjtJoint.mjJNT_HINGE)
    ):
        raise RuntimeError(f"{MODEL}: expected one motor on each arm joint 0..6 (dofs 0..6)")
    if (
        np.any(m.actuator_actnum) or np.any(m.actuator_delay) or np.any(m.actuator_plugin >= 0)
        or np.any(m.actuator_damping) or np.any(m.actuator_dampingpoly)
        or np.any(m.actuator_armature) or np.any(m.jnt_actfrclimited[arm])
        or np.any(m.jnt_actgravcomp[arm])
        or m.opt.disableflags & mujoco.mjtDisableBit.mjDSBL_ACTUATION
        or m.opt.integrator != mujoco.mjtIntegrator.mjINT_EULER
    ):  # fmt: skip
        raise RuntimeError(f"{MODEL}: its actuators or options would change the PD law")
    m.actuator_dyntype[:] = mujoco.mjtDyn.mjDYN_NONE
    m.actuator_gaintype[:] = mujoco.mjtGain.mjGAIN_FIXED
    m.actuator_gainprm[:] = 0.0
    m.actuator_gainprm[:, 0] = 1.0
    m.actuator_biastype[:] = mujoco.mjtBias.mjBIAS_AFFINE
    m.actuator_biasprm[:] = 0.0
    m.actuator_biasprm[:, 1] = -P_GAINS
    m.actuator_biasprm[:, 2] = -D_GAINS
    m.actuator_gear[:] = 0.0
    m.actuator_gear[:, 0] = 1.0
    m.actuator_ctrllimited[:] = False
    m.actuator_forcelimited[:] = False
