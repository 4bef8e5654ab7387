"""Live DIME runs for the Chapter 5 notebook: variants x seeds -> one long evals table.

The thesis's networks (a 2048-wide critic, 16 diffusion steps) make about three critic
updates per second on a 2-core CPU, so the notebook's *live* runs use a smaller network,
chosen per budget by :func:`live_network` and printed next to every curve; the ``full``
budget uses the thesis's sizes. Counts (steps, evaluation interval) are full-budget values
that the budget scales, as everywhere in vslbook. Runs go through :func:`vslbook.training.run`,
so finished runs are reused and interrupted ones resume.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pandas as pd

from vslbook.budget import Budget, get_budget
from vslbook.results import RunDir, collect_runs, load_table
from vslbook.training import run


def live_network(budget: Budget | str | None = None) -> dict[str, Any]:
    """Network sizes for live runs: small on CPU budgets, the thesis's at ``full``."""
    bud = get_budget(budget)
    return bud.pick(
        smoke=dict(critic_hidden=64, actor_hidden=64, n_diffusion_steps=4, num_threads=2),
        reduced=dict(critic_hidden=256, actor_hidden=256, n_diffusion_steps=4),
        full={},
    )


@dataclass
class VariantRuns:
    """What :func:`run_variants` returns.

    Attributes:
        evals: the long metrics table of every run (``run, step, metric, value, ...``) with
            an extra ``variant`` column holding the label.
        runs: the run directories of each label, one per seed in seed order.
    """

    evals: pd.DataFrame
    runs: dict[str, list[RunDir]]

    def curve_rows(self, metric: str = "eval_return") -> pd.DataFrame:
        """Rows of one metric, ready for :func:`vslbook.stats.iqm_curve` (x ``step``)."""
        rows = self.evals[self.evals.metric == metric]
        if rows.empty:
            known = ", ".join(sorted(self.evals.metric.unique()))
            raise ValueError(f"no metric {metric!r} in these runs; they logged: {known}")
        return rows


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
) -> VariantRuns:
    """Train every ``{label: (algo, overrides)}`` for ``seeds`` seeds.

    Overrides are applied over :func:`live_network` and ``common``. The metrics are written
    by :func:`vslbook.results.collect_runs` to ``tables`` and read back through its sha256
    check, so the returned table is exactly what a later analysis would load. Finished runs
    are reused and interrupted ones resume (:func:`vslbook.training.run`); ``progress``
    shows a bar per run.
    """
    if seeds < 1:
        raise ValueError(f"seeds must be >= 1, got {seeds}")
    bud = get_budget(budget)
    if not variants:
        raise ValueError("variants is empty; expected {label: (algo, overrides)}")
    labels: dict[str, str] = {}
    by_label: dict[str, list[RunDir]] = {}
    for label, (algo, overrides) in variants.items():
        for seed in range(seeds):
            over = {**live_network(bud), **(common or {}), **overrides}
            rd = run(algo, env, seed, bud, root=root, overrides=over, progress=progress)
            labels[rd.name] = label
            by_label.setdefault(label, []).append(rd)
    collect_runs([rd for rds in by_label.values() for rd in rds], tables)
    evals = load_table("evals.csv.gz", tables)
    evals["variant"] = evals["run"].map(labels)
    return VariantRuns(evals, by_label)


def load_agent(run_dir: RunDir):
    """Rebuild the agent (policy, critics, α) of a run from its last checkpoint.

    Returns ``(agent, env)``: the :class:`vslbook.srl.dime.Agent` in eval mode and a fresh
    environment of the run's task.
    """
    from vslbook.envs import make
    from vslbook.registry import config_from_record, get_algorithm
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
