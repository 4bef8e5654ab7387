"""The MuJoCo model of Box Pushing with Obstacle (thesis Section 4.5.1, Appendix B.4.2.1).

fancy-gym 0.3.0 ships only ``box_pushing/assets/box_pushing.xml`` (Franka Panda with a push
rod, the box on a free joint, the target markers); it is read from the installed wheel with
:func:`vslbook.envs.robot.assets.load_spec` (``collision="all"`` dropped: MuJoCo 3 rejects
it) and edited here with the :class:`mujoco.MjSpec` API; no model file is copied.

Edits:

* **Obstacle** (``obstacle``): a box of half-size 0.05×0.05×0.01 (mass 2000, friction
  (0.3, 0.001, 0.0001), priority 1) with four thin side walls (half-size 0.005 × 0.05 ×
  0.045, centred 0.0485 above the base), i.e. a copy in shape of the box. It is a **mocap**
  body: it is moved to the context's (x_o, y_o) at reset through ``data.mocap_pos``, and it
  collides as an immovable body (the heavy 2000 kg body of the authors' model is in effect
  immovable as well; a mocap body cannot tip or slide and needs no extra degrees of freedom,
  so ``qpos`` keeps the layout of the original model). Its masses are kept for the record.
* **Targets** (``target_pos``, ``replan_target_pos``, sites only) become mocap bodies as
  well, so the goal pose is set in ``data`` and the compiled model never changes between
  episodes.

``obstacle=False`` leaves the obstacle out: the scene of fancy-gym 0.3.0's box pushing
(``BoxPushingDense`` and its siblings), which the step-by-step physics check
(``tests/test_box_pushing_reference.py``) compares against.
"""

from __future__ import annotations

import mujoco
import numpy as np

from vslbook.envs.robot.assets import load_spec

MODEL_FILE = "box_pushing/assets/box_pushing.xml"
PATCHES = (('collision="all" ', ""),)

#: Height of the obstacle's (and the box's) body frame above the world origin.
OBSTACLE_Z = -0.01
OBSTACLE_HALF = (0.05, 0.05, 0.01)
WALL_HEIGHT = 0.045
_WALL_T = 0.005
_GEOM_BOX = mujoco.mjtGeom.mjGEOM_BOX


def build_spec(obstacle: bool = True) -> mujoco.MjSpec:
    """The editable spec: fancy-gym's box pushing model with mocap targets, plus the
    obstacle unless ``obstacle`` is False."""
    spec = load_spec(MODEL_FILE, PATCHES)
    for name in ("target_pos", "replan_target_pos"):
        spec.body(name).mocap = True
    if not obstacle:
        return spec
    body = spec.worldbody.add_body(name="obstacle", mocap=True, pos=[0.4, 0.0, OBSTACLE_Z])
    hx, hy, hz = OBSTACLE_HALF
    body.add_geom(
        name="obstacle_base", type=_GEOM_BOX, size=[hx, hy, hz], mass=2000.0,
        friction=[0.3, 0.001, 0.0001], priority=1, rgba=[0.8, 0.1, 0.1, 1.0],
    )  # fmt: skip
    zc = WALL_HEIGHT + 0.0035  # wall centre above the base (0.0485 as in the box)
    walls = (
        ((hx, 0.0, zc), (_WALL_T, hy, WALL_HEIGHT)),
        ((0.0, hy, zc), (hx, _WALL_T, WALL_HEIGHT)),
        ((-hx, 0.0, zc), (_WALL_T, hy, WALL_HEIGHT)),
        ((0.0, -hy, zc), (hx, _WALL_T, WALL_HEIGHT)),
    )
    for i, (pos, size) in enumerate(walls):
        body.add_geom(
            name=f"obstacle_wall{i}", type=_GEOM_BOX, pos=list(pos), size=list(size),
            mass=1.0, rgba=[0.8, 0.1, 0.1, 1.0],
        )  # fmt: skip
    return spec


def build_model(obstacle: bool = True) -> mujoco.MjModel:
    """The compiled model (timestep 0.002 as in the file), with or without the obstacle."""
    model = build_spec(obstacle).compile()
    if not np.isclose(model.opt.timestep, 0.002):  # pragma: no cover - guards a changed file
        raise RuntimeError(f"unexpected timestep {model.opt.timestep} in {MODEL_FILE}")
    return model
