"""Fig. 4.2: what a trained Di-SkilL model does on the 5-link reacher (5LR).

* (a) the high-probability regions of the per-expert context distributions π(c | o):
  each goal of a grid over the disk is coloured by the expert that prefers it most, with an
  intensity proportional to that expert's π(c | o) (:func:`draw_context_regions`);
* (b) how many experts are *active* at each goal (:func:`active_experts`): expert o is
  active at c when π(c | o) > p(c), i.e. it draws c more often than the environment would
  (the thesis does not define "active"; this is our reading of Fig. 4.2b);
* (c) diverse solutions for the same goal: the tip trajectories of the experts' mean θ
  (:func:`reaches`, :func:`draw_reaches`).

And, behind Fig. 4.3c, where on the disk a model (Di-SkilL or BBRL) loses return:
:func:`goal_returns` runs Algorithm 3 (o ~ π(o | c), the expert's mean θ) at given goals,
:func:`ring` places goals on a circle by their angle from the start posture (the arm lies
along +x, so ±180° is straight behind it, where the arm can turn either way), and
:func:`draw_goal_returns` plots the return against that angle, one line per model.

π(c | o) is evaluated with the model's own normaliser, a fixed batch of contexts from p(c)
(:meth:`vslbook.erl.diskill.DiSkill.choose_experts`): with N contexts c_j ~ p(c),
π(c | o) / p(c) ≈ exp φ_o(c) / mean_j exp φ_o(c_j).
"""

from __future__ import annotations

from typing import Any

import matplotlib.pyplot as plt
import numpy as np
import pandas as pd
import torch

__all__ = [
    "active_experts", "disk_grid", "draw_active_experts", "draw_context_regions",
    "draw_goal_returns", "draw_reaches", "goal_returns", "goal_returns_table",
    "log_preference", "reaches", "ring", "ring_summary", "summary_at_test_goals",
]  # fmt: skip

RADIUS = 0.5  # 5LR's goals: the disk of radius 0.5 around the first joint (B.4.3)


def disk_grid(n: int = 41, radius: float = RADIUS) -> np.ndarray:
    """The points of an n × n grid on [−r, r]² that lie in the disk of radius r: (M, 2)."""
    if not isinstance(n, int) or n < 2:
        raise ValueError(f"n must be an integer >= 2, got {n!r}")
    g = np.linspace(-radius, radius, n)
    xy = np.stack(np.meshgrid(g, g), -1).reshape(-1, 2)
    return xy[np.hypot(xy[:, 0], xy[:, 1]) <= radius]


def log_preference(model: Any, contexts: np.ndarray) -> np.ndarray:
    """log π(c | o) − log p(c) for every expert and context: (K, M).

    Estimated with the model's normaliser batch c_j ~ p(c):
    φ_o(c) − log mean_j exp φ_o(c_j) (Eq. 4.6 with Z from samples of p(c)).
    """
    if model.energies is None:
        raise ValueError("the model has no context distributions (BBRL): nothing to show")
    dtype = model.energies.dtype  # the networks' (config.dtype)
    c = torch.as_tensor(np.asarray(contexts, dtype=np.float64), dtype=dtype)
    norm = torch.as_tensor(model.normaliser_contexts, dtype=dtype)
    with torch.no_grad():
        e_norm = model.energies.energies(norm)
        log_mean_z = torch.logsumexp(e_norm, -1) - np.log(e_norm.shape[-1])
        return (model.energies.energies(c) - log_mean_z[:, None]).double().numpy()


def active_experts(model: Any, contexts: np.ndarray, threshold: float = 0.0) -> np.ndarray:
    """How many experts have log π(c | o) − log p(c) > ``threshold`` at each context: (M,)."""
    return (log_preference(model, contexts) > threshold).sum(0)


def _colors(k: int) -> np.ndarray:
    """RGBA rows of the first ``k`` experts' colours (:func:`vslbook.plots.expert_color`)."""
    from matplotlib.colors import to_rgba

    from vslbook.plots import expert_color

    return np.array([to_rgba(expert_color(i)) for i in range(k)])


def _disk(ax: plt.Axes) -> None:
    ax.add_patch(plt.Circle((0, 0), RADIUS, fill=False, color="tab:red", lw=1.5))
    ax.plot(0, 0, "k+", ms=8)
    ax.set_aspect("equal")
    ax.set_xlim(-0.55, 0.55)
    ax.set_ylim(-0.55, 0.55)
    ax.set_xlabel("goal x [m]")
    ax.set_ylabel("goal y [m]")


def draw_context_regions(ax: plt.Axes, model: Any, grid: np.ndarray | None = None) -> plt.Axes:
    """Fig. 4.2a: each goal in the colour of the expert with the largest π(c | o), the
    intensity proportional to that probability (relative to the expert's own peak)."""
    grid = disk_grid() if grid is None else grid
    pref = log_preference(model, grid)  # (K, M)
    best = pref.argmax(0)
    # intensity: the expert's π(c | o) relative to its own largest value on the grid
    rel = np.exp(pref.max(0) - pref.max(1)[best])
    colors = _colors(pref.shape[0])[best]
    colors[:, 3] = np.clip(rel, 0.1, 1.0)
    ax.scatter(grid[:, 0], grid[:, 1], c=colors, s=18, marker="s", linewidths=0)
    _disk(ax)
    ax.set_title("(a) most probable expert per goal")
    return ax


def draw_active_experts(ax: plt.Axes, model: Any, grid: np.ndarray | None = None) -> plt.Axes:
    """Fig. 4.2b: the number of experts with π(c | o) > p(c) at each goal, one colour per
    count (a discrete scale with a tick at each whole number)."""
    from matplotlib.colors import BoundaryNorm

    grid = disk_grid() if grid is None else grid
    n = active_experts(model, grid)
    top = max(int(n.max()), 1)
    cmap = plt.get_cmap("viridis", top + 1)  # one colour per count 0, 1, …, top
    norm = BoundaryNorm(np.arange(-0.5, top + 1), cmap.N)
    sc = ax.scatter(grid[:, 0], grid[:, 1], c=n, s=18, marker="s", cmap=cmap, norm=norm,
                    linewidths=0)  # fmt: skip
    bar = plt.colorbar(sc, ax=ax, label="active experts", shrink=0.8)
    bar.set_ticks(np.arange(0, top + 1, max(1, (top + 10) // 11)))
    _disk(ax)
    ax.set_title("(b) experts with π(c|o) > p(c)")
    return ax


def reaches(model: Any, goal: np.ndarray) -> list[dict[str, Any]]:
    """Fig. 4.2c: every expert's mean θ at ``goal``: its tip path (T, 3), final distance and
    gating probability π(o | c)."""
    goal = np.asarray(goal, dtype=np.float64).reshape(1, -1)
    k = model.config.n_experts
    theta = model.mean_parameters(np.repeat(goal, k, 0), np.arange(k))
    if model.energies is not None and k > 1:
        from vslbook.erl.diskill_nets import log_gating

        pref = torch.as_tensor(log_preference(model, goal))
        gate = log_gating(pref).exp()[:, 0].numpy()
    else:
        gate = np.ones(k)
    out = []
    for o in range(k):
        tip = model.task.path(theta[o], goal[0])["fingertip"]
        distance = float(np.linalg.norm(tip[-1, :2] - goal[0]))
        out.append({"expert": o, "tip": tip, "distance": distance, "gating": float(gate[o])})
    return out


def draw_reaches(
    ax: plt.Axes, model: Any, goals: np.ndarray, *, min_gating: float = 0.05
) -> plt.Axes:
    """Fig. 4.2c: tip trajectories of the experts that the gating picks with probability at
    least ``min_gating`` at each goal, in the experts' colours."""
    colors = _colors(model.config.n_experts)
    for goal in np.atleast_2d(goals):
        for r in reaches(model, goal):
            if r["gating"] < min_gating:
                continue
            ax.plot(r["tip"][:, 0], r["tip"][:, 1], color=colors[r["expert"]], lw=1.2, alpha=0.9)
            ax.plot(*r["tip"][-1, :2], "o", color=colors[r["expert"]], ms=3)
        ax.plot(*goal, "*", color="tab:red", ms=10, mec="k", mew=0.5)
    _disk(ax)
    ax.set_title(f"(c) tip paths of experts with π(o|c) ≥ {min_gating:g}")
    return ax


# --------------------------------------------------------------------------- Fig. 4.3c


#: Goals at least this many degrees from the start posture (+x) lie "behind the arm": the
#: arm must turn through half a circle, and one Gaussian's mean θ can fall between the two
#: ways round (Fig. 4.3c's ring; shaded by :func:`draw_goal_returns`).
BEHIND_ARM_DEG = 150.0


def ring(radius: float = 0.4, step: float = 5.0) -> np.ndarray:
    """Goals on the circle of ``radius`` around the first joint, every ``step`` degrees from
    −180° (behind the arm) on: (M, 2)."""
    if not 0 < radius <= RADIUS:
        raise ValueError(f"radius must be in (0, {RADIUS}] (the goal disk), got {radius!r}")
    if not 0 < step <= 180:
        raise ValueError(f"step must be in (0, 180] degrees, got {step!r}")
    angle = np.radians(np.arange(-180.0, 180.0, step))
    return radius * np.stack([np.cos(angle), np.sin(angle)], 1)


def goal_returns(model: Any, goals: np.ndarray, seed: int = 0) -> pd.DataFrame:
    """Algorithm 3 at each goal, as the test evaluation runs it: o ~ π(o | c) (from
    ``seed``), the expert's mean θ, one episode. Columns: ``angle`` (degrees from +x, the
    start posture), ``radius``, ``expert``, ``return`` and ``tip_distance`` (m)."""
    goals = np.asarray(goals, dtype=np.float64)
    if goals.ndim != 2 or goals.shape[1] != 2 or not len(goals):
        raise ValueError(f"goals must be an (M, 2) array with M >= 1, got shape {goals.shape}")
    o = model.choose_experts(goals, torch.Generator().manual_seed(int(seed)))
    out = model.task.evaluate(model.mean_parameters(goals, o), goals, workers=0)
    return pd.DataFrame({
        "angle": np.degrees(np.arctan2(goals[:, 1], goals[:, 0])),
        "radius": np.hypot(goals[:, 0], goals[:, 1]),
        "expert": o,
        "return": out.returns,
        "tip_distance": out.info["tip_distance"],
    })  # fmt: skip


#: A goal whose return is below this is one the model fails (a reached goal costs about −1
#: on the 5-link reacher; one the tip misses costs tens to hundreds).
POOR_RETURN = -5.0
_POOR = f"{POOR_RETURN:g}".replace("-", "−")  # as printed


def ring_summary(frame: pd.DataFrame) -> str:
    """One line on :func:`goal_returns` at a :func:`ring`: the median return over the ring,
    the median and the worst behind the arm (|angle| ≥ :data:`BEHIND_ARM_DEG`), and how many
    goals are below :data:`POOR_RETURN`."""
    behind = frame[frame["angle"].abs() >= BEHIND_ARM_DEG]
    if behind.empty:
        raise ValueError(f"no goal behind the arm (|angle| >= {BEHIND_ARM_DEG:g}°) in the ring")
    worst = behind["return"].idxmin()
    poor = int((frame["return"] < POOR_RETURN).sum())
    return (f"median return {frame['return'].median():.2f} over the ring; behind the arm "
            f"(|angle| ≥ {BEHIND_ARM_DEG:g}°) median {behind['return'].median():.2f}, worst "
            f"{behind['return'][worst]:.1f} at {behind['angle'][worst]:.0f}°; goals below "
            f"{_POOR}: {poor} of {len(frame)}")  # fmt: skip


def summary_at_test_goals(frame: pd.DataFrame) -> str:
    """One line on :func:`goal_returns` at a run's test goals: the mean return (for a single
    policy, the test return the run logged last), the goals below :data:`POOR_RETURN` with
    their return, angle and distance, and the mean without them."""
    poor = frame["return"] < POOR_RETURN
    goals = ", ".join(f"{r['return']:.0f} at {r['angle']:.0f}° ({r['radius']:.2f} m)"
                      for _, r in frame[poor].sort_values("return").iterrows())  # fmt: skip
    return (f"mean return {frame['return'].mean():.2f} over its {len(frame)} test goals; "
            f"{int(poor.sum())} below {_POOR}" + (f": {goals}" if goals else "")
            + f"; without them {frame.loc[~poor, 'return'].mean():.2f}")  # fmt: skip


#: What :func:`goal_returns_table` evaluates each model at: the ring of Fig. 4.3c's panel and
#: the run's own 75 fixed test goals.
GOAL_SETS = ("ring 0.4 m, every 5°", "test contexts")


def goal_returns_table(runs: dict[str, list[Any]], seeds: tuple[int, ...] | None = None
                       ) -> pd.DataFrame:  # fmt: skip
    """:func:`goal_returns` of each run's final checkpoint at both :data:`GOAL_SETS`, long:
    columns ``method``, ``seed``, ``run`` (the run directory's name), ``goals`` and those of
    :func:`goal_returns`. ``runs``: method → run directories in seed order (a figure set's
    ``runs``); ``seeds`` keeps only those seeds.

    ``data/measurements/reacher5_goal_returns.csv`` holds this table for the checkpoints the
    record does not keep (it keeps seed 0's), with how it was made.
    """
    from pathlib import Path

    from vslbook.experiments.diskill_runs import load_model
    from vslbook.results import RunDir

    frames = []
    for method, paths in runs.items():
        for path in paths:
            seed = int(RunDir.open(path).config["seed"])
            if seeds is not None and seed not in seeds:
                continue
            model = load_model(path)
            for goals, contexts in zip(GOAL_SETS, (ring(0.4, 5.0), model.test_contexts),
                                       strict=True):  # fmt: skip
                frame = goal_returns(model, contexts)
                frame.insert(0, "goals", goals)
                frame.insert(0, "run", Path(path).name)
                frame.insert(0, "seed", seed)
                frame.insert(0, "method", method)
                frames.append(frame)
    if not frames:
        raise ValueError(f"no run of seeds {seeds} in runs {sorted(runs)}")
    return pd.concat(frames, ignore_index=True)


def draw_goal_returns(ax: plt.Axes, returns: dict[str, pd.DataFrame]) -> plt.Axes:
    """The return against the goal's angle, one line per model (label → :func:`goal_returns`
    on a :func:`ring`; a label that names a method takes its style), on a symmetric-log
    axis: the goals behind the arm can cost a hundred times more than the rest."""
    from vslbook.plot_style import is_method, method_style

    for label, frame in returns.items():
        f = frame.sort_values("angle")
        style = method_style(label) | {"marker": "o"} if is_method(label) else {"marker": "o"}
        ax.plot(f["angle"], f["return"], ms=3, lw=1.2, label=label, **style)
    ax.set_yscale("symlog", linthresh=1.0)
    ax.set_xticks(np.arange(-180, 181, 45))
    edge = BEHIND_ARM_DEG
    ax.axvspan(-180, -edge, color="0.9", zorder=0)
    ax.axvspan(edge, 180, color="0.9", zorder=0, label=f"behind the arm (±{edge:g}–180°)")
    ax.set_xlabel("goal angle from the start posture (degrees)")
    ax.set_ylabel("return (mean θ, symlog)")
    ax.legend(fontsize=8)
    return ax
