"""Live DIME runs for the Chapter 5 notebook: variants x seeds -> one long evals table.

A budget only scales counts (steps, evaluation interval, seeds). The network is *not* the
budget's business: the thesis's networks (a 2048-wide critic, 16 diffusion steps) make about
three critic updates per second on a 2-core CPU, so a notebook picks a named configuration
(:data:`vslbook.srl.dime_config.NAMED_CONFIGS`, e.g. ``"cpu-256"``) in plain sight and passes
it as ``common``; :meth:`VariantRuns.caption` then says, generated from each variant's
config, how it differs from the thesis's table and how many seeds it has. Runs go through
:func:`vslbook.training.run`, so finished runs are reused (when the code is the same),
interrupted ones resume, and diverged ones are marked FAILED and reported, not dropped.
"""

from __future__ import annotations

import warnings
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import pandas as pd

from vslbook.budget import Budget, get_budget
from vslbook.data import collect_runs, load_table
from vslbook.progress import progress_prefix, run_set_progress
from vslbook.registry import get_algorithm
from vslbook.results import RunDir
from vslbook.srl.dime_config import describe_differences, named_config
from vslbook.training import run, run_seeds


@dataclass
class VariantRuns:
    """What :func:`run_variants` returns.

    Attributes:
        evals: the long metrics table of every run (``run, step, metric, value, ...``) with
            an extra ``variant`` column holding the label.
        runs: the run directories of each label, one per seed in seed order.
        overrides: the config overrides of each label (named configuration, common and the
            variant's own), from which the captions are generated.
    """

    evals: pd.DataFrame
    runs: dict[str, list[RunDir]]
    overrides: dict[str, tuple[str, dict[str, Any]]] = field(default_factory=dict)

    @property
    def unusable(self) -> dict[str, str]:
        """``{run name: status or failure}`` for every run that is not DONE."""
        out = {}
        for rds in self.runs.values():
            for rd in rds:
                if rd.failed:
                    out[rd.name] = f"FAILED: {rd.failure.get('message')}"
                elif not rd.done:
                    out[rd.name] = rd.status
        return out

    def curve_rows(self, metric: str = "eval_return") -> pd.DataFrame:
        """Rows of one metric from the finished runs, ready for :func:`vslbook.stats.iqm_curve`.

        Runs that are not DONE (diverged or incomplete) are left out *with a warning that
        names them*; :attr:`unusable` lists them too.
        """
        rows = self.evals[self.evals.metric == metric]
        if rows.empty:
            known = ", ".join(sorted(self.evals.metric.unique()))
            raise ValueError(f"no metric {metric!r} in these runs; they logged: {known}")
        bad = self.unusable
        if bad:
            listed = "; ".join(f"{name} ({why})" for name, why in bad.items())
            warnings.warn(
                f"{len(bad)} run(s) could not be used for {metric!r}: {listed}", stacklevel=2
            )
            rows = rows[~rows.run.isin(bad)]
        return rows

    def seeds(self, label: str) -> int:
        """How many finished (DONE) runs the variant ``label`` has."""
        return sum(rd.done for rd in self.runs[label])

    def caption(self, label: str) -> str:
        """``"<label>: <n> seed(s), <differences from the thesis's table>"`` from the config."""
        algo, overrides = self.overrides[label]
        spec = get_algorithm(algo)
        seeds = self.seeds(label)
        return (
            f"{label} ({algo}): {seeds} seed{'s' if seeds != 1 else ''}, "
            f"{describe_differences(overrides, spec.config)}"
        )

    def captions(self) -> str:
        """One caption line per variant, plus the runs that could not be used, if any."""
        lines = [self.caption(label) for label in self.runs]
        bad = self.unusable
        if bad:
            lines.append(f"not used ({len(bad)}): " + ", ".join(bad))
        return "\n".join(lines)


def run_variants(
    env: str,
    variants: Mapping[str, tuple[str, Mapping[str, Any]]],
    *,
    seeds: int,
    budget: Budget | str | None = None,
    root: str | Path,
    tables: str | Path,
    common: Mapping[str, Any] | None = None,
    progress: bool = True,
    reuse_stale: bool | None = None,
) -> VariantRuns:
    """Train every ``{label: (algo, overrides)}`` for ``seeds`` seeds (0 .. seeds-1).

    The seeds of one variant train together in one process where the algorithm can
    (:func:`vslbook.training.run_seeds`; the same run directories as one seed at a time).

    ``common`` (e.g. a named configuration plus run lengths) is applied first, then each
    variant's overrides. The metrics are written by :func:`vslbook.data.collect_runs` to
    ``tables`` and read back through its sha256 check, so the returned table is exactly what
    a later analysis would load. Finished runs made by the same code are reused, interrupted
    ones resume, stale ones are re-run unless ``reuse_stale`` (see
    :func:`vslbook.training.run`); ``progress`` shows a bar per run (per variant where its
    seeds train together), labelled with the variant; on the book's pages one line for the
    whole set (:func:`vslbook.progress.run_set_progress`).
    """
    if isinstance(seeds, bool) or not isinstance(seeds, int) or seeds < 1:
        raise ValueError(f"seeds must be an integer >= 1, got {seeds!r}")
    bud = get_budget(budget)
    if not variants:
        raise ValueError("variants is empty; expected {label: (algo, overrides)}")
    labels: dict[str, str] = {}
    by_label: dict[str, list[RunDir]] = {}
    used: dict[str, tuple[str, dict[str, Any]]] = {}
    with run_set_progress(f"{env} runs ({len(variants)} variant(s) × {seeds} seed(s))"):
        for label, (algo, overrides) in variants.items():
            over = {**(common or {}), **overrides}
            used[label] = (algo, over)
            with progress_prefix(label):
                if seeds > 1 and get_algorithm(algo).train_seeds is not None:  # seed axis
                    rds = run_seeds(
                        algo, env, list(range(seeds)), bud, root=root, overrides=over,
                        progress=progress, reuse_stale=reuse_stale,
                    )  # fmt: skip
                else:
                    rds = [
                        run(algo, env, seed, bud, root=root, overrides=over,
                            progress=progress, reuse_stale=reuse_stale)
                        for seed in range(seeds)
                    ]  # fmt: skip
            for rd in rds:
                labels[rd.name] = label
                by_label.setdefault(label, []).append(rd)
    collect_runs([rd for rds in by_label.values() for rd in rds], tables)
    evals = load_table("evals.csv.gz", tables)
    evals["variant"] = evals["run"].map(labels)
    return VariantRuns(evals, by_label, used)


#: The ablation variants of the notebook's Section 5 on Pendulum-v1 (the thesis panel each
#: stands for is in the notebook's table): label -> (algorithm, overrides).
ABLATIONS: dict[str, tuple[str, dict[str, Any]]] = {
    "DIME": ("dime", {}),
    "2 steps": ("dime", {"n_diffusion_steps": 2}),
    "fixed α = 0.1": ("dime", {"fixed_alpha": 0.1}),
    "Gaussian": ("dime-gaussian", {}),
    "no distr. Q": ("dime", {"critic": "scalar"}),
    "GB": ("dime", {"general_bridges": True}),
    "fixed β": ("dime", {"learn_beta": False}),
    "CrossQ": ("crossq", {}),
}
#: The fixed α of the Fig. 5.7 point-mass panels (the thesis's run from small α up to 4, 5).
POINT_MASS_ALPHAS = (0.01, 1.0, 5.0)


@dataclass(frozen=True)
class RunSet:
    """One of Chapter 5's live run sets: what :func:`run_variants` trains for a figure."""

    env: str
    variants: dict[str, tuple[str, dict[str, Any]]]
    seeds: int
    common: dict[str, Any]

    def run(
        self,
        budget: Budget | str | None,
        root: str | Path,
        tables: str | Path,
        **kwargs: Any,
    ) -> VariantRuns:
        """:func:`run_variants` of this set (``kwargs``: ``progress``, ``reuse_stale``)."""
        return run_variants(
            self.env, self.variants, seeds=self.seeds, budget=budget, root=root,
            tables=tables, common=self.common, **kwargs,
        )  # fmt: skip


def chapter5_run_sets(
    budget: Budget | str | None = None, *, dmc: str = "cpu-256", small: str = "cpu-64"
) -> dict[str, RunSet]:
    """The live run sets of the Chapter 5 notebook at ``budget``, by name.

    * ``"cheetah"``: DIME on DeepMind Control cheetah-run next to the published curve, the
      thesis's 1M steps scaled by the budget, ``budget.seeds`` seeds, evaluated every 24k
      steps at ``full`` (as published), every 6k at ``reduced`` (120k scaled), once at
      ``smoke``; network ``dmc``.
    * ``"ablations"``: :data:`ABLATIONS` on Pendulum-v1, ``budget.seeds`` seeds, 100k steps
      at ``full`` / 15k at ``reduced`` / 5050 at ``smoke`` (Table C.2's 5000 exploration
      steps included), value range [-1600, 100]; network ``small``.
    * ``"pointmass"``: Fig. 5.7, DIME with a target network and each fixed α of
      :data:`POINT_MASS_ALPHAS`, one seed (the figure shows one agent), 100k / 10k / 5050
      steps; network ``small``.

    ``dmc`` and ``small`` are named configurations
    (:data:`vslbook.srl.dime_config.NAMED_CONFIGS`); only counts depend on the budget.
    """
    b = get_budget(budget)
    ablation_steps = b.pick(smoke=5_050, reduced=15_000, full=100_000)
    pm_steps = b.pick(smoke=5_050, reduced=10_000, full=100_000)
    return {
        "cheetah": RunSet(
            "dm_control/cheetah-run-v0",
            {"DIME": ("dime", {})},
            b.seeds,
            {**named_config(dmc), "total_steps": 1_000_000,
             "eval_every": b.pick(smoke=1_000_000, reduced=120_000, full=24_000)},
        ),  # fmt: skip
        "ablations": RunSet(
            "Pendulum-v1",
            dict(ABLATIONS),
            b.seeds,
            {**named_config(small), "total_steps": b.full_count(ablation_steps),
             "eval_every": b.full_count(b.pick(smoke=5_050, reduced=1_000, full=5_000)),
             "v_min": -1600.0, "v_max": 100.0},
        ),  # fmt: skip
        "pointmass": RunSet(
            "vslbook/PointMassFourGoals-v0",
            {f"α = {a:g}": ("dime", {"fixed_alpha": a}) for a in POINT_MASS_ALPHAS},
            1,
            {**named_config(small), "use_target_network": True,
             "total_steps": b.full_count(pm_steps), "eval_every": b.full_count(pm_steps)},
        ),  # fmt: skip
    }


def load_agent(run_dir: RunDir):
    """Rebuild the agent (policy, critics, α) of a run from its last checkpoint.

    Returns ``(agent, env)``: the :class:`vslbook.srl.dime.Agent` in eval mode and a fresh
    environment of the run's task.
    """
    from vslbook.envs import make
    from vslbook.registry import config_from_record
    from vslbook.srl.dime import default_value_range, make_agent

    config = run_dir.config
    spec = get_algorithm(config["algo"])
    cfg = config_from_record(spec.config, config)
    env = make(config["env"])
    v_min, v_max = cfg.v_min, cfg.v_max
    if cfg.critic == "distributional" and v_min is None:
        v_min, v_max = default_value_range(config["env"])
    agent = make_agent(
        env.observation_space.shape[0], env.action_space.shape[0], cfg, v_min=v_min, v_max=v_max
    )
    state = run_dir.load_checkpoint()
    if state is None:
        raise ValueError(f"run {run_dir.path} has no checkpoint to load")
    agent.load_state_dict(state["agent"])
    agent.policy.eval()
    agent.critic.eval()
    return agent, env
