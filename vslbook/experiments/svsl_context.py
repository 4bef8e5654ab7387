"""The context space of a Chapter 3 mixture: grids, coverage, expected entropies, drawings.

The analysis half of Fig. 3.2 and Figs. A.1 / A.2 (thesis Section 3.4.2, Appendix A.3.2,
A.3.3), for SVSL, HiREPS and LaDiPS alike (:func:`mixture_of` turns each into the mixture of
Eq. 3.1), and what both halves share: the methods, one task object per name and process,
the methods' configurations at given counts. Runs and learning curves are in
:mod:`vslbook.experiments.svsl_mixtures`, which re-exports everything public here.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import matplotlib.pyplot as plt
import numpy as np
from matplotlib.patches import Ellipse, Rectangle

from vslbook.envs.robot import make_task
from vslbook.erl import hireps, ladips
from vslbook.erl.mixture_baseline import MixtureAlgorithm
from vslbook.erl.svsl import SVSL, SVSLConfig, svsl_config
from vslbook.erl.svsl_model import MixtureModel

__all__ = [
    "METHODS",
    "box_grid",
    "check_count",
    "check_method",
    "check_shape",
    "draw_box",
    "draw_context_gaussians",
    "draw_success_grid",
    "entropy_contexts",
    "entropy_due",
    "expected_entropy",
    "method_config",
    "mixture_of",
    "shared_task",
    "success_grid",
    "svsl_entropy",
    "svsl_episodes",
]

#: The three methods of Fig. 3.2a/b, in the thesis's order.
METHODS = ("SVSL", "HiREPS", "LaDiPS")

#: Rows (contexts × draws) of one Monte-Carlo entropy batch; larger sets are split.
_ENTROPY_CHUNK = 200_000

# --------------------------------------------------------------------------------------
# tasks, counts and configurations
# --------------------------------------------------------------------------------------
_TASKS: dict[str, Any] = {}


def shared_task(name: str) -> Any:
    """One task object per name and process, shared by the runs and evaluations.

    Episodes are deterministic given (θ, c), so sharing changes no number; it starts the
    task's worker pool (``VSLBOOK_WORKERS``) once instead of once per run.
    """
    if name not in _TASKS:
        _TASKS[name] = make_task(name)
    return _TASKS[name]


def check_method(method: Any) -> str:
    """``method`` if it is one of :data:`METHODS`, else a ValueError."""
    if method not in METHODS:
        raise ValueError(f"unknown method {method!r}; expected one of {METHODS}")
    return str(method)


def svsl_episodes(config: SVSLConfig) -> int:
    """Episodes SVSL evaluates in a whole run (rejected θ included; tests excluded).

    Each new expert fills its buffer (``buffer_size``); every iteration updates the newest
    expert, every H-th iteration all k experts present, each update drawing
    ``new_samples_expert + new_samples_context`` episodes; the weight phase refreshes every
    buffer once: N·n + N·K·m + ⌊K/H⌋·m·N(N − 1)/2 + N·n (n the buffer, m the samples per
    update).
    """
    n, k, h = config.n_experts, config.iterations_per_expert, config.fine_tune_every
    per_update = config.new_samples_expert + config.new_samples_context
    fills = n * config.buffer_size
    newest = n * k * per_update
    fine_tune = (k // h) * per_update * (n * (n - 1) // 2)
    weight_phase = n * config.buffer_size if config.weight_iterations > 0 else 0
    return fills + newest + fine_tune + weight_phase


def method_config(task: str, method: str, counts: dict[str, Any]) -> Any:
    """SVSLConfig, HiREPSConfig or LaDiPSConfig of one method on ``task`` with ``counts``.

    SVSL takes :func:`vslbook.erl.svsl.svsl_config` (Table A.1) with the counts; the
    baselines take their task preset (Tables A.2, A.3) with N, the samples per iteration
    and the iterations of the counts.
    """
    svsl = svsl_config(
        task,
        n_experts=counts["n_experts"],
        iterations_per_expert=counts["iterations_per_expert"],
        fine_tune_every=counts["fine_tune_every"],
        weight_iterations=counts["weight_iterations"],
        test_every=counts["test_every"],
        test_contexts=counts["test_contexts"],
    )
    if method == "SVSL":
        return svsl
    check_method(method)
    samples = counts["baseline_samples"]
    iterations = counts["baseline_iterations"] or math.ceil(svsl_episodes(svsl) / samples)
    kw = {"n_experts": counts["baseline_experts"], "samples_per_iteration": samples,
          "iterations": iterations}  # fmt: skip
    if method == "HiREPS":
        return hireps.HiREPSConfig.for_task(task, **kw)
    return ladips.LaDiPSConfig.for_task(task, **kw)


# --------------------------------------------------------------------------------------
# contexts: grids and the entropy set
# --------------------------------------------------------------------------------------
def check_shape(shape: Any) -> tuple[int, int]:
    """``(n_x, n_y)`` as two positive ints, else a ValueError."""
    ok = (
        isinstance(shape, (tuple, list))
        and len(shape) == 2
        and all(isinstance(v, (int, np.integer)) and not isinstance(v, bool) and v >= 1
                for v in shape)
    )  # fmt: skip
    if not ok:
        raise ValueError(f"grid shape must be two positive integers (n_x, n_y), got {shape!r}")
    return int(shape[0]), int(shape[1])


def check_count(name: str, value: Any) -> int:
    """``value`` as a positive int, else a ValueError naming ``name``."""
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 1:
        raise ValueError(f"{name} must be a positive integer, got {value!r}")
    return int(value)


def _check_dims(task: Any, dims: Any) -> tuple[int, int]:
    dc = task.context_dim
    ok = (
        isinstance(dims, (tuple, list))
        and len(dims) == 2
        and all(isinstance(d, (int, np.integer)) and not isinstance(d, bool) and 0 <= d < dc
                for d in dims)
        and dims[0] != dims[1]
    )  # fmt: skip
    if not ok:
        raise ValueError(
            f"dims must be two different context indices in [0, {dc}) for {task.name}, got {dims!r}"
        )
    return int(dims[0]), int(dims[1])


def box_grid(
    task: str,
    shape: tuple[int, int],
    dims: Sequence[int] = (0, 1),
    fixed: Sequence[float] | None = None,
    *,
    low: Sequence[float] | None = None,
    high: Sequence[float] | None = None,
) -> np.ndarray:
    """Centres of an (n_x, n_y) grid of cells over context dims ``dims``, (n_y, n_x, dc).

    The cells split the box [low, high] (default the task's context box) along
    ``dims[0]`` (x) and ``dims[1]`` (y); the other context entries are taken from the full
    context ``fixed`` (needed when the task has more than two context dimensions).
    """
    nx, ny = check_shape(shape)
    t = shared_task(task)
    d0, d1 = _check_dims(t, dims)
    dc = t.context_dim
    lo = np.asarray(t.context_low if low is None else low, dtype=np.float64)
    hi = np.asarray(t.context_high if high is None else high, dtype=np.float64)
    if lo.shape != (dc,) or hi.shape != (dc,) or not np.all(hi > lo):
        raise ValueError(f"low/high must be ({dc},) vectors with high > low, got {lo}, {hi}")
    if fixed is None:
        if dc != 2:
            raise ValueError(
                f"{task} has {dc} context dimensions; give fixed= (a full context) for the "
                f"ones outside dims {(d0, d1)}"
            )
        base = np.zeros(dc)
    else:
        base = np.asarray(fixed, dtype=np.float64)
        if base.shape != (dc,):
            raise ValueError(f"fixed must be a full context of shape ({dc},), got {base.shape}")
    xs = lo[d0] + (np.arange(nx) + 0.5) * (hi[d0] - lo[d0]) / nx
    ys = lo[d1] + (np.arange(ny) + 0.5) * (hi[d1] - lo[d1]) / ny
    gx, gy = np.meshgrid(xs, ys)
    out = np.broadcast_to(base, (ny, nx, dc)).copy()
    out[..., d0], out[..., d1] = gx, gy
    return out


def entropy_contexts(task: str, spec: dict[str, Any]) -> np.ndarray:
    """The contexts (m, dc) on which E_c H[π(θ | c)] is estimated (Figs. A.1, A.2).

    ``spec["entropy_grid"]``: the cell centres of a grid over a 2-D context box;
    ``spec["entropy_contexts"]``: that many draws from p(c) (uniform on the valid box), the
    same for every run and method (stream ``default_rng([0, 4])``).
    """
    if "entropy_grid" in spec:
        grid = box_grid(task, tuple(spec["entropy_grid"]))
        return grid.reshape(-1, shared_task(task).context_dim)
    if "entropy_contexts" in spec:
        n = check_count("entropy_contexts", spec["entropy_contexts"])
        return shared_task(task).sample_contexts(n, np.random.default_rng([0, 4]))
    raise ValueError(f"spec needs 'entropy_grid' or 'entropy_contexts', got keys {sorted(spec)}")


def mixture_of(model: Any) -> MixtureModel:
    """The policy π(θ | c) of a trained SVSL, HiREPS or LaDiPS object as a MixtureModel.

    All three use the same mixture with a Bayes gating (Eq. 3.1; the baselines' π(o) and
    N(c | μ_o, S_o) play the parts of SVSL's π(o) and π(c | o)), so one density serves all.
    """
    if isinstance(model, SVSL):
        return model.model
    if isinstance(model, MixtureAlgorithm):
        mix = model.mix
        return MixtureModel.from_arrays({
            "log_w": mix.log_prior, "ctx_mean": mix.ctx_mean, "ctx_cov": mix.ctx_cov,
            "gain": mix.K, "offset": mix.k, "cov": mix.cov,
        })  # fmt: skip
    raise ValueError(f"expected an SVSL, HiREPS or LaDiPS object, got {type(model).__name__}")


def expected_entropy(mix: MixtureModel, contexts: np.ndarray, draws: int, rng) -> float:
    """E_c H[π(θ | c)] over ``contexts`` (Monte Carlo, ``draws`` θ per context; A.3.2.1,
    A.3.3.1). Sets of more than 200,000 (c, θ) rows are split into batches of contexts."""
    c = np.asarray(contexts, dtype=np.float64)
    per = max(1, _ENTROPY_CHUNK // draws)
    if len(c) <= per:
        return float(np.mean(mix.expected_entropy(c, draws, rng)))
    parts = [mix.expected_entropy(c[i : i + per], draws, rng) for i in range(0, len(c), per)]
    return float(np.mean(np.concatenate(parts)))


def entropy_due(it: int, test_every: int, last: int, spec: dict[str, Any]) -> bool:
    """Whether the test point at iteration ``it`` also estimates the expected entropy: every
    ``spec["entropy_every"]``-th test point (default every one) and the last iteration."""
    return it % (test_every * spec.get("entropy_every", 1)) == 0 or it == last


def svsl_entropy(s: SVSL, contexts: np.ndarray, draws: int) -> float:
    """SVSL's expected entropy, leaving out the untrained newest expert while adding."""
    mix = MixtureModel.from_arrays(s.model.arrays())
    cfg = s.config
    if s.iteration < cfg.n_experts * cfg.iterations_per_expert and mix.n_experts > 1:
        mix.keep(np.arange(mix.n_experts) < mix.n_experts - 1)
    return expected_entropy(mix, contexts, draws, np.random.default_rng([s.seed, 3, s.iteration]))


# --------------------------------------------------------------------------------------
# context coverage and success grids
# --------------------------------------------------------------------------------------
def draw_box(ax: plt.Axes, low: Sequence[float], high: Sequence[float], **kw: Any) -> None:
    """The rectangle [low, high] (two entries each) as a dashed outline."""
    lo, hi = np.asarray(low, dtype=np.float64), np.asarray(high, dtype=np.float64)
    style = {"fill": False, "ls": "--", "color": "grey"} | kw
    ax.add_patch(Rectangle(lo, *(hi - lo), **style))


def draw_context_gaussians(ax: plt.Axes, model: Any, dims: Sequence[int] = (0, 1)) -> plt.Axes:
    """Each expert's context Gaussian, its marginal on context dims ``dims`` as a 2σ ellipse.

    The marginal of N(μ, S) on dims (i, j) is N(μ[[i, j]], S[[i, j]][:, [i, j]]). For SVSL
    these are the curricula π(c | o) (Eq. 3.1); for a baseline its gating's N(c | μ_o, S_o).
    The opacity grows with π(o).
    """
    mix = mixture_of(model)
    d = list(dims)
    if len(d) != 2 or d[0] == d[1] or not all(0 <= i < mix.context_dim for i in d):
        raise ValueError(
            f"dims must be two different indices in [0, {mix.context_dim}), got {dims!r}"
        )
    from vslbook.plots import expert_color

    weights = np.exp(mix.log_w)
    for i, (m, c) in enumerate(zip(mix.ctx_mean, mix.ctx_cov, strict=True)):
        vals, vecs = np.linalg.eigh(c[np.ix_(d, d)])
        angle = np.degrees(np.arctan2(vecs[1, -1], vecs[0, -1]))
        w, h = 4 * np.sqrt(np.maximum(vals[::-1], 1e-12))
        alpha = 0.15 + 0.6 * float(weights[i] / weights.max())
        ax.add_patch(Ellipse(m[d], w, h, angle=angle, color=expert_color(i), alpha=alpha))
    return ax


def success_grid(
    task: str,
    model: Any,
    shape: tuple[int, int],
    *,
    dims: Sequence[int] = (0, 1),
    fixed: Sequence[float] | None = None,
    low: Sequence[float] | None = None,
    high: Sequence[float] | None = None,
    n_draws: int = 10,
    seed: int = 0,
) -> np.ndarray:
    """Success rate per cell of an (n_x, n_y) grid over context dims ``dims`` (Fig. 3.2e/f).

    At each cell centre (:func:`box_grid`) ``n_draws`` experts are drawn from π(o | c) and
    their means K_o c + k_o executed; returns the fraction of successes, shape (n_y, n_x)
    (row 0 at the smallest y).
    """
    nx, ny = check_shape(shape)
    n_draws = check_count("n_draws", n_draws)
    t = shared_task(task)
    contexts = box_grid(task, (nx, ny), dims, fixed, low=low, high=high).reshape(-1, t.context_dim)
    rep = np.repeat(contexts, n_draws, axis=0)
    theta, _ = mixture_of(model).sample(rep, np.random.default_rng(seed), mean=True)
    out = t.evaluate(theta, rep, workers=None)
    return out.success.reshape(ny, nx, n_draws).mean(axis=2).astype(np.float64)


def draw_success_grid(
    ax: plt.Axes,
    grid: np.ndarray,
    extent: tuple[float, float, float, float],
    *,
    title: str = "",
    labels: tuple[str, str] = ("x [m]", "y [m]"),
) -> plt.Axes:
    """Success rates as an image over ``extent`` = (x_lo, x_hi, y_lo, y_hi) (dark: low),
    titled ``title``'s first line with the mean success, then its other lines."""
    g = np.asarray(grid, dtype=np.float64)
    if g.ndim != 2 or not np.all((g >= 0) & (g <= 1)):
        raise ValueError(f"grid must be a 2-D array of rates in [0, 1], got shape {g.shape}")
    im = ax.imshow(g, origin="lower", extent=extent, vmin=0, vmax=1, cmap="viridis",
                   aspect="equal")  # fmt: skip
    head, _, rest = title.partition("\n")
    ax.set_title(f"{head} mean success {g.mean():.0%}".strip() + (f"\n{rest}" if rest else ""),
                 fontsize=9)  # fmt: skip
    ax.set_xlabel(labels[0])
    ax.set_ylabel(labels[1])
    plt.colorbar(im, ax=ax, fraction=0.05)
    return ax
