"""Pictures of the robot tasks: an offscreen MuJoCo render of a task's scene.

:func:`render_scene` draws :meth:`EpisodicTask.scene` (the start of an episode in one
context) from the task's camera in :data:`CAMERAS`. Offscreen rendering needs an OpenGL
backend without a screen, set before MuJoCo is first imported: ``MUJOCO_GL=osmesa`` (Mesa's
software renderer, which ``make setup`` installs; about 0.5 s for a 400 × 300 picture on
one core) or ``egl`` where a GPU exists. With ``MUJOCO_GL=disable``
(what the tests use) :func:`render_scene` raises a clear error instead of failing deep
inside MuJoCo.

Paths over a picture: :func:`project` maps world points to the picture's pixels under a
free camera (pure numpy, no rendering), :func:`render_paths` renders a scene and projects an
episode's paths (:meth:`EpisodicTask.path`) onto it, and :func:`draw_path` draws projected
points on a matplotlib axis that shows the picture.
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
        camera = _camera_of(task)
    model, data = task.scene(context)
    return render_data(model, data, camera, width=width, height=height)


def _camera_of(task: EpisodicTask) -> Camera:
    if task.name not in CAMERAS:
        raise ValueError(f"no camera for task {task.name!r}; known: {sorted(CAMERAS)}")
    return CAMERAS[task.name]


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


def camera_frame(camera: Camera) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """``(position, forward, up, right)`` of a free camera in world coordinates.

    MuJoCo's free camera (``mjv_updateCamera``): with azimuth a and elevation e (degrees),
    forward = (cos e cos a, cos e sin a, sin e), up = (−sin e cos a, −sin e sin a, cos e),
    right = forward × up, and the camera sits ``distance`` behind ``lookat`` along forward.
    """
    a, e = np.radians(camera.azimuth), np.radians(camera.elevation)
    forward = np.array([np.cos(e) * np.cos(a), np.cos(e) * np.sin(a), np.sin(e)])
    up = np.array([-np.sin(e) * np.cos(a), -np.sin(e) * np.sin(a), np.cos(e)])
    right = np.cross(forward, up)
    position = np.asarray(camera.lookat, dtype=np.float64) - camera.distance * forward
    return position, forward, up, right


def project(camera: Camera, points: Any, width: int, height: int, *, fovy: float) -> np.ndarray:
    """Pixel coordinates ``(n, 2)`` (x right, y down) of world points ``(n, 3)``.

    A pinhole camera with MuJoCo's free-camera frame (:func:`camera_frame`) and vertical
    field of view ``fovy`` in degrees (the model's ``vis.global_.fovy``, 45 by default): a
    point at depth z, right offset r and up offset u lands at
    ``x = w/2 + f r / z − ½``, ``y = h/2 − f u / z − ½`` with the focal length
    ``f = (h/2) / tan(fovy/2)`` in pixels. The −½ puts the centre of pixel (i, j) at (i, j),
    the convention of matplotlib's ``imshow``. Points behind the camera give NaN.
    """
    pts = np.asarray(points, dtype=np.float64)
    if pts.ndim != 2 or pts.shape[1] != 3:
        raise ValueError(f"points must have shape (n, 3), got {pts.shape}")
    for name, value in (("width", width), ("height", height)):
        if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 1:
            raise ValueError(f"{name} must be a positive int, got {value!r}")
    if not (isinstance(fovy, (int, float, np.floating)) and 0.0 < float(fovy) < 180.0):
        raise ValueError(f"fovy must be an angle in degrees in (0, 180), got {fovy!r}")
    position, forward, up, right = camera_frame(camera)
    rel = pts - position
    depth = rel @ forward
    f = 0.5 * height / np.tan(np.radians(float(fovy)) / 2.0)
    with np.errstate(divide="ignore", invalid="ignore"):
        x = 0.5 * width + f * (rel @ right) / depth - 0.5
        y = 0.5 * height - f * (rel @ up) / depth - 0.5
    out = np.column_stack([x, y])
    out[depth <= 0] = np.nan
    return out


def render_paths(
    task: EpisodicTask,
    theta: Any,
    context: Any,
    *,
    width: int = 480,
    height: int = 360,
    camera: Camera | None = None,
) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """The picture of :func:`render_scene` and the episode's paths in its pixels.

    Returns ``(picture (height, width, 3) uint8, name → (T, 2) pixel coordinates)``, the
    paths of :meth:`EpisodicTask.path` for (θ, c) projected with :func:`project` (the
    model's ``fovy``); draw them with :func:`draw_path`.
    """
    camera = camera if camera is not None else _camera_of(task)
    paths = task.path(theta, context)
    picture = render_scene(task, context, width=width, height=height, camera=camera)
    model, _ = task.scene(context)
    fovy = float(model.vis.global_.fovy)
    return picture, {k: project(camera, v, width, height, fovy=fovy) for k, v in paths.items()}


def draw_path(ax: Any, pixels: Any, *, start_marker: str = "o", **style: Any) -> list[Any]:
    """Draw projected points ``(T, 2)`` on a matplotlib axis showing the picture: a line
    through them and a marker at the first point. ``style`` goes to ``ax.plot`` (colour,
    width, label, ...). Returns the matplotlib artists; the axis limits are kept."""
    px = np.asarray(pixels, dtype=np.float64)
    if px.ndim != 2 or px.shape[1] != 2:
        raise ValueError(f"pixels must have shape (T, 2), got {px.shape}")
    xlim, ylim = ax.get_xlim(), ax.get_ylim()
    style = {"lw": 1.5, **style}
    artists = list(ax.plot(px[:, 0], px[:, 1], **style))
    if len(px) and start_marker:
        color = artists[0].get_color()
        artists += ax.plot(px[:1, 0], px[:1, 1], start_marker, color=color, ms=4)
    ax.set_xlim(xlim)
    ax.set_ylim(ylim)
    return artists
