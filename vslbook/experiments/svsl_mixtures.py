"""SVSL, HiREPS and LaDiPS on any Chapter 3 robot task: runs, curves, coverage, success grids.

The task-independent part of Fig. 3.2 and Figs. A.1 / A.2 (thesis Section 3.4.2, Appendix
A.3.2, A.3.3); :mod:`vslbook.experiments.svsl_beer_pong` and
:mod:`vslbook.experiments.svsl_table_tennis` fill in the counts and drawings of one task.

A task is named as in :mod:`vslbook.envs.robot` (``"beer-pong"``, ``"table-tennis-ch3"``);
its counts are a dict (the ``*_counts(budget)`` functions of the task modules) with the keys

* ``n_experts``, ``iterations_per_expert``, ``fine_tune_every``, ``weight_iterations``,
  ``test_every``, ``test_contexts`` — SVSL's N, K, H, weight iterations and test protocol;
* ``baseline_experts``, ``baseline_samples``, ``baseline_iterations`` — the baselines' N,
  episodes per iteration and iterations (None: as many iterations as SVSL evaluates
  episodes, :func:`svsl_episodes`, so the three curves span the same number of episodes);
* ``entropy_draws`` and either ``entropy_grid`` (cells (n_x, n_y) over a 2-D context box)
  or ``entropy_contexts`` (that many contexts drawn once from p(c) with a fixed stream):
  where the expected mixture entropy E_c H[π(θ | c)] of Figs. A.1 / A.2 is estimated;
  optionally ``entropy_every``: estimate it only at every that-many-th test point (and at
  the end), for entropy sets too costly to evaluate at every test.

What is computed here:

* :func:`run_method` — one method for one seed in a resumable run directory. Rows of
  ``metrics.jsonl`` carry ``samples`` (executed episodes; θ rejected before simulation are
  not counted, A.3.2 / A.3.3) and, at every test point, ``test_return`` and
  ``test_success`` (θ ~ π(θ | c) on fixed test contexts from p(c)) and
  ``expected_entropy``.
* :func:`curve_frame` / :func:`learning_curves` — curves against executed episodes, IQM and
  95 % stratified-bootstrap CI over seeds (the thesis plots the mean ± 2 standard errors).
* :func:`mixture_of` — the three methods' policies as one mixture type (Eq. 3.1).
* :func:`box_grid`, :func:`success_grid` — a grid over two chosen context dimensions (the
  others fixed) and the success rate per cell of executing the means of experts drawn from
  π(o | c).
* :func:`draw_context_gaussians` — the per-expert context Gaussians projected on two
  context dimensions (their marginals).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import asdict
from pathlib import Path
from typing import Any

import matplotlib.pyplot as plt
import numpy as np
import pandas as pd
from matplotlib.patches import Ellipse, Rectangle

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
    "box_grid",
    "check_method",
    "curve_frame",
    "draw_context_gaussians",
    "draw_learning_curves",
    "draw_success_grid",
    "entropy_contexts",
    "expected_entropy",
    "learning_curves",
    "load_model",
    "method_config",
    "mixture_of",
    "run_method",
    "shared_task",
    "success_grid",
    "svsl_episodes",
    "train_baseline",
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


def _svsl_entropy(s: SVSL, contexts: np.ndarray, draws: int) -> float:
    """SVSL's expected entropy, leaving out the untrained newest expert while adding."""
    mix = MixtureModel.from_arrays(s.model.arrays())
    cfg = s.config
    if s.iteration < cfg.n_experts * cfg.iterations_per_expert and mix.n_experts > 1:
        mix.keep(np.arange(mix.n_experts) < mix.n_experts - 1)
    return expected_entropy(mix, contexts, draws, np.random.default_rng([s.seed, 3, s.iteration]))


# --------------------------------------------------------------------------------------
# runs
# --------------------------------------------------------------------------------------
def _entropy_spec(counts: dict[str, Any]) -> dict[str, Any]:
    if "entropy_grid" in counts:
        spec: dict[str, Any] = {"entropy_grid": list(counts["entropy_grid"])}
    else:
        spec = {"entropy_contexts": counts["entropy_contexts"]}
    spec["entropy_draws"] = counts["entropy_draws"]
    if counts.get("entropy_every", 1) != 1:
        spec["entropy_every"] = check_count("entropy_every", counts["entropy_every"])
    return spec


def _entropy_due(it: int, test_every: int, last: int, extra: dict[str, Any]) -> bool:
    """Whether the test point at iteration ``it`` also estimates the expected entropy."""
    return it % (test_every * extra.get("entropy_every", 1)) == 0 or it == last


def run_method(task: str, method: str, seed: int, root: str | Path, counts: dict[str, Any]) -> Path:
    """Train one method for one seed on ``task`` in a run directory under ``root``.

    A finished run with the same configuration is reused, an unfinished one resumed. Rows
    of ``metrics.jsonl`` carry ``samples`` (executed episodes so far) and, every
    ``test_every`` iterations and at the end, ``test_return``, ``test_success`` and
    ``expected_entropy``. The baselines test as often as SVSL (the same number of test
    points over their run).
    """
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise ValueError(f"seed must be an integer >= 0, got {seed!r}")
    config = method_config(task, method, counts)
    ent = _entropy_spec(counts)
    if isinstance(config, SVSLConfig):
        return _run_svsl(task, config, int(seed), root, ent)
    svsl_cfg = method_config(task, "SVSL", counts)
    points = max(1, svsl_cfg.total_iterations // svsl_cfg.test_every)
    test = {"test_every": max(1, config.iterations // points),
            "test_contexts": counts["test_contexts"]}  # fmt: skip
    return _run_baseline(task, method, config, int(seed), root, test | ent)


def _run_svsl(
    task_name: str, config: SVSLConfig, seed: int, root: str | Path, extra: dict[str, Any]
) -> Path:
    """:func:`vslbook.erl.svsl.train` in a run directory, adding the expected entropy."""
    record = {"algo": "svsl", "env": task_name, "task_kwargs": {}, "seed": seed} | asdict(config)
    rd = open_run(root, record | extra)
    if rd.done:
        return rd.path
    task = shared_task(task_name)
    s = SVSL(task, config, seed)
    saved = rd.load_checkpoint()
    if saved is not None:
        s.load_state_dict(saved["svsl"])
    contexts = entropy_contexts(task_name, extra)

    def log(it: int, metrics: dict[str, float]) -> None:
        if "test_return" in metrics and _entropy_due(
            it, config.test_every, config.total_iterations, extra
        ):
            metrics["expected_entropy"] = _svsl_entropy(s, contexts, extra["entropy_draws"])
        rd.log(it, **metrics)

    train_svsl(
        task, config, seed, state=s, callback=log,
        checkpoint=lambda st: rd.save_checkpoint({"svsl": st.state_dict()}),
        checkpoint_every=50,
    )  # fmt: skip
    rd.mark_done({"samples": s.samples, "experts": s.model.n_experts})
    return rd.path


def _run_baseline(
    task_name: str, method: str, config: Any, seed: int, root: str | Path, extra: dict[str, Any]
) -> Path:
    """HiREPS or LaDiPS in a run directory, with SVSL's test protocol every ``test_every``."""
    record = {"algo": method.lower(), "env": task_name, "seed": seed} | asdict(config)
    rd = open_run(root, record | extra)
    if rd.done:
        return rd.path
    algo = train_baseline(rd, shared_task(task_name), method, config, seed, extra, workers=None)
    rd.mark_done({"samples": algo.total_samples, "iterations": config.iterations})
    return rd.path


def train_baseline(
    rd: RunDir,
    task: Any,
    method: str,
    config: Any,
    seed: int,
    extra: dict[str, Any],
    *,
    stop_after: int | None = None,
    workers: int | None = 0,
    progress: bool = False,
) -> MixtureAlgorithm:
    """Iterations of HiREPS or LaDiPS in ``rd``, resuming from its checkpoint.

    Every ``extra["test_every"]`` iterations and at the end, θ ~ π(θ | c) is evaluated on
    ``extra["test_contexts"]`` fixed contexts from p(c) (as :meth:`SVSL.test`); with
    ``extra["entropy_draws"]`` the expected mixture entropy is estimated there too. Stops
    after ``stop_after`` iterations of this call (default: all), checkpointing there; the
    caller marks the run done once ``algo.iterations_done == config.iterations``.
    """
    check_method(method)
    cls = hireps.HiREPS if method == "HiREPS" else ladips.LaDiPS
    algo = cls(task, config, seed, workers=workers)
    saved = rd.load_checkpoint()
    if saved is not None:
        algo.load_state_dict(saved["algo"])
    tests = task.sample_contexts(extra["test_contexts"], np.random.default_rng([seed, 1]))
    contexts = entropy_contexts(task.name, extra) if "entropy_draws" in extra else None
    every = extra["test_every"]
    stop = config.iterations
    if stop_after is not None:
        stop = min(algo.iterations_done + int(stop_after), stop)
    bar = None
    if progress:
        from tqdm.auto import tqdm

        bar = tqdm(total=config.iterations, initial=algo.iterations_done, desc=method)
    for i in range(algo.iterations_done, stop):
        metrics = algo.iteration()
        metrics["samples_iteration"] = metrics.pop("samples")
        metrics["samples"] = algo.total_samples  # executed episodes so far
        it = i + 1
        if it % every == 0 or it == config.iterations:
            # θ ~ π(θ | c) on the fixed test contexts, as SVSL.test
            th, _ = algo.sample(tests, np.random.default_rng([seed, 2, it]))
            out = task.evaluate(th, tests, workers=workers)
            metrics["test_return"] = float(np.mean(out.returns))
            metrics["test_success"] = float(np.mean(out.success))
            if contexts is not None and _entropy_due(it, every, config.iterations, extra):
                rng = np.random.default_rng([seed, 3, it])
                metrics["expected_entropy"] = expected_entropy(
                    mixture_of(algo), contexts, extra["entropy_draws"], rng
                )
        rd.log(it, **metrics)
        if bar is not None:
            bar.update(1)
        if it % 25 == 0 or it == stop:
            rd.save_checkpoint({"algo": algo.state_dict()})
    if bar is not None:
        bar.close()
    return algo


def _config_from(cls: type, cfg: dict[str, Any]) -> Any:
    fields = {k: v for k, v in cfg.items() if k in cls.__dataclass_fields__}
    return cls(**{k: tuple(v) if isinstance(v, list) else v for k, v in fields.items()})


def load_model(path: str | Path) -> Any:
    """The trained SVSL, HiREPS or LaDiPS object stored in a run directory's checkpoint."""
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
    model = cls(shared_task(cfg["env"]), _config_from(config_cls, cfg), int(cfg["seed"]))
    model.load_state_dict(state[key])
    return model


# --------------------------------------------------------------------------------------
# curves over executed episodes (Fig. 3.2a/b, Figs. A.1, A.2)
# --------------------------------------------------------------------------------------
def curve_frame(
    runs: dict[str, list[str | Path]],
    y: str = "test_return",
    points: int = 40,
    methods: Sequence[str] = METHODS,
) -> pd.DataFrame:
    """Long frame (method, run, samples, ``y``) with every run on one grid of episode counts.

    Each run's test rows (``y`` against executed episodes ``samples``) are linearly
    interpolated onto ``points`` counts spanning all runs; a run contributes only inside
    its own range (no extrapolation). ``methods``: the names ``runs`` may use.
    """
    if not runs:
        raise ValueError("runs is empty; expected {method: [run directories]}")
    unknown = [m for m in runs if m not in methods]
    if unknown:
        raise ValueError(f"unknown method(s) {unknown}; expected some of {tuple(methods)}")
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
    methods: Sequence[str] = METHODS,
) -> pd.DataFrame:
    """IQM and 95 % stratified-bootstrap CI over seeds per method (Fig. 3.2a/b; Figs. A.1,
    A.2 with ``y="expected_entropy"``; Chapter 4's curves with their ``methods``): columns
    method, samples, iqm, lo, hi, n_runs."""
    frame = curve_frame(runs, y, points, methods)
    return iqm_curve(frame, x="samples", y=y, run="run", group="method", reps=reps, seed=seed)


def draw_learning_curves(
    ax: plt.Axes, curves: pd.DataFrame, *, ylabel: str = "test return (IQM)",
    thesis: str | None = None,
) -> plt.Axes:  # fmt: skip
    """One IQM line with its CI band per method over executed episodes, the thesis's
    outcome (``thesis``) as text."""
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
    weights = np.exp(mix.log_w)
    cmap = plt.get_cmap("tab20")
    for i, (m, c) in enumerate(zip(mix.ctx_mean, mix.ctx_cov, strict=True)):
        vals, vecs = np.linalg.eigh(c[np.ix_(d, d)])
        angle = np.degrees(np.arctan2(vecs[1, -1], vecs[0, -1]))
        w, h = 4 * np.sqrt(np.maximum(vals[::-1], 1e-12))
        alpha = 0.15 + 0.6 * float(weights[i] / weights.max())
        ax.add_patch(Ellipse(m[d], w, h, angle=angle, color=cmap(i % 20), alpha=alpha))
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
    """Success rates as an image over ``extent`` = (x_lo, x_hi, y_lo, y_hi) (dark: low)."""
    g = np.asarray(grid, dtype=np.float64)
    if g.ndim != 2 or not np.all((g >= 0) & (g <= 1)):
        raise ValueError(f"grid must be a 2-D array of rates in [0, 1], got shape {g.shape}")
    im = ax.imshow(g, origin="lower", extent=extent, vmin=0, vmax=1, cmap="viridis",
                   aspect="equal")  # fmt: skip
    ax.set_title(f"{title} mean success {g.mean():.0%}".strip(), fontsize=9)
    ax.set_xlabel(labels[0])
    ax.set_ylabel(labels[1])
    plt.colorbar(im, ax=ax, fraction=0.05)
    return ax
