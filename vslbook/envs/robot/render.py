"""Pictures of the robot tasks: an offscreen MuJoCo render of a task's scene.

:func:`render_scene` draws :meth:`EpisodicTask.scene` (the start of an episode in one
context) from the task's camera in :data:`CAMERAS`. Offscreen rendering needs an OpenGL
backend without a screen, set before MuJoCo is first imported: ``MUJOCO_GL=osmesa`` (Mesa's
software renderer, which ``make setup`` installs; about 0.5 s for a 400 × 300 picture on
one core) or ``egl`` where a GPU exists. With ``MUJOCO_GL=disable``
(what the tests use) :func:`render_scene` raises a clear error instead of failing deep
inside MuJoCo.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from typing import Any

import numpy as np

from vslbook.envs.robot.task import EpisodicTask

GL_BACKENDS = ("egl", "osmesa", "glfw")


@dataclass(frozen=True)
class Camera:
    """A free camera: the point it looks at, its distance, azimuth and elevation (degrees)."""

    lookat: tuple[float, float, float]
    distance: float
    azimuth: float
    elevation: float


#: task name → the camera its pictures are taken from.
CAMERAS: dict[str, Camera] = {
    "reacher5": Camera((0.0, 0.0, 0.0), 1.15, 90.0, -89.0),
    "reacher5-ch3": Camera((0.0, 0.0, 0.0), 1.15, 90.0, -89.0),
    "table-tennis-4d": Camera((0.4, 0.0, 0.9), 3.6, 150.0, -25.0),
    "table-tennis-hard": Camera((0.4, 0.0, 0.9), 3.6, 150.0, -25.0),
    "table-tennis-ch3": Camera((0.4, 0.0, 0.9), 3.6, 150.0, -25.0),
    "beer-pong": Camera((0.0, -0.9, 0.9), 3.4, 160.0, -28.0),
    "hopper-jump": Camera((0.9, 0.0, 0.7), 4.2, 90.0, -12.0),
    "box-pushing-obstacle": Camera((0.45, -0.1, 0.0), 2.2, 180.0, -60.0),
    "mini-golf": Camera((0.45, -0.1, 0.0), 2.2, 180.0, -60.0),
}


def gl_backend() -> str:
    """The offscreen backend MuJoCo will use, or a clear error if rendering is off."""
    backend = os.environ.get("MUJOCO_GL", "")
    if backend not in GL_BACKENDS:
        raise RuntimeError(
            f"offscreen rendering needs MUJOCO_GL set to one of {GL_BACKENDS} before MuJoCo "
            f"is imported; it is {backend!r}"
        )
    return backend


def render_scene(
    task: EpisodicTask,
    context: Any,
    *,
    width: int = 480,
    height: int = 360,
    camera: Camera | None = None,
) -> np.ndarray:
    """An ``(height, width, 3)`` uint8 picture of ``task`` at the start of ``context``."""
    gl_backend()
    for name, value in (("width", width), ("height", height)):
        if not isinstance(value, int) or not 16 <= value <= 4096:
            raise ValueError(f"{name} must be an int in [16, 4096], got {value!r}")
    if camera is None:
        if task.name not in CAMERAS:
            raise ValueError(f"no camera for task {task.name!r}; known: {sorted(CAMERAS)}")
        camera = CAMERAS[task.name]
    model, data = task.scene(context)
    return render_data(model, data, camera, width=width, height=height)


def render_data(
    model: Any, data: Any, camera: Camera, *, width: int = 480, height: int = 360
) -> np.ndarray:
    """An ``(height, width, 3)`` uint8 picture of the MuJoCo state ``data`` (forwarded)."""
    import mujoco

    gl_backend()
    cam = mujoco.MjvCamera()
    cam.type = mujoco.mjtCamera.mjCAMERA_FREE
    cam.lookat[:] = camera.lookat
    cam.distance, cam.azimuth, cam.elevation = camera.distance, camera.azimuth, camera.elevation
    # the offscreen buffer must hold the picture
    model.vis.global_.offwidth = max(model.vis.global_.offwidth, width)
    model.vis.global_.offheight = max(model.vis.global_.offheight, height)
    with mujoco.Renderer(model, height, width) as renderer:
        renderer.update_scene(data, camera=cam)
        return renderer.render().copy()
