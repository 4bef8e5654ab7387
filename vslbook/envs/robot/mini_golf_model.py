"""The MuJoCo model of Robot Mini Golf (thesis Section 4.5.1, Appendix B.4.4).

No loadable MIT model file of the mini-golf scene exists (fancy-gym 0.3.0 has none), so the
scene is built here with the :class:`mujoco.MjSpec` API on the Franka Panda with push rod of
fancy-gym 0.3.0's ``box_pushing/assets/box_pushing.xml`` (read from the installed wheel by
:func:`vslbook.envs.robot.assets.load_spec`, ``collision="all"`` dropped as for Box
Pushing; no model file is copied). The box and the two target markers of that file are
deleted; the timestep (0.002 s), the solver options (Newton, elliptic cones, impratio 3)
and the table stay as they are.

Scene (world coordinates, metres; the table top lies at z = −0.019; the ball rolls from
y = 0.5 towards the goal line y = −0.7):

* **Club** (``push_rod``): the rod cylinder becomes ``rod_contact`` with radius 0.015
  (half-length 0.15, as before), a club head ``rod_contact2`` (box, half-size 0.03 × 0.02 ×
  0.015 at (0.015, 0, 0.225) in the rod frame) is added, and the ``rod_tip`` site moves to
  the head's height (0, 0, 0.225), half-size 0.015: the authors' mini-golf rod.
* **Ball** (``ball``, free joint ``ball_joint``): sphere ``ball_contact`` of radius 0.025,
  mass 0.05, friction (0.1, 0.1, 0.1), ``condim`` 4, ``solref`` (0.1, 0.03), ``solimp``
  (0.9, 0.95, 0.001, 0.5, 2), priority 1 (so its contact parameters win in every contact),
  with the site ``target_ball`` at its centre. It starts at (x_ball, 0.5, 0.005).
* **Side walls** (body ``walls``): ``side_wall_left`` at x = 0.15 and ``side_wall_right``
  at x = 0.7, centred at (·, −0.05, 0.025), half-size 0.005 × 0.65 × 0.08 (y ∈ [−0.7, 0.6]).
* **Static obstacle** (``static_obstacle``, geom ``static_obstacle_geom``): half-size
  0.02 × 0.02 × 0.1 at (0.425, −0.0625, 0) (the authors' ``static_obstacle_box_2``).
* **Moving obstacle** (``obstacle``, geom ``obstacle_geom``): half-size 0.03 × 0.03 × 0.1, a
  **mocap** body moved to the context's (x_obs, y_obs, 0) at reset (the authors'
  ``obstacle_box_1``, the green box; their heavy 2000 kg welded box is in effect immovable
  too, and a mocap body keeps the compiled model the same for every context).
* **Goal** (``goal``, mocap body at (x_goal, −0.7, 0)): walls ``goal_wall_left`` and
  ``goal_wall_right`` of half-size 0.4 × 0.005 × 0.08 at x_goal ∓ 0.428 (z centre 0.025),
  which leaves a gap of 2 · (0.428 − 0.4) = **0.056 m** for the 0.05 m ball, centred at
  x_goal; the site ``ball_target`` at (x_goal, −0.7, 0.005) is the goal point of the reward.
* **Goal ceiling** (``goal_ceiling``, static): a thin wall of half-size 1.25 × 0.005 × 0.85
  at (0.175, −0.7, 0.95), nearly transparent, closing the goal line above z = 0.1 so a lofted
  ball cannot fly over the goal walls (as in the authors' scene).

All walls and obstacles have friction (0.3, 0.001, 0.0001) and ``solref`` (0.1, 0.03) (the
authors' file writes ``"0.1, 0.03"``, which MuJoCo 3 rejects); their nominal mass 2000 kg
is kept for the record (they are welded or mocap bodies). The authors' 6-D variant has a
second moving (red) box, ``obstacle_box_0``; the 4-D task of the thesis parks it out of
reach at (5, 5, 5), so it is left out here.
"""

from __future__ import annotations

import mujoco
import numpy as np

from vslbook.envs.robot.assets import load_spec
from vslbook.envs.robot.box_pushing_model import MODEL_FILE, PATCHES

BALL_RADIUS = 0.025
BALL_MASS = 0.05
BALL_START_Y, BALL_START_Z = 0.5, 0.005
SIDE_WALL_X = (0.15, 0.7)
SIDE_WALL_HALF = (0.005, 0.65, 0.08)
SIDE_WALL_CENTRE_YZ = (-0.05, 0.025)
STATIC_OBSTACLE_POS = (0.425, -0.0625, 0.0)
STATIC_OBSTACLE_HALF = (0.02, 0.02, 0.1)
OBSTACLE_HALF = (0.03, 0.03, 0.1)
OBSTACLE_Z = 0.0
GOAL_Y = -0.7
GOAL_WALL_OFFSET = 0.428
GOAL_WALL_HALF = (0.4, 0.005, 0.08)
GOAL_WALL_Z = 0.025
GOAL_SITE_Z = 0.005
#: Width of the opening between the goal walls (2 · (0.428 − 0.4) = 0.056 m).
GOAL_GAP = 2.0 * (GOAL_WALL_OFFSET - GOAL_WALL_HALF[0])
CEILING_POS = (0.175, -0.7, 0.95)
CEILING_HALF = (1.25, 0.005, 0.85)
ROD_RADIUS = 0.015
ROD_HEAD_POS = (0.015, 0.0, 0.225)
ROD_HEAD_HALF = (0.03, 0.02, 0.015)
ROD_TIP_POS = (0.0, 0.0, 0.225)

_BOX = mujoco.mjtGeom.mjGEOM_BOX
_WALL_FRICTION = [0.3, 0.001, 0.0001]
_WALL_SOLREF = [0.1, 0.03]
_WALL_MASS = 2000.0


def _add_box(body: mujoco.MjsBody, name: str, pos, size, rgba) -> mujoco.MjsGeom:
    return body.add_geom(
        name=name, type=_BOX, pos=list(pos), size=list(size), rgba=list(rgba),
        mass=_WALL_MASS, friction=_WALL_FRICTION, solref=_WALL_SOLREF,
    )  # fmt: skip


def build_spec() -> mujoco.MjSpec:
    """The editable spec: the Panda with the mini-golf club, ball, walls, obstacles, goal."""
    spec = load_spec(MODEL_FILE, PATCHES)
    for name in ("box_0", "target_pos", "replan_target_pos"):
        spec.delete(spec.body(name))

    rod = spec.body("push_rod")
    if len(rod.geoms) != 1 or len(rod.sites) != 1:  # pragma: no cover - guards a changed file
        raise RuntimeError(f"unexpected push rod in {MODEL_FILE}")
    shaft = rod.geoms[0]
    shaft.name = "rod_contact"
    shaft.size = [ROD_RADIUS, shaft.size[1], 0.0]
    rod.add_geom(
        name="rod_contact2", type=_BOX, pos=list(ROD_HEAD_POS), size=list(ROD_HEAD_HALF),
        rgba=[0.0, 1.0, 1.0, 1.0],
    )  # fmt: skip
    tip = rod.sites[0]
    tip.pos = list(ROD_TIP_POS)
    tip.size = [0.015, 0.015, 0.01]

    world = spec.worldbody
    ball = world.add_body(name="ball", pos=[0.425, BALL_START_Y, BALL_START_Z])
    ball.add_freejoint(name="ball_joint")
    ball.add_geom(
        name="ball_contact", type=mujoco.mjtGeom.mjGEOM_SPHERE, size=[BALL_RADIUS, 0.0, 0.0],
        mass=BALL_MASS, friction=[0.1, 0.1, 0.1], condim=4, solref=[0.1, 0.03],
        solimp=[0.9, 0.95, 0.001, 0.5, 2.0], priority=1, rgba=[1.0, 1.0, 0.0, 1.0],
    )  # fmt: skip
    ball.add_site(
        name="target_ball", type=mujoco.mjtGeom.mjGEOM_SPHERE, size=[0.02, 0.02, 0.02],
        rgba=[1.0, 0.0, 0.0, 1.0],
    )  # fmt: skip

    walls = world.add_body(name="walls")
    y, z = SIDE_WALL_CENTRE_YZ
    _add_box(walls, "side_wall_left", (SIDE_WALL_X[0], y, z), SIDE_WALL_HALF, (1, 0, 0, 1))
    _add_box(walls, "side_wall_right", (SIDE_WALL_X[1], y, z), SIDE_WALL_HALF, (0, 1, 1, 1))

    static = world.add_body(name="static_obstacle", pos=list(STATIC_OBSTACLE_POS))
    _add_box(static, "static_obstacle_geom", (0, 0, 0), STATIC_OBSTACLE_HALF, (0, 0, 1, 1))

    obstacle = world.add_body(name="obstacle", mocap=True, pos=[0.4, -0.1, OBSTACLE_Z])
    _add_box(obstacle, "obstacle_geom", (0, 0, 0), OBSTACLE_HALF, (0, 1, 0, 1))

    goal = world.add_body(name="goal", mocap=True, pos=[0.425, GOAL_Y, 0.0])
    for name, sign in (("goal_wall_left", -1.0), ("goal_wall_right", 1.0)):
        pos = (sign * GOAL_WALL_OFFSET, 0.0, GOAL_WALL_Z)
        _add_box(goal, name, pos, GOAL_WALL_HALF, (0, 0, 1, 1))
    goal.add_site(
        name="ball_target", type=mujoco.mjtGeom.mjGEOM_SPHERE, pos=[0.0, 0.0, GOAL_SITE_Z],
        size=[BALL_RADIUS, 0.0, 0.0], rgba=[1.0, 0.0, 0.0, 0.5],
    )  # fmt: skip

    ceiling = world.add_body(name="goal_ceiling")
    _add_box(ceiling, "goal_ceiling_geom", CEILING_POS, CEILING_HALF, (0, 0, 1, 0.05))
    return spec


def build_model() -> mujoco.MjModel:
    """The compiled model (timestep 0.002 as in the file)."""
    model = build_spec().compile()
    if not np.isclose(model.opt.timestep, 0.002):  # pragma: no cover - guards a changed file
        raise RuntimeError(f"unexpected timestep {model.opt.timestep} in {MODEL_FILE}")
    return model
