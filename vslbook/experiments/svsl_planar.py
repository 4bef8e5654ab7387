"""Fig. 3.1: SVSL with and without the responsibilities, and HiREPS, on the planar reacher.

The thesis (Section 3.4.1) trains the 10-link planar reacher with 60 experts (K = 350,
H = 50) for (i) SVSL as derived, (ii) SVSL with log π̃(o | c, θ) and log π̃(o | c) set to
zero, and HiREPS, over 15 seeds, and shows for six contexts the means of the experts that
100 draws from π(o | c) pick (Fig. 3.1a, d, e) and the per-expert context distributions
(Fig. 3.1c, f). Its reported outcome: with the responsibilities the solutions are versatile
(several experts per context), precise and valid, and the context distributions cover the
whole context space; without them the solutions are imprecise, partly go through the
obstacles and the context distributions crowd into easy regions; HiREPS chose only 3 of its
60 experts.

:func:`planar_counts` gives the counts per budget (a budget scales the number of experts,
iterations and seeds; α, β, the KL bounds and K stay the thesis's) and :func:`variant_config`
each variant's configuration, the presets of ``vslbook run svsl|hireps --env
vslbook/PlanarReacher-v0`` (:mod:`vslbook.experiments.ch3_algorithms`). The runs are
declared in :mod:`vslbook.experiments.ch3_runs` (``fig3-1``; the variant without
responsibilities is ``--set responsibilities=false``) and trained by
:func:`vslbook.training.run`: ``run_set("fig3-1", budget, root)`` gives variant → run
directories. :func:`load_model` reads a trained model back, :func:`planar_scores` measures
precision, validity and versatility of it, and the ``draw_*`` functions make the panels.
"""

from __future__ import annotations

from typing import Any

import matplotlib.pyplot as plt
import numpy as np
from matplotlib.figure import Figure
from matplotlib.patches import Ellipse, Rectangle

from vslbook.budget import Budget, get_budget
from vslbook.envs.robot import make_task
from vslbook.envs.robot.planar_reacher import OBSTACLES, link_points
from vslbook.erl import hireps
from vslbook.erl.svsl import SVSL, svsl_config
from vslbook.experiments.svsl_mixtures import load_model
from vslbook.plots import count_phrase, expert_color

__all__ = [
    "FIG_CONTEXTS",
    "SCORE_LABELS",
    "VARIANTS",
    "distinct_solutions",
    "draw_context_coverage",
    "draw_fig_3_1",
    "draw_solutions",
    "load_model",
    "planar_counts",
    "planar_scores",
    "score_label",
    "variant_config",
    "ways_around_obstacles",
]

#: The six target contexts drawn in Fig. 3.1 (its red dots). The thesis does not list their
#: coordinates; these are the ones the authors' planar-reacher run script draws: x ∈ {5.5, 6.5}
#: and y ∈ {−2, 0, 2}, the middle of the context box [4.5, 7] × [−6, 6].
FIG_CONTEXTS = np.array([[5.5, 0.0], [6.5, 0.0], [5.5, -2.0], [6.5, -2.0], [5.5, 2.0], [6.5, 2.0]])

#: The three methods of Fig. 3.1, in the order of its panels.
VARIANTS = ("SVSL", "SVSL, no responsibilities", "HiREPS")


def planar_counts(budget: Budget | str | None = None) -> dict[str, int]:
    """Experts, iterations and seeds of Fig. 3.1 at a budget (full: the thesis's).

    ``reduced`` keeps K = 350 with 30 of the thesis's 60 experts. With 12 experts the
    coverage of the context box came out level with and without the responsibilities
    (0.69 against 0.70 over 3 seeds): 12 context Gaussians leave much of the box
    uncovered either way. With 30 it is 0.83 / 0.885 / 0.885 against 0.735 / 0.68 / 0.78
    (seeds 0-2 of each variant), as Fig. 3.1c/f has it. A 30-expert run takes about 2 minutes on one
    core (a 60-expert run about 5.5).
    """
    b = get_budget(budget)
    return {
        "n_experts": b.pick(smoke=2, reduced=30, full=60),
        "iterations_per_expert": b.pick(smoke=50, reduced=350, full=350),
        "weight_iterations": b.pick(smoke=10, reduced=100, full=100),
        "hireps_iterations": b.pick(smoke=20, reduced=600, full=2900),
        "seeds": b.pick(smoke=1, reduced=b.seeds, full=15),
    }


def variant_config(variant: str, budget: Budget | str | None = None) -> Any:
    """The configuration of one Fig. 3.1 variant at a budget."""
    n = planar_counts(budget)
    if variant in VARIANTS[:2]:
        return svsl_config(
            "planar-reacher",
            n_experts=n["n_experts"],
            iterations_per_expert=n["iterations_per_expert"],
            weight_iterations=n["weight_iterations"],
            responsibilities=variant == VARIANTS[0],
        )
    if variant == VARIANTS[2]:
        return hireps.HiREPSConfig.for_task(
            "planar-reacher", n_experts=n["n_experts"], iterations=n["hireps_iterations"]
        )
    raise ValueError(f"unknown variant {variant!r}; expected one of {VARIANTS}")


def _sample_means(model: Any, contexts: np.ndarray, n: int, rng) -> tuple[np.ndarray, np.ndarray]:
    """Per context, ``n`` draws o ~ π(o | c) and the chosen experts' means: (m, n, 10), (m, n)."""
    rep = np.repeat(contexts, n, axis=0)
    if isinstance(model, SVSL):
        th, o = model.model.sample(rep, rng, mean=True)
    else:  # HiREPS: its own gating draw, then the chosen expert's mean K_o c + k_o
        _, o = model.sample(rep, rng)
        th = np.einsum("njc,nc->nj", model.mix.K[o], rep) + model.mix.k[o]
    return th.reshape(len(contexts), n, -1), np.asarray(o).reshape(len(contexts), n)


#: A solution "solves" a target if its tip is this close (the thesis defines no success for
#: this task; Fig. 3.1 calls solutions precise and valid) and no link touches an obstacle.
SOLVED_TIP_DISTANCE = 0.3

#: Two chosen solutions count as different modes if their joint angles differ by more
#: than this (Euclidean norm over the 10 wrapped angles, radians).
MODE_DISTANCE = 1.0


def distinct_solutions(thetas: np.ndarray, threshold: float = MODE_DISTANCE) -> int:
    """Number of modes among solutions (n, 10): greedy grouping of angles within ``threshold``."""
    wrapped = (np.asarray(thetas, dtype=np.float64) + np.pi) % (2 * np.pi) - np.pi
    centres: list[np.ndarray] = []
    for t in wrapped:
        if all(np.linalg.norm(t - c) > threshold for c in centres):
            centres.append(t)
    return len(centres)


_OBSTACLE_CENTRES = np.stack([OBSTACLES[:, :2].mean(1), OBSTACLES[:, 2:].mean(1)], axis=1)


def ways_around_obstacles(thetas: np.ndarray) -> int:
    """Number of different ways around the obstacles among solutions (n, 10) to one target.

    A threshold-free reading of "modes" for this task: two collision-free arms that reach
    the same target are the same way around the obstacles if one can be bent into the other
    without crossing an obstacle (the same homotopy class of the plane without the three
    rectangles). For each obstacle the angle the arm sweeps around the obstacle's centre,
    from the base to the tip, tells the classes apart: arms of one class sweep nearly the
    same angle (the tips differ a little), arms passing an obstacle on different sides
    differ by about 2π. Two arms count as one way if every obstacle's angle differs by less
    than π (greedy grouping, as :func:`distinct_solutions`). Meant for solving draws: an arm
    that crosses an obstacle has no class.
    """
    pts = link_points(np.atleast_2d(np.asarray(thetas, dtype=np.float64)))  # (n, 11, 2)
    rel = pts[:, :, None, :] - _OBSTACLE_CENTRES  # (n, 11, 3, 2)
    heading = np.arctan2(rel[..., 1], rel[..., 0])
    step = (np.diff(heading, axis=1) + np.pi) % (2 * np.pi) - np.pi  # each link: < π
    swept = step.sum(axis=1)  # (n, 3)
    classes: list[np.ndarray] = []
    for a in swept:
        if all(np.any(np.abs(a - c) >= np.pi) for c in classes):
            classes.append(a)
    return len(classes)


def _context_gaussians(model: Any) -> tuple[np.ndarray, np.ndarray]:
    if isinstance(model, SVSL):
        return model.model.ctx_mean, model.model.ctx_cov
    return model.mix.ctx_mean, model.mix.ctx_cov  # HiREPS's Bayes gating


def planar_scores(
    model: Any,
    *,
    n_contexts: int = 200,
    n_draws: int = 20,
    seed: int = 0,
    contexts: np.ndarray | None = None,
) -> dict[str, float]:
    """Precision, validity, versatility and coverage of a trained model on targets.

    For each of ``n_contexts`` contexts drawn from p(c) (or each row of ``contexts``, e.g.
    :data:`FIG_CONTEXTS` with ``n_draws=100``, the thesis's reading of Fig. 3.1), ``n_draws``
    experts are drawn from π(o | c) and their means executed:

    * ``tip_distance``: mean ‖f(θ) − c‖ (precision); ``collision_rate`` (validity);
      ``mean_return``;
    * ``solved_rate``: share of draws with tip distance ≤ :data:`SOLVED_TIP_DISTANCE` and no
      collision;
    * ``modes_per_context``: distinct solutions (:func:`distinct_solutions`) among the draws
      that solve the target (0 if none does), versatility counted as the thesis does for beer
      pong (A.3.2.1: only successful solutions); ``experts_per_context``: distinct experts
      among all draws (experts that share one solution count once in the first and
      separately in the second);
    * ``ways_per_context``: the different ways around the obstacles
      (:func:`ways_around_obstacles`) among the same solving draws, a count of modes that
      needs no distance threshold;
    * ``coverage``: the share of the contexts that lie within two standard deviations
      (Mahalanobis) of at least one expert's context distribution.
    """
    task = make_task("planar-reacher")
    rng = np.random.default_rng(seed)
    if contexts is None:
        contexts = task.sample_contexts(n_contexts, rng)
    contexts = np.asarray(contexts, dtype=np.float64)
    if contexts.ndim != 2 or contexts.shape[1] != 2 or len(contexts) == 0:
        raise ValueError(f"contexts must be targets of shape (m, 2), got {contexts.shape}")
    th, o = _sample_means(model, contexts, n_draws, rng)
    out = task.evaluate(th.reshape(-1, th.shape[-1]), np.repeat(contexts, n_draws, axis=0))
    solved = (out.info["tip_distance"] <= SOLVED_TIP_DISTANCE) & (out.info["collision"] == 0)
    solved = solved.reshape(len(contexts), n_draws)
    modes = [distinct_solutions(t[k]) if k.any() else 0 for t, k in zip(th, solved, strict=True)]
    ways = [ways_around_obstacles(t[k]) if k.any() else 0 for t, k in zip(th, solved, strict=True)]
    means, covs = _context_gaussians(model)
    diff = contexts[:, None, :] - means[None]
    maha = np.einsum("nei,eij,nej->ne", diff, np.linalg.inv(covs), diff)
    return {
        "tip_distance": float(np.mean(out.info["tip_distance"])),
        "collision_rate": float(np.mean(out.info["collision"])),
        "mean_return": float(np.mean(out.returns)),
        "solved_rate": float(np.mean(solved)),
        "modes_per_context": float(np.mean(modes)),
        "ways_per_context": float(np.mean(ways)),
        "experts_per_context": float(np.mean([len(np.unique(row)) for row in o])),
        "coverage": float(np.mean(np.min(maha, axis=1) <= 4.0)),
    }


def draw_solutions(ax: plt.Axes, model: Any, *, n_draws: int = 100, seed: int = 0) -> plt.Axes:
    """Fig. 3.1a/d/e: the arms of the experts chosen for the six contexts, one colour each."""
    rng = np.random.default_rng(seed)
    th, o = _sample_means(model, FIG_CONTEXTS, n_draws, rng)
    for j in range(len(FIG_CONTEXTS)):
        for expert in np.unique(o[j]):
            pts = link_points(th[j][o[j] == expert][0])
            ax.plot(pts[:, 0], pts[:, 1], "-", color=expert_color(expert), lw=1.2, alpha=0.8)
            ax.plot(*pts[-1], "o", color="green", ms=3)
    _draw_scene(ax)
    return ax


def _draw_scene(ax: plt.Axes) -> None:
    for x0, x1, y0, y1 in OBSTACLES:
        ax.add_patch(Rectangle((x0, y0), x1 - x0, y1 - y0, color="tab:red", alpha=0.6))
    ax.plot(FIG_CONTEXTS[:, 0], FIG_CONTEXTS[:, 1], "o", color="red", ms=5)
    ax.add_patch(Rectangle((4.5, -6), 2.5, 12, fill=False, ls="--", color="grey"))
    ax.set_aspect("equal")
    ax.set_xlim(-1, 10)
    ax.set_ylim(-7, 7)


def draw_context_coverage(ax: plt.Axes, model: Any) -> plt.Axes:
    """Fig. 3.1c/f: each expert's context Gaussian (2σ ellipse) in the context box."""
    means, covs = _context_gaussians(model)
    log_w = model.model.log_w if isinstance(model, SVSL) else model.mix.log_prior
    weights = np.exp(log_w)
    for i, (m, c) in enumerate(zip(means, covs, strict=True)):
        vals, vecs = np.linalg.eigh(c)
        angle = np.degrees(np.arctan2(vecs[1, -1], vecs[0, -1]))
        w, h = 4 * np.sqrt(np.maximum(vals[::-1], 1e-12))
        alpha = 0.15 + 0.6 * float(weights[i] / weights.max())
        ax.add_patch(Ellipse(m, w, h, angle=angle, color=expert_color(i), alpha=alpha))
    ax.add_patch(Rectangle((4.5, -6), 2.5, 12, fill=False, ls="--", color="grey"))
    ax.plot(FIG_CONTEXTS[:, 0], FIG_CONTEXTS[:, 1], "o", color="red", ms=4)
    ax.set_xlim(2.25, 9.25)  # the box [4.5, 7] x [-6, 6] and what spills out of it
    ax.set_ylim(-8, 8)
    ax.set_aspect("equal")
    return ax


#: What each score of :func:`planar_scores` measures, in words (the axis labels of the
#: figure of the scores).
SCORE_LABELS = {
    "tip_distance": "mean distance of the tip to the target",
    "collision_rate": "share of draws that collide",
    "mean_return": "mean return",
    "solved_rate": "share of draws that solve their target",
    "modes_per_context": "distinct solutions per target",
    "ways_per_context": "ways around the obstacles per target",
    "experts_per_context": "experts drawn per target",
    "coverage": "share of targets inside an expert's context distribution",
}


def score_label(key: str, seeds: int) -> str:
    """The axis label of score ``key`` (:data:`SCORE_LABELS`) aggregated over ``seeds``."""
    if key not in SCORE_LABELS:
        raise ValueError(f"unknown score {key!r}; expected one of {sorted(SCORE_LABELS)}")
    return f"{SCORE_LABELS[key]}\n(IQM over {count_phrase(seeds, 'seed')})"


def draw_fig_3_1(models: dict[str, Any], title: str = "") -> Figure:
    """Fig. 3.1 for one model per variant of :data:`VARIANTS` (a row each): the mean
    solutions of the experts chosen at the six targets (a, d, e; :func:`draw_solutions`)
    and the per-expert context distributions (c, f; :func:`draw_context_coverage`)."""
    missing = [v for v in VARIANTS if v not in models]
    if missing:
        raise ValueError(f"no model of variant(s) {missing}; expected {{variant: model}}")
    fig, axes = plt.subplots(len(VARIANTS), 2, figsize=(9.0, 5.6 * len(VARIANTS)),
                             gridspec_kw={"width_ratios": (1.8, 1.0)},
                             layout="constrained")  # fmt: skip
    for row, variant in zip(axes, VARIANTS, strict=True):
        draw_solutions(row[0], models[variant])
        row[0].set_title(f"{variant}: mean solutions at the six targets", fontsize=10)
        draw_context_coverage(row[1], models[variant])
        row[1].set_title("context distributions", fontsize=10)
    for ax in axes.ravel():
        ax.set(xlabel="x", ylabel="y")
    if title:
        fig.suptitle(title, fontsize=10)
    return fig
