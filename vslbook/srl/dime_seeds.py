"""Algorithm 4 for S seeds in one process: :func:`vslbook.srl.dime_loop.run_algorithm4`
over a seed axis (:class:`~vslbook.srl.seed_axis.SeedStack`).

Each seed has its own run directory, environment, replay buffer, numpy generator (uniform
exploration, replay indices) and torch generator (policy noise), seeded as its single-seed
run seeds them, and its own evaluations and diagnostics
(:class:`~vslbook.srl.dime_state.SeedState`); only the network updates are batched, by the
:class:`StackedSeeds` learner the loop calls where a single seed's calls
:class:`~vslbook.srl.dime_loop.OneSeed`. Per seed the numbers are those of a single-seed run
up to float rounding (batched matrix products round differently), which the tests check
update by update.

Checkpoints. All seeds are checkpointed at the same environment step (every
``checkpoint_every`` steps, at least every ``$VSLBOOK_CHECKPOINT_SECONDS``, and when
``stop_after`` stops the run), each into its own run directory in the single-seed format,
plus the actions of each seed's unfinished episode: on resume the environment is reset with
that episode's seed and the actions are replayed (the simulators are deterministic), so no
simulator state is pickled and an episode may be cut anywhere. A seed whose losses or
parameters stop being finite is marked FAILED and leaves the stack; the others go on.
Configurations with a target network (an ablation) have no seed axis: their seeds are
trained one after the other by the single-seed loop.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from typing import Any

import numpy as np
import torch
from torch import Tensor

from vslbook.budget import Budget
from vslbook.registry import config_from_record
from vslbook.results import DivergenceError, RunDir
from vslbook.srl.cuda_graphs import GraphedUpdates, graphs_wanted
from vslbook.srl.dime_config import DIMEConfig
from vslbook.srl.dime_loop import DimeLoop, run_algorithm4, train
from vslbook.srl.dime_state import Schedule, SeedState
from vslbook.srl.dime_updates import Agent, UpdateStats, resolve_device
from vslbook.srl.replay import Batch
from vslbook.srl.seed_axis import SeedStack

__all__ = ["StackedSeeds", "train_seeds"]


class StackedSeeds:
    """The :class:`~vslbook.srl.dime_loop.Learner` of seeds trained as one
    :class:`~vslbook.srl.seed_axis.SeedStack` (eager, or replayed as CUDA graphs): seed s
    draws its policy noise from its own generator (``SeedState.noise``), in the chunks its
    single-seed run draws them from torch's global stream."""

    together = True

    def __init__(self, seeds: list[SeedState], cfg: DIMEConfig, device: torch.device) -> None:
        self.cfg, self.device = cfg, device
        self.agents = [s.agent for s in seeds]  # each seed's own modules, in stack order
        self.stack = SeedStack(self.agents)
        self.use_graphs = graphs_wanted(cfg, device)
        self._graphs: GraphedUpdates | None = None  # the stack's (captured again after a drop)
        self._eval_graphs = [GraphedUpdates(a) if self.use_graphs else None for a in self.agents]

    def graphs(self) -> GraphedUpdates | None:
        """The stack's CUDA graphs, or None (eager updates)."""
        if self.use_graphs and (self._graphs is None or self._graphs.learner is not self.stack):
            self._graphs = GraphedUpdates(self.stack)
        return self._graphs

    def act(self, seeds: list[SeedState]) -> list[np.ndarray]:
        obs = torch.as_tensor(np.stack([s.obs for s in seeds]), dtype=torch.float32,
                              device=self.device)  # fmt: skip
        noise = self.stack.noise([s.noise for s in seeds], 1)
        g = self.graphs()
        actions = self.stack.act(obs, noise) if g is None else g.act(obs, noise)
        return list(actions.cpu().numpy())

    def batch(self, batches: list[Batch]) -> Batch:
        return Batch(*[torch.stack(x) for x in zip(*batches, strict=True)])

    def critic_update(self, seeds: list[SeedState], batch: Batch) -> UpdateStats:
        noise = self.stack.noise([s.noise for s in seeds], self.cfg.batch_size)
        g = self.graphs()
        return (self.stack.critic_update(batch, noise) if g is None
                else g.critic_update(batch, noise))  # fmt: skip

    def actor_alpha_update(self, seeds: list[SeedState], obs: Tensor) -> tuple[UpdateStats, Tensor]:
        noise = self.stack.noise([s.noise for s in seeds], self.cfg.batch_size)
        g = self.graphs()
        if g is not None:
            return g.actor_alpha_update(obs, noise)
        stats = self.stack.actor_update(obs, noise)
        return stats, self.stack.alpha_update(stats.running_cost)

    def agent(self, k: int) -> Agent:
        self.agents[k].load_state_dict(self.stack.agent_state(k))  # its policy, as one module
        return self.agents[k]

    def agent_state(self, k: int) -> dict[str, Any]:
        return self.stack.agent_state(k)

    def eval_graphs(self, k: int) -> GraphedUpdates | None:
        return self._eval_graphs[k]

    def keep(self, positions: list[int]) -> None:
        states = [self.stack.agent_state(pos) for pos in positions]
        self.agents = [self.agents[pos] for pos in positions]
        self._eval_graphs = [self._eval_graphs[pos] for pos in positions]
        for agent, state in zip(self.agents, states, strict=True):
            agent.load_state_dict(state)
        if self.agents:
            self.stack = SeedStack(self.agents)


def train_seeds(
    runs: list[RunDir],
    records: list[dict],
    budget: Budget,
    *,
    progress: bool = True,
    stop_after: int | None = None,
    config_cls: type[DIMEConfig] = DIMEConfig,
) -> list[dict | DivergenceError | None]:
    """Train the seeds of ``records`` (one run directory each) together, resuming them.

    The records differ only in ``seed``. Seeds whose checkpoints are at the same environment
    step train as one stack; groups at different steps train one after the other. Returns
    per seed a summary when finished, None when stopped early (``stop_after`` environment
    steps of this call) and the :class:`~vslbook.results.DivergenceError` of a seed that
    diverged.
    """
    if len(runs) != len(records) or not runs:
        raise ValueError(f"need one run directory per record, got {len(runs)} and {len(records)}")
    cfg = config_from_record(config_cls, records[0])
    for r in records[1:]:
        if config_from_record(config_cls, r) != cfg or r["env"] != records[0]["env"]:
            raise ValueError("the seeds trained together must share env and configuration")
    # One seed after the other through the single-seed loop: the target-network ablation
    # (no seed axis for the target copy), and compiled updates (``compile`` wraps the
    # single-seed update functions; the vmap-ed stacked ones are not compiled).
    if cfg.use_target_network or cfg.compile:
        out: list[Any] = []
        for run, rec in zip(runs, records, strict=True):
            try:
                out.append(train(run, rec, budget, progress=progress, stop_after=stop_after,
                                 config_cls=config_cls))  # fmt: skip
            except DivergenceError as err:
                run.mark_failed(err)
                out.append(err)
        return out
    if cfg.num_threads:
        torch.set_num_threads(cfg.num_threads)
    device = resolve_device(cfg.device)

    def create(i: int) -> SeedState:
        return SeedState.create(runs[i], records[i], cfg, budget, device, own_noise=True)

    seeds = [create(i) for i in range(len(runs))]
    _align(seeds, create)
    groups: dict[int, list[int]] = {}  # checkpoints at different steps: one group per step
    for i, s in enumerate(seeds):
        groups.setdefault(s.step, []).append(i)
    results: list[Any] = [None] * len(seeds)
    for _, members in sorted(groups.items()):
        group = [seeds[i] for i in members]
        desc = (f"{records[0].get('algo', 'dime')} {records[0]['env']} seeds "
                f"{','.join(str(s.seed) for s in group)}")  # fmt: skip
        loop = DimeLoop(group, StackedSeeds(group, cfg, device), cfg, Schedule.of(cfg, budget),
                        device, progress=progress, desc=desc)  # fmt: skip
        run_algorithm4(loop, stop_after)
        for i, result in zip(members, loop.results, strict=True):
            results[i] = result
    return results


def _align(seeds: list[SeedState], fresh: Callable[[int], SeedState]) -> None:
    """Roll seeds whose checkpoint is ahead of the others back to their previous one.

    A stack writes its seeds' checkpoints one after another, so a crash between two writes
    leaves some seeds a checkpoint ahead. Trained apart, a seed's numbers would differ in
    the last bits from those it gets in the stack (other batch shapes), so the run would no
    longer resume exactly; with the checkpoint each seed kept before its last
    (``state.pt.prev``), the stack resumes together from the common step. Seeds that were
    not trained together (no previous checkpoint at that step) keep their own groups. A
    seed whose first checkpoint is the only one, beside seeds with none, starts afresh
    (``fresh(i)``, after its checkpoint is set aside and its rows dropped).
    """
    lowest = min(s.step for s in seeds)
    for i, s in enumerate(seeds):
        if s.step > lowest:
            previous = s.run.load_checkpoint(previous=True)
            if previous is not None and previous["step"] == lowest:
                s.load(previous)
            elif previous is None and lowest == 0:
                path = s.run.checkpoint_path
                os.replace(path, path.with_name(path.name + ".ahead"))
                s.run.rewind()
                seeds[i] = fresh(i)
