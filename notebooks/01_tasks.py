# ---
# jupyter:
#   jupytext:
#     text_representation:
#       extension: .py
#       format_name: percent
#   kernelspec:
#     display_name: Python 3
#     language: python
#     name: python3
# ---

# %% [markdown]
# # The robot tasks of Chapters 3 and 4
#
# Chapters 3 and 4 learn skills for contextual, episodic robot tasks: a context $c$ (a goal,
# a ball's serve, an obstacle's place) is drawn from the task's $p(c)$, the learner picks the
# parameters $\theta$ of a movement primitive once, a PD controller tracks the primitive's
# trajectory in MuJoCo {cite:p}`todorov2012mujoco`, and one return scores the whole episode.
# `vslbook.envs.robot` re-implements every task on MuJoCo 3 and gymnasium 1 from the thesis's
# descriptions (Sections 3.4 and 4.5.1, Appendices A.3 and B.4), loading the MIT model files
# of fancy-gym 0.3.0 from its installed wheel and building the rest of each scene in code.
# Every task has the same interface: `sample_contexts(n, rng)` draws from $p(c)$ with the
# task's rejection rules, `evaluate(theta, contexts)` runs a batch (an invalid $\theta$ is
# penalised without being simulated) and returns returns, success and per-episode
# information.
#
# Pictures are rendered offscreen; that needs an OpenGL backend without a screen, chosen
# before MuJoCo is first imported: Mesa's OSMesa (`MUJOCO_GL=osmesa`, installed by
# `make setup`) on a machine without a GPU, EGL on one with a GPU.

# %%
import os

if os.environ.get("MUJOCO_GL") not in ("egl", "osmesa"):
    os.environ["MUJOCO_GL"] = "osmesa"  # offscreen pictures (the tests run with rendering off)

import matplotlib.pyplot as plt
import numpy as np

from vslbook.budget import get_budget
from vslbook.envs.robot import TASKS, make_task
from vslbook.envs.robot.render import CAMERAS, render_scene
from vslbook.plots import use_style

use_style()
print(f"budget: {get_budget().name} (this page runs the same at every budget)")

# %% [markdown]
# ## The tasks at a glance
#
# Contexts, their ranges and the number of primitive parameters as this library implements
# them; where the thesis and the authors' code disagree (listed in each module's docstring),
# the library follows the thesis.

# %%
rows = []
for name in TASKS:
    task = make_task(name)
    rows.append((name, task.context_dim, task.n_params, task.has_success,
                 task.describe_contexts()))
    task.close()
width = max(len(r[0]) for r in rows)
print(f"{'task':{width}s}  dim c  params  success  contexts")
for name, dim, n_params, success, contexts in rows:
    print(f"{name:{width}s}  {dim:5d}  {n_params:6d}  {str(success):7s}  {contexts}")
assert all(r[2] > 0 for r in rows), "every task has primitive parameters"

# %% [markdown]
# ## The scenes
#
# Each MuJoCo task at the start of an episode in one context drawn from its $p(c)$ (seed 0):
# the robot at its initial configuration, and what the context places — the 5-link
# reacher's target, the table-tennis ball at its serve and the landing goal, the beer-pong
# cup, the hopper's jump goal, the box-pushing goal and obstacle. The planar 10-link reacher
# of Fig. 3.1 has no simulator; Chapter 3 draws it with its obstacles.

# %%
scenes = [n for n in TASKS if n in CAMERAS]
cols = 4
fig, axes = plt.subplots(-(-len(scenes) // cols), cols, figsize=(3.4 * cols, 2.9 * -(-len(scenes) // cols)))
pictures = {}
for ax, name in zip(axes.flat, scenes, strict=False):  # spare panels stay empty
    task = make_task(name)
    context = task.sample_contexts(1, np.random.default_rng(0))[0]
    pictures[name] = render_scene(task, context, width=400, height=300)
    task.close()
    ax.imshow(pictures[name])
    ax.set_title(f"{name}\nc = {np.array2string(context, precision=2)}", fontsize=8)
for ax in axes.flat:
    ax.axis("off")
fig.tight_layout()
plt.show()
# a picture that rendered nothing would be one flat colour
assert all(p.std() > 10 for p in pictures.values()), "a scene rendered as a flat image"

# %% [markdown]
# The context really moves the scene: the same task at two contexts differs exactly where
# the context places something. Below, the box-pushing obstacle and goal at two contexts,
# and the difference of the two pictures.

# %%
task = make_task("box-pushing-obstacle")
c1, c2 = task.sample_contexts(2, np.random.default_rng(1))
a, b = render_scene(task, c1), render_scene(task, c2)
task.close()
diff = np.abs(a.astype(int) - b.astype(int)).sum(-1)
fig, axes = plt.subplots(1, 3, figsize=(10, 2.8))
for ax, img, title in zip(axes, (a, b, diff), ("context 1", "context 2", "|difference|"), strict=True):
    ax.imshow(img, cmap="magma" if img.ndim == 2 else None)
    ax.set_title(title, fontsize=9)
    ax.axis("off")
fig.tight_layout()
plt.show()
changed = (diff > 30).mean()
print(f"{100 * changed:.1f} % of the pixels change between the two contexts")
assert 0.0005 < changed < 0.3, "the context should move a few objects, not the whole scene"
