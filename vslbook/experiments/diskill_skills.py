"""Figs. 4.5, 4.6, B.2 and B.4: diverse skills of one Di-SkilL policy for fixed contexts.

For a context c the gating π(o | c) (Algorithm 3) names the experts that would act there;
each of them executes its mean θ and the task's recorded path of a moving point (the box
of box pushing, the ball of table tennis) is drawn over a rendered picture of the scene
(:func:`vslbook.envs.robot.render.render_paths`), one colour per expert. A θ that the task
rejects before simulation (its trajectory leaves the joint limits) has no path and is
listed as rejected.
"""

from __future__ import annotations

from typing import Any

import matplotlib.pyplot as plt
import numpy as np

__all__ = ["draw_skills", "skills"]


def skills(model: Any, context: np.ndarray, *, min_gating: float = 0.05) -> list[dict[str, Any]]:
    """The experts with π(o | c) ≥ ``min_gating`` at ``context``: expert, gating, mean θ."""
    import torch

    from vslbook.erl.diskill_nets import log_gating
    from vslbook.experiments.diskill_reacher import log_preference

    c = np.asarray(context, dtype=np.float64).reshape(1, -1)
    k = model.config.n_experts
    if model.energies is None or k == 1:
        gate = np.ones(1)
    else:
        gate = log_gating(torch.as_tensor(log_preference(model, c))).exp()[:, 0].numpy()
    theta = model.mean_parameters(np.repeat(c, k, 0), np.arange(k))
    return [
        {"expert": int(o), "gating": float(gate[o]), "theta": theta[o]}
        for o in np.argsort(-gate) if gate[o] >= min_gating
    ]  # fmt: skip


def draw_skills(
    ax: plt.Axes, model: Any, context: np.ndarray, point: str, *, min_gating: float = 0.05,
    width: int = 480, height: int = 360,
) -> list[dict[str, Any]]:  # fmt: skip
    """Draw the scene at ``context`` and the path of ``point`` for every expert the gating
    picks with probability ≥ ``min_gating``; returns one row per expert (with ``executed``)."""
    from vslbook.envs.robot.render import draw_path, render_paths, render_scene

    task = model.task
    if point not in task.path_names:
        raise ValueError(f"{task.name} records {task.path_names}, not {point!r}")
    from vslbook.plots import expert_color

    rows, shown = [], False
    for s in skills(model, context, min_gating=min_gating):
        try:
            picture, paths = render_paths(task, s["theta"], context, width=width, height=height)
        except ValueError:  # rejected before simulation: no path
            rows.append(s | {"executed": False})
            continue
        if not shown:
            ax.imshow(picture)
            shown = True
        draw_path(ax, paths[point], color=expert_color(s["expert"]), lw=2,
                  label=f"expert {s['expert']} (π(o|c) {s['gating']:.2f})")  # fmt: skip
        rows.append(s | {"executed": True})
    if not shown:
        ax.imshow(render_scene(task, context, width=width, height=height))
        ax.text(0.5, 0.5, "every chosen expert's θ is rejected", transform=ax.transAxes,
                ha="center", color="w", fontsize=9)  # fmt: skip
    else:
        ax.legend(fontsize=8, loc="lower right")
    ax.set_axis_off()
    return rows
