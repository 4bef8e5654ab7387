"""Fig. 3.2 (Beer Pong panels a, c, e, f, g) and Fig. A.1: SVSL, HiREPS and LaDiPS on beer pong.

The thesis (Section 3.4.2, Appendix A.3.2) trains SVSL with N = 70 experts added one by one
(K = 750 iterations each, all experts fine-tuned every H = 50 iterations; α = 0.001, β = 0.5,
β_w = 2.5, Table A.1) and HiREPS (ε 0.3, κ 0.9, Table A.2) and LaDiPS (ε 0.1, ε_gating 0.05,
α = log 30, Table A.3) with all 70 experts from the start, over 20 seeds. Its reported
outcome (:data:`THESIS_OUTCOME`): LaDiPS is the most sample-efficient (intra-option
learning), SVSL reaches the highest final reward, HiREPS converges early after about half a
million samples; SVSL's per-expert context distributions cover the whole cup box; executing
the means of experts drawn from π(o | c) on a fine grid of cup positions succeeds 92 % of
the time for SVSL and 75 % for HiREPS on average; for one context, 20 draws from SVSL's
mixture give ball trajectories with different numbers of bounces; and SVSL's mixture has a
much higher expected entropy than LaDiPS's and HiREPS's (Fig. A.1).

What is computed here, and how:

* :func:`beer_pong_counts` — the counts per budget (a budget scales only counts: experts,
  iterations, seeds, samples per baseline iteration, test contexts, grid cells and draws;
  α, β, β_w, H, the KL bounds and the baselines' ε, κ, α stay the thesis's).
* :func:`run_beer_pong` — one method for one seed in a resumable run directory. The
  baselines run for as many iterations as SVSL evaluates episodes
  (:func:`svsl_episodes`), so the three curves span the same number of episodes.
* :func:`curve_frame` / :func:`learning_curves` — Fig. 3.2a: test return of the mixture
  (θ ~ π(θ | c) on fixed test contexts from p(c)) against *executed* episodes (θ rejected
  before simulation are not counted, A.3.2), IQM and 95 % stratified-bootstrap CI over the
  seeds (the thesis plots the mean ± 2 standard errors). Each run is interpolated onto a
  common grid of episode counts first (runs log at different counts).
* :func:`draw_context_coverage` — Fig. 3.2c: SVSL's per-expert context Gaussians.
* :func:`success_grid` — Fig. 3.2e/f: per cell of a grid over the cup box, experts drawn
  from π(o | c) at the cell's centre and their means executed; the success rate per cell.
* :func:`ball_trajectories` — Fig. 3.2g: the ball's height over time for draws from the
  mixture at one context, with the chosen expert.
* Fig. A.1: the mixture's expected entropy E_c H[π(θ | c)] (Monte Carlo on a grid of
  contexts), logged as ``expected_entropy`` at every test point of every run;
  ``learning_curves(runs, "expected_entropy")`` gives its curves.
"""

from __future__ import annotations

import math
from dataclasses import asdict
from pathlib import Path
from typing import Any

import matplotlib.pyplot as plt
import numpy as np
import pandas as pd
from matplotlib.patches import Ellipse, Rectangle

from vslbook.budget import Budget, get_budget
from vslbook.envs.robot import make_task
from vslbook.erl import hireps, ladips
from vslbook.erl.mixture_baseline import MixtureAlgorithm
from vslbook.erl.svsl import SVSL, SVSLConfig, svsl_config
from vslbook.erl.svsl import train as train_svsl
from vslbook.erl.svsl_model import MixtureModel
from vslbook.experiments.erl_runs import open_run
from vslbook.results import RunDir
from vslbook.stats import iqm_curve

__all__ = [
    "METHODS",
    "TASK",
    "THESIS_OUTCOME",
    "ball_trajectories",
    "beer_pong_counts",
    "curve_frame",
    "draw_ball_trajectories",
    "draw_context_coverage",
    "draw_success_grid",
    "draw_learning_curves",
    "grid_contexts",
    "learning_curves",
    "load_model",
    "method_config",
    "mixture_of",
    "run_beer_pong",
    "success_grid",
    "svsl_episodes",
]

TASK = "beer-pong"

#: The three methods of Fig. 3.2a, in the thesis's order.
METHODS = ("SVSL", "HiREPS", "LaDiPS")

#: What the thesis reports for the beer-pong panels (Section 3.4.2, Fig. 3.2, A.3.2.1).
THESIS_OUTCOME = {
    "curves": (
        "thesis (Fig. 3.2a): LaDiPS most sample-efficient, SVSL highest final reward, "
        "HiREPS converges early after ~0.5 M samples"
    ),
    "coverage": "thesis (Fig. 3.2c): SVSL's context distributions cover the whole cup box",
    "success": "thesis (Fig. 3.2e/f): success 92 % (SVSL) vs 75 % (HiREPS) on average",
    "success_svsl": 0.92,
    "success_hireps": 0.75,
    "trajectories": (
        "thesis (Fig. 3.2g): 20 draws at one context give ball trajectories with different "
        "numbers of bounces, one per expert"
    ),
    "entropy": (
        "thesis (Fig. A.1): SVSL's expected mixture entropy is much higher than LaDiPS's "
        "and HiREPS's"
    ),
}


# --------------------------------------------------------------------------------------
# counts and configurations
# --------------------------------------------------------------------------------------
def beer_pong_counts(budget: Budget | str | None = None) -> dict[str, Any]:
    """Counts of Fig. 3.2 (beer pong) and Fig. A.1 at a budget (full: the thesis's).

    Full: N = 70, K = 750, H = 50 (Table A.1), 20 seeds, the authors' 100 weight iterations;
    the baselines' 70 experts draw 700 episodes per iteration. The rest (test contexts, the
    success grid, the entropy grid) the thesis leaves open ("a fine grid"; 100 draws per
    context for the success rate, 1000 θ per context for the entropy).

    Smoke ("does it run") skips SVSL's weight phase (``weight_iterations = 0``) and runs one
    baseline iteration of 40 episodes; reduced (N = 3, K = 100, 3 seeds) takes about 6 min
    per SVSL run and 18 baseline iterations of 700 episodes on 2 cores. N and K are counts
    a budget may scale; H, α, β, β_w and the KL bounds are not.
    """
    b = get_budget(budget)
    return {
        "seeds": b.pick(smoke=1, reduced=3, full=20),
        "n_experts": b.pick(smoke=1, reduced=3, full=70),  # SVSL's N
        "iterations_per_expert": b.pick(smoke=3, reduced=100, full=750),  # K
        "fine_tune_every": 50,  # H: a hyper-parameter, never scaled
        "weight_iterations": b.pick(smoke=0, reduced=100, full=100),
        "test_every": b.pick(smoke=2, reduced=25, full=50),
        "test_contexts": b.pick(smoke=10, reduced=100, full=200),
        "baseline_experts": 70,  # Tables A.2, A.3 (LaDiPS's α = log 30 needs N >= 30)
        "baseline_samples": b.pick(smoke=40, reduced=700, full=700),
        # None: as many iterations as SVSL evaluates episodes (svsl_episodes)
        "baseline_iterations": b.pick(smoke=1, reduced=None, full=None),
        "grid": b.pick(smoke=(2, 3), reduced=(8, 12), full=(13, 20)),  # cells along (x, y)
        "grid_draws": b.pick(smoke=2, reduced=10, full=100),
        "entropy_grid": b.pick(smoke=(2, 2), reduced=(4, 6), full=(8, 12)),
        "entropy_draws": b.pick(smoke=20, reduced=200, full=1000),
        "trajectory_draws": b.pick(smoke=3, reduced=20, full=20),
    }


def svsl_episodes(config: SVSLConfig) -> int:
    """Episodes SVSL evaluates in a whole run (rejected θ included; tests excluded).

    Each new expert fills its buffer (``buffer_size``); every iteration updates the newest
    expert, every H-th iteration all k experts present, each update drawing
    ``new_samples_expert + new_samples_context`` episodes; the weight phase refreshes every
    buffer once. Full budget: 70·256 + 750·70·36 + 15·36·(0 + 1 + … + 69) + 70·256
    = 3,229,940.
    """
    n, k, h = config.n_experts, config.iterations_per_expert, config.fine_tune_every
    per_update = config.new_samples_expert + config.new_samples_context
    fills = n * config.buffer_size
    newest = n * k * per_update
    fine_tune = (k // h) * per_update * (n * (n - 1) // 2)
    weight_phase = n * config.buffer_size if config.weight_iterations > 0 else 0
    return fills + newest + fine_tune + weight_phase


def method_config(method: str, budget: Budget | str | None = None) -> Any:
    """The configuration of one method at a budget (SVSLConfig, HiREPSConfig, LaDiPSConfig)."""
    n = beer_pong_counts(budget)
    svsl = svsl_config(
        TASK,
        n_experts=n["n_experts"],
        iterations_per_expert=n["iterations_per_expert"],
        fine_tune_every=n["fine_tune_every"],
        weight_iterations=n["weight_iterations"],
        test_every=n["test_every"],
        test_contexts=n["test_contexts"],
    )
    if method == "SVSL":
        return svsl
    if method not in METHODS:
        raise ValueError(f"unknown method {method!r}; expected one of {METHODS}")
    samples = n["baseline_samples"]
    iterations = n["baseline_iterations"] or math.ceil(svsl_episodes(svsl) / samples)
    kw = {"n_experts": n["baseline_experts"], "samples_per_iteration": samples,
          "iterations": iterations}  # fmt: skip
    if method == "HiREPS":
        return hireps.HiREPSConfig.for_task(TASK, **kw)
    return ladips.LaDiPSConfig.for_task(TASK, **kw)


# --------------------------------------------------------------------------------------
# runs
# --------------------------------------------------------------------------------------
_TASKS: list[Any] = []


def _task() -> Any:
    """One beer-pong task per process, shared by the runs and evaluations of this module.

    Episodes are deterministic given (θ, c), so sharing changes no number; it starts the
    task's worker pool (``VSLBOOK_WORKERS``) once instead of once per run.
    """
    if not _TASKS:
        _TASKS.append(make_task(TASK))
    return _TASKS[0]


def grid_contexts(shape: tuple[int, int]) -> np.ndarray:
    """Centres of an (n_x, n_y) grid of cells over the cup box, shape (n_y, n_x, 2)."""
    nx, ny = _check_shape(shape)
    lo, hi = _task().context_low, _task().context_high
    xs = lo[0] + (np.arange(nx) + 0.5) * (hi[0] - lo[0]) / nx
    ys = lo[1] + (np.arange(ny) + 0.5) * (hi[1] - lo[1]) / ny
    gx, gy = np.meshgrid(xs, ys)
    return np.stack([gx, gy], axis=-1)


def _check_shape(shape: Any) -> tuple[int, int]:
    ok = (
        isinstance(shape, (tuple, list))
        and len(shape) == 2
        and all(isinstance(v, (int, np.integer)) and not isinstance(v, bool) and v >= 1
                for v in shape)
    )  # fmt: skip
    if not ok:
        raise ValueError(f"grid shape must be two positive integers (n_x, n_y), got {shape!r}")
    return int(shape[0]), int(shape[1])


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


def _expected_entropy(mix: MixtureModel, contexts: np.ndarray, draws: int, rng) -> float:
    """E_c H[π(θ | c)] over ``contexts`` (Monte Carlo, ``draws`` θ per context; Fig. A.1)."""
    return float(np.mean(mix.expected_entropy(contexts, draws, rng)))


def _svsl_entropy(s: SVSL, contexts: np.ndarray, draws: int) -> float:
    """SVSL's expected entropy, leaving out the untrained newest expert while adding."""
    mix = MixtureModel.from_arrays(s.model.arrays())
    cfg = s.config
    if s.iteration < cfg.n_experts * cfg.iterations_per_expert and mix.n_experts > 1:
        mix.keep(np.arange(mix.n_experts) < mix.n_experts - 1)
    return _expected_entropy(mix, contexts, draws, np.random.default_rng([s.seed, 3, s.iteration]))


def run_beer_pong(
    method: str, seed: int, root: str | Path, budget: Budget | str | None = None
) -> Path:
    """Train one method for one seed in a run directory under ``root`` (reused if done).

    Rows of ``metrics.jsonl`` carry ``samples`` (executed episodes so far) and, every
    ``test_every`` iterations and at the end, ``test_return``, ``test_success`` and
    ``expected_entropy``.
    """
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise ValueError(f"seed must be an integer >= 0, got {seed!r}")
    config = method_config(method, budget)
    n = beer_pong_counts(budget)
    ent = {"entropy_grid": list(n["entropy_grid"]), "entropy_draws": n["entropy_draws"]}
    if isinstance(config, SVSLConfig):
        return _run_svsl(config, int(seed), root, ent)
    # as many test points as SVSL has (one every test_every of its iterations)
    svsl_cfg = method_config("SVSL", budget)
    points = max(1, svsl_cfg.total_iterations // svsl_cfg.test_every)
    test = {"test_every": max(1, config.iterations // points), "test_contexts": n["test_contexts"]}
    return _run_baseline(method, config, int(seed), root, test | ent)


def _run_svsl(config: SVSLConfig, seed: int, root: str | Path, extra: dict[str, Any]) -> Path:
    """:func:`vslbook.erl.svsl.run` for beer pong, adding the expected entropy at test rows."""
    record = {"algo": "svsl", "env": TASK, "task_kwargs": {}, "seed": seed} | asdict(config)
    rd = open_run(root, record | extra)
    if rd.done:
        return rd.path
    task = _task()
    s = SVSL(task, config, seed)
    saved = rd.load_checkpoint()
    if saved is not None:
        s.load_state_dict(saved["svsl"])
    grid = grid_contexts(tuple(extra["entropy_grid"])).reshape(-1, 2)

    def log(it: int, metrics: dict[str, float]) -> None:
        if "test_return" in metrics:
            metrics["expected_entropy"] = _svsl_entropy(s, grid, extra["entropy_draws"])
        rd.log(it, **metrics)

    train_svsl(
        task, config, seed, state=s, callback=log,
        checkpoint=lambda st: rd.save_checkpoint({"svsl": st.state_dict()}),
        checkpoint_every=50,
    )  # fmt: skip
    rd.mark_done({"samples": s.samples, "experts": s.model.n_experts})
    return rd.path


def _run_baseline(
    method: str, config: Any, seed: int, root: str | Path, extra: dict[str, Any]
) -> Path:
    """HiREPS or LaDiPS in a run directory, with SVSL's test protocol every ``test_every``."""
    record = {"algo": method.lower(), "env": TASK, "seed": seed} | asdict(config)
    rd = open_run(root, record | extra)
    if rd.done:
        return rd.path
    task = _task()
    cls = hireps.HiREPS if method == "HiREPS" else ladips.LaDiPS
    algo = cls(task, config, seed, workers=None)
    saved = rd.load_checkpoint()
    if saved is not None:
        algo.load_state_dict(saved["algo"])
    tests = task.sample_contexts(extra["test_contexts"], np.random.default_rng([seed, 1]))
    grid = grid_contexts(tuple(extra["entropy_grid"])).reshape(-1, 2)
    every = extra["test_every"]
    for i in range(algo.iterations_done, config.iterations):
        metrics = algo.iteration()
        metrics["samples_iteration"] = metrics.pop("samples")
        metrics["samples"] = algo.total_samples  # executed episodes so far
        it = i + 1
        if it % every == 0 or it == config.iterations:
            # θ ~ π(θ | c) on the fixed test contexts, as SVSL.test
            th, _ = algo.sample(tests, np.random.default_rng([seed, 2, it]))
            out = task.evaluate(th, tests, workers=None)
            metrics["test_return"] = float(np.mean(out.returns))
            metrics["test_success"] = float(np.mean(out.success))
            rng = np.random.default_rng([seed, 3, it])
            draws = extra["entropy_draws"]
            metrics["expected_entropy"] = _expected_entropy(mixture_of(algo), grid, draws, rng)
        rd.log(it, **metrics)
        if it % 25 == 0 or it == config.iterations:
            rd.save_checkpoint({"algo": algo.state_dict()})
    rd.mark_done({"samples": algo.total_samples, "iterations": config.iterations})
    return rd.path


def _config_from(cls: type, cfg: dict[str, Any]) -> Any:
    fields = {k: v for k, v in cfg.items() if k in cls.__dataclass_fields__}
    return cls(**{k: tuple(v) if isinstance(v, list) else v for k, v in fields.items()})


def load_model(path: str | Path) -> Any:
    """The trained SVSL, HiREPS or LaDiPS object stored in a finished run directory."""
    rd = RunDir.open(path)
    cfg = rd.config
    algo = cfg.get("algo")
    classes = {
        "svsl": (SVSL, SVSLConfig, "svsl"),
        "hireps": (hireps.HiREPS, hireps.HiREPSConfig, "algo"),
        "ladips": (ladips.LaDiPS, ladips.LaDiPSConfig, "algo"),
    }
    if algo not in classes:
        raise ValueError(f"{rd.path}: algo {algo!r} is not one of svsl, hireps, ladips")
    state = rd.load_checkpoint()
    if state is None:
        raise FileNotFoundError(f"{rd.path} has no checkpoint")
    cls, config_cls, key = classes[algo]
    task = _task() if cfg["env"] == TASK else make_task(cfg["env"])
    model = cls(task, _config_from(config_cls, cfg), int(cfg["seed"]))
    model.load_state_dict(state[key])
    return model


# --------------------------------------------------------------------------------------
# Fig. 3.2a and Fig. A.1: curves over executed episodes
# --------------------------------------------------------------------------------------
def curve_frame(
    runs: dict[str, list[str | Path]], y: str = "test_return", points: int = 40
) -> pd.DataFrame:
    """Long frame (method, run, samples, ``y``) with every run on one grid of episode counts.

    Each run's test rows (``y`` against executed episodes ``samples``) are linearly
    interpolated onto ``points`` counts spanning all runs; a run contributes only inside
    its own range (no extrapolation).
    """
    if not runs:
        raise ValueError("runs is empty; expected {method: [run directories]}")
    unknown = [m for m in runs if m not in METHODS]
    if unknown:
        raise ValueError(f"unknown method(s) {unknown}; expected some of {METHODS}")
    tables = []
    for method, paths in runs.items():
        for j, path in enumerate(paths):
            df = RunDir.open(path).metrics_frame()
            if y not in df.columns:
                raise ValueError(f"{path}: no {y!r} column in metrics.jsonl")
            df = df[np.isfinite(pd.to_numeric(df[y], errors="coerce"))]
            tables.append((method, j, df["samples"].to_numpy(float), df[y].to_numpy(float)))
    lo = min(x[0] for *_, x, _ in tables if len(x))
    hi = max(x[-1] for *_, x, _ in tables if len(x))
    grid = np.unique(np.linspace(lo, hi, points).round())
    rows = []
    for method, j, x, v in tables:
        inside = grid[(grid >= x[0]) & (grid <= x[-1])] if len(x) else grid[:0]
        for g, val in zip(inside, np.interp(inside, x, v), strict=True):
            rows.append({"method": method, "run": j, "samples": g, y: val})
    return pd.DataFrame(rows, columns=["method", "run", "samples", y])


def learning_curves(
    runs: dict[str, list[str | Path]],
    y: str = "test_return",
    *,
    points: int = 40,
    reps: int | None = None,
    seed: int = 0,
) -> pd.DataFrame:
    """IQM and 95 % stratified-bootstrap CI over seeds per method (Fig. 3.2a; Fig. A.1 with
    ``y="expected_entropy"``): columns method, samples, iqm, lo, hi, n_runs."""
    frame = curve_frame(runs, y, points)
    return iqm_curve(frame, x="samples", y=y, run="run", group="method", reps=reps, seed=seed)


def draw_learning_curves(
    ax: plt.Axes, curves: pd.DataFrame, *, ylabel: str = "test return (IQM)",
    thesis: str | None = THESIS_OUTCOME["curves"],
) -> plt.Axes:  # fmt: skip
    """Fig. 3.2a / A.1: one IQM line with its CI band per method, the thesis's outcome as text."""
    from vslbook.plots import learning_curve

    for method, df in curves.groupby("method", sort=False):
        learning_curve(ax, df.drop(columns="method"), x="samples", label=str(method))
    ax.set_xlabel("executed episodes")
    ax.set_ylabel(ylabel)
    ax.legend(fontsize=8)
    if thesis:
        ax.text(0.01, 0.01, thesis, transform=ax.transAxes, fontsize=7, va="bottom",
                wrap=True, color="#555555")  # fmt: skip
    return ax


# --------------------------------------------------------------------------------------
# Fig. 3.2c, e, f, g
# --------------------------------------------------------------------------------------
def _draw_box(ax: plt.Axes) -> None:
    task = _task()
    lo, hi = task.context_low, task.context_high
    ax.add_patch(Rectangle(lo, *(hi - lo), fill=False, ls="--", color="grey"))


def draw_context_coverage(ax: plt.Axes, model: Any) -> plt.Axes:
    """Fig. 3.2c: each expert's context Gaussian (2σ ellipse) over the cup box.

    For SVSL these are the curricula π(c | o); for a baseline its gating's N(c | μ_o, S_o).
    The opacity grows with π(o).
    """
    mix = mixture_of(model)
    weights = np.exp(mix.log_w)
    cmap = plt.get_cmap("tab20")
    for i, (m, c) in enumerate(zip(mix.ctx_mean, mix.ctx_cov, strict=True)):
        vals, vecs = np.linalg.eigh(c)
        angle = np.degrees(np.arctan2(vecs[1, -1], vecs[0, -1]))
        w, h = 4 * np.sqrt(np.maximum(vals[::-1], 1e-12))
        alpha = 0.15 + 0.6 * float(weights[i] / weights.max())
        ax.add_patch(Ellipse(m, w, h, angle=angle, color=cmap(i % 20), alpha=alpha))
    _draw_box(ax)
    ax.set_xlim(-0.6, 0.6)
    ax.set_ylim(-2.5, -0.9)
    ax.set_aspect("equal")
    ax.set_xlabel("cup x [m]")
    ax.set_ylabel("cup y [m]")
    return ax


def _check_count(name: str, value: Any) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 1:
        raise ValueError(f"{name} must be a positive integer, got {value!r}")
    return int(value)


def success_grid(
    model: Any, shape: tuple[int, int] = (8, 12), *, n_draws: int = 10, seed: int = 0
) -> np.ndarray:
    """Fig. 3.2e/f: success rate per cell of an (n_x, n_y) grid over the cup box.

    At each cell's centre ``n_draws`` experts are drawn from π(o | c) and their means
    K_o c + k_o executed (the thesis: 100 draws per context); returns the fraction in the
    cup, shape (n_y, n_x) (row 0 at the smallest y).
    """
    nx, ny = _check_shape(shape)
    n_draws = _check_count("n_draws", n_draws)
    contexts = grid_contexts((nx, ny)).reshape(-1, 2)
    rep = np.repeat(contexts, n_draws, axis=0)
    theta, _ = mixture_of(model).sample(rep, np.random.default_rng(seed), mean=True)
    out = _task().evaluate(theta, rep, workers=None)
    return out.success.reshape(ny, nx, n_draws).mean(axis=2).astype(np.float64)


def draw_success_grid(ax: plt.Axes, grid: np.ndarray, title: str = "") -> plt.Axes:
    """Fig. 3.2e/f: the success rates as an image over the cup box (dark: low)."""
    g = np.asarray(grid, dtype=np.float64)
    if g.ndim != 2 or not np.all((g >= 0) & (g <= 1)):
        raise ValueError(f"grid must be a 2-D array of rates in [0, 1], got shape {g.shape}")
    lo, hi = _task().context_low, _task().context_high
    im = ax.imshow(g, origin="lower", extent=(lo[0], hi[0], lo[1], hi[1]), vmin=0, vmax=1,
                   cmap="viridis", aspect="equal")  # fmt: skip
    ax.set_title(f"{title} mean success {g.mean():.0%}".strip(), fontsize=9)
    ax.set_xlabel("cup x [m]")
    ax.set_ylabel("cup y [m]")
    plt.colorbar(im, ax=ax, fraction=0.05)
    return ax


def ball_trajectories(
    model: Any, context: Any, *, n_draws: int = 20, seed: int = 0
) -> list[dict[str, Any]]:
    """Fig. 3.2g: the ball's path for ``n_draws`` draws θ ~ π(θ | c) at one context.

    Each simulated draw gives ``{"expert", "t" (s), "z" (m), "success"}``; draws rejected
    before simulation (duration or joint limits, A.3.2) or unstable have no path and are
    left out.
    """
    n_draws = _check_count("n_draws", n_draws)
    task = _task()
    c = task.check_contexts(np.atleast_2d(np.asarray(context, dtype=np.float64)))
    if len(c) != 1:
        raise ValueError(f"context must be one cup position (x, y), got shape {np.shape(context)}")
    theta, experts = mixture_of(model).sample(
        np.repeat(c, n_draws, axis=0), np.random.default_rng(seed)
    )
    out = []
    for th, o in zip(theta, experts, strict=True):
        ep = task.episode(th, c[0])
        if not ep.executed or "in_cup" not in ep.info:
            continue
        path = task.ball_path
        out.append({
            "expert": int(o), "t": np.arange(len(path)) * 0.005, "z": path[:, 2].copy(),
            "success": bool(ep.success),
        })  # fmt: skip
    return out


def draw_ball_trajectories(ax: plt.Axes, trajectories: list[dict[str, Any]]) -> plt.Axes:
    """Fig. 3.2g: ball height over time, one colour per expert (solid: in the cup)."""
    cmap = plt.get_cmap("tab20")
    for tr in trajectories:
        ax.plot(tr["t"], tr["z"], color=cmap(tr["expert"] % 20), lw=1.0,
                ls="-" if tr["success"] else ":")  # fmt: skip
    ax.set_xlabel("time [s]")
    ax.set_ylabel("ball z [m]")
    return ax
