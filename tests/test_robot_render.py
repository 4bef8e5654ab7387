"""Scenes of the robot tasks (EpisodicTask.scene) and their offscreen pictures.

The scene tests read the MuJoCo state by the model's own names and compare it with the
context, independently of how each task places things. The picture test renders in a
subprocess with Mesa's OSMesa (the test process keeps MUJOCO_GL=disable).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys

import numpy as np
import pytest

from vslbook.envs.robot import make_task
from vslbook.envs.robot.render import CAMERAS, render_scene


def _context(name: str, seed: int = 0) -> np.ndarray:
    task = make_task(name)
    return task.sample_contexts(1, np.random.default_rng(seed))[0]


def test_box_pushing_scene_places_goal_and_obstacle():
    task = make_task("box-pushing-obstacle")
    c = _context("box-pushing-obstacle")
    m, d = task.scene(c)
    obstacle = d.xpos[m.body("obstacle").id]
    goal = d.xpos[m.body("target_pos").id]
    np.testing.assert_allclose(obstacle[:2], c[3:5], atol=1e-9)
    np.testing.assert_allclose(goal[:2], c[:2], atol=1e-9)
    # the goal's yaw is the context's angle: its x axis turned by c[2] about z
    x_axis = d.xmat[m.body("target_pos").id].reshape(3, 3)[:, 0]
    np.testing.assert_allclose(x_axis[:2], [np.cos(c[2]), np.sin(c[2])], atol=1e-6)


def test_reacher_scene_puts_the_target_at_the_goal():
    task = make_task("reacher5")
    c = _context("reacher5")
    m, d = task.scene(c)
    np.testing.assert_allclose(d.xpos[m.body("target").id][:2], c, atol=1e-9)


def test_beer_pong_scene_puts_the_cup_at_the_context():
    task = make_task("beer-pong")
    c = _context("beer-pong")
    m, d = task.scene(c)
    np.testing.assert_allclose(d.xpos[m.body("cup_table").id][:2], c, atol=1e-9)


def test_table_tennis_scene_serves_the_ball_and_marks_the_goal():
    task = make_task("table-tennis-4d")
    c = _context("table-tennis-4d")
    m, d = task.scene(c)
    ball = d.xpos[m.body("target_ball").id]
    goal = d.xpos[m.body("target_point").id]
    # context order [ball x, ball y, goal x, goal y] (the thesis's); the goal lies on the table
    np.testing.assert_allclose(ball[:2], c[:2], atol=1e-9)
    np.testing.assert_allclose(goal[:2], c[2:4], atol=1e-9)


def test_hopper_scene_moves_the_goal():
    task = make_task("hopper-jump")
    c = _context("hopper-jump")
    m, d = task.scene(c)
    assert d.xpos[m.body("goal_site_body").id][0] == pytest.approx(c[3])


def test_scene_rejects_bad_contexts():
    task = make_task("box-pushing-obstacle")
    with pytest.raises(ValueError, match="one context"):
        task.scene(task.sample_contexts(2, np.random.default_rng(0)))
    with pytest.raises(ValueError, match="outside"):
        task.scene(np.full(task.context_dim, 99.0))
    with pytest.raises(NotImplementedError, match="no MuJoCo scene"):
        make_task("planar-reacher").scene(np.array([5.0, 0.0]))


def test_render_refuses_without_an_offscreen_backend(monkeypatch):
    monkeypatch.setenv("MUJOCO_GL", "disable")
    task = make_task("reacher5")
    with pytest.raises(RuntimeError, match="MUJOCO_GL"):
        render_scene(task, _context("reacher5"))


def test_every_simulated_task_has_a_camera():
    from vslbook.envs.robot import TASKS

    assert set(TASKS) - set(CAMERAS) == {"planar-reacher"}


_RENDER = r"""
import json, sys
import numpy as np
from vslbook.envs.robot import make_task
from vslbook.envs.robot.render import render_scene
task = make_task("reacher5")
out = {}
for key, goal in (("a", [0.3, 0.2]), ("b", [-0.3, -0.2])):
    img = render_scene(task, np.array(goal), width=160, height=120)
    out[key] = img.tolist()
json.dump(out, sys.stdout)
"""


@pytest.mark.slow
def test_pictures_render_and_follow_the_context():
    env = {**os.environ, "MUJOCO_GL": "osmesa", "OMP_NUM_THREADS": "1"}
    proc = subprocess.run(
        [sys.executable, "-c", _RENDER], capture_output=True, text=True, env=env, timeout=300
    )
    assert proc.returncode == 0, proc.stderr[-2000:]
    imgs = {k: np.array(v, dtype=np.uint8) for k, v in json.loads(proc.stdout).items()}
    a, b = imgs["a"], imgs["b"]
    assert a.shape == (120, 160, 3)
    assert a.std() > 10, "a flat picture: nothing was drawn"
    # only the target moves: a small part of the picture changes, in two places
    changed = np.abs(a.astype(int) - b.astype(int)).sum(-1) > 30
    assert 0 < changed.mean() < 0.05
    rows, cols = np.nonzero(changed)
    assert cols.max() - cols.min() > 40, "the target should move across the picture"


# -- projection of world points onto the picture -----------------------------------------------
def test_project_by_hand():
    from vslbook.envs.robot.render import Camera, project

    # azimuth 90, elevation 0: the camera looks along +y from (0, -2, 0); right is +x, up +z
    cam = Camera((0.0, 0.0, 0.0), 2.0, 90.0, 0.0)
    pts = np.array([[0.0, 0.0, 0.0], [0.5, 0.0, 0.25], [0.5, 2.0, 0.0], [0.0, -3.0, 0.0]])
    px = project(cam, pts, 200, 100, fovy=90.0)
    f = 50.0  # (h/2) / tan(45°)
    np.testing.assert_allclose(px[0], [99.5, 49.5])  # the look-at point: the picture's centre
    np.testing.assert_allclose(px[1], [99.5 + f * 0.5 / 2, 49.5 - f * 0.25 / 2])
    np.testing.assert_allclose(px[2], [99.5 + f * 0.5 / 4, 49.5])  # twice as deep: half the shift
    assert np.isnan(px[3]).all()  # behind the camera
    # looking straight down (elevation -90 would be degenerate; -89°): +x goes up the picture
    # for azimuth 0, i.e. to smaller rows
    top = Camera((0.0, 0.0, 0.0), 1.0, 0.0, -89.0)
    a, b = project(top, np.array([[0.0, 0.0, 0.0], [0.1, 0.0, 0.0]]), 100, 100, fovy=45.0)
    assert b[1] < a[1] and abs(b[0] - a[0]) < 1e-9
    with pytest.raises(ValueError, match=r"shape \(n, 3\)"):
        project(cam, np.zeros((2, 2)), 10, 10, fovy=45.0)
    with pytest.raises(ValueError, match="fovy"):
        project(cam, pts, 10, 10, fovy=0.0)
    with pytest.raises(ValueError, match="width"):
        project(cam, pts, 0, 10, fovy=45.0)


_MARKERS = r"""
import json, sys
import mujoco
import numpy as np
from vslbook.envs.robot.render import Camera, project, render_data
spheres = {"red": ([0.3, -0.2, 0.1], "1 0 0 1"), "green": ([-0.25, 0.15, 0.3], "0 1 0 1"),
           "blue": ([0.05, 0.35, -0.15], "0 0 1 1")}
geoms = "".join(
    f'<geom type="sphere" size="0.012" pos="{p[0]} {p[1]} {p[2]}" rgba="{c}" material="glow"/>'
    for p, c in spheres.values())
xml = f'''<mujoco><visual><global fovy="35"/></visual>
<asset><material name="glow" emission="1" specular="0"/></asset>
<worldbody>{geoms}</worldbody></mujoco>'''
model = mujoco.MjModel.from_xml_string(xml)
data = mujoco.MjData(model)
mujoco.mj_forward(model, data)
cam = Camera((0.02, 0.05, 0.03), 1.4, 130.0, -30.0)
img = render_data(model, data, cam, width=160, height=120)
px = project(cam, np.array([p for p, _ in spheres.values()]), 160, 120,
             fovy=float(model.vis.global_.fovy))
json.dump({"img": img.tolist(), "px": px.tolist(), "names": list(spheres)}, sys.stdout)
"""


@pytest.mark.slow
def test_project_matches_rendered_markers():
    """Three small glowing spheres in an otherwise empty scene: the centroid of each one's
    pixels in MuJoCo's own picture lies where project() puts its centre."""
    env = {**os.environ, "MUJOCO_GL": "osmesa", "OMP_NUM_THREADS": "1"}
    proc = subprocess.run(
        [sys.executable, "-c", _MARKERS], capture_output=True, text=True, env=env, timeout=300
    )
    assert proc.returncode == 0, proc.stderr[-2000:]
    out = json.loads(proc.stdout)
    img = np.array(out["img"], dtype=int)
    for k, (name, want) in enumerate(zip(out["names"], out["px"], strict=True)):
        others = [c for c in range(3) if c != k]
        mask = (img[..., k] > 120) & (img[..., others].max(axis=-1) < 60)
        assert 3 <= mask.sum() < 100, f"{name}: {mask.sum()} pixels"
        rows, cols = np.nonzero(mask)
        centroid = np.array([cols.mean(), rows.mean()])
        assert np.linalg.norm(centroid - want) < 1.0, (name, centroid, want)
