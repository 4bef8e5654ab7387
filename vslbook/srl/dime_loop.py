"""Algorithm 4 (DIME), the loop: collect, update, evaluate; for one seed or a seed axis.

Read :func:`run_algorithm4` next to Algorithm 4. Per environment step t:

    l. 3-5   :meth:`DimeLoop.collect`: a_t ~ π_θ(·|s_t) through the whole denoising chain
             (uniform random actions for the first ``learning_starts`` steps),
             s_{t+1} ~ p(·|s_t, a_t), D ← D ∪ {transition}
    l. 7-10  :meth:`DimeLoop.update`: ``utd`` critic updates ϕ ← ϕ - λ_ϕ ∇J_Q (Eq. 5.24 /
             distributional Eq. 5.21); after every ``policy_delay``-th one actor step on
             Eq. 5.27 and one temperature step on Eq. 5.28
    then     :meth:`DimeLoop.evaluate` every ``eval_every`` steps, :meth:`DimeLoop.end_episodes`,
             :meth:`DimeLoop.checkpoint`

(Algorithm 4 writes the same schedule as one loop over critic updates k that collects a
transition when k hits the UTD ratio.)

The same loop trains one seed (:func:`train`, the :class:`OneSeed` learner: the update
functions of :mod:`vslbook.srl.dime_updates` on one :class:`~vslbook.srl.dime_updates.Agent`)
and several seeds at once (:mod:`vslbook.srl.dime_seeds`, a learner over a
:class:`~vslbook.srl.seed_axis.SeedStack`): a :class:`Learner` takes and returns every
tensor with a leading seed axis, and each seed keeps its own
:class:`~vslbook.srl.dime_state.SeedState` (environments, buffer, streams, counters).

Episodes and resume. Time-limit truncations bootstrap, terminations do not. A single seed is
checkpointed at episode boundaries only, the seed axis at any step (the cut episode's actions
are replayed on resume); a run resumed from a checkpoint logs exactly the numbers an
uninterrupted run logs on CPU (all metrics except the wall-clock rates
``critic_updates_per_s`` and ``env_steps_per_s``).

Divergence. Every update's losses, the critic's mean Q and the entropy bound are watched for
finiteness on the device (:class:`vslbook.srl.divergence.FiniteWatch`, no host sync per
update) and checked at every evaluation, episode end and checkpoint, the parameters and log α
at every evaluation; the first non-finite one is a :class:`vslbook.results.DivergenceError`
naming the step of the update that produced it and the quantity. A single seed raises it
(:func:`vslbook.training.run` marks the run FAILED instead of DONE); on the seed axis the
seed is marked FAILED and leaves the stack, and the others go on.
"""

from __future__ import annotations

import time
from typing import Any, Protocol

import numpy as np
import torch
from torch import Tensor

from vslbook.budget import Budget
from vslbook.progress import progress_bar
from vslbook.registry import config_from_record
from vslbook.results import DivergenceError, RunDir
from vslbook.srl.cuda_graphs import GraphedUpdates, graphs_wanted
from vslbook.srl.dime_config import DIMEConfig
from vslbook.srl.dime_env import act, evaluate
from vslbook.srl.dime_state import Schedule, SeedState, eval_row, require_finite_parameters
from vslbook.srl.dime_updates import (
    Agent,
    UpdateStats,
    actor_update,
    alpha_update,
    critic_update,
    policy_noise,
    resolve_device,
)
from vslbook.srl.divergence import WATCHED, FiniteWatch
from vslbook.srl.replay import Batch

__all__ = ["DimeLoop", "Learner", "OneSeed", "run_algorithm4", "train"]


class Learner(Protocol):
    """The agents of the seeds a loop trains, updated together (l. 3 and 7-10).

    Tensors carry a leading seed axis, one entry per live seed in order. ``together``: the
    seeds train as one stack (checkpoints may cut an episode and keep the previous one; a
    diverged seed leaves, the others go on) rather than one seed alone (checkpoints at
    episode ends; a divergence ends the run).
    """

    together: bool

    def act(self, seeds: list[SeedState]) -> list[np.ndarray]:
        """l. 3: a ~ π_θ(·|s) for each seed's observation, in [-1, 1]."""

    def batch(self, batches: list[Batch]) -> Batch:
        """The seeds' minibatches as the updates take them."""

    def critic_update(self, seeds: list[SeedState], batch: Batch) -> UpdateStats:
        """l. 7: one critic step per seed (Eq. 5.21 / 5.24)."""

    def actor_alpha_update(self, seeds: list[SeedState], obs: Tensor) -> tuple[UpdateStats, Tensor]:
        """l. 9-10: one actor step (Eq. 5.27) and one temperature step (Eq. 5.28) per seed."""

    def agent(self, k: int) -> Agent:
        """The agent of the seed at position ``k``, holding the learner's current state."""

    def agent_state(self, k: int) -> dict[str, Any]:
        """That agent's :meth:`~vslbook.srl.dime_updates.Agent.state_dict`."""

    def eval_graphs(self, k: int) -> GraphedUpdates | None:
        """CUDA graphs for that seed's evaluation, or None."""

    def keep(self, positions: list[int]) -> None:
        """Go on with the seeds at ``positions`` only (the others diverged)."""


def _seed_axis(stats: UpdateStats) -> UpdateStats:
    """One seed's update statistics with a seed axis of length 1 (views, no copies)."""
    return UpdateStats(*(None if x is None else x.unsqueeze(0) for x in stats))


class OneSeed:
    """Algorithm 4's updates for one seed: :func:`~vslbook.srl.dime_updates.critic_update`,
    :func:`~vslbook.srl.dime_updates.actor_update` and
    :func:`~vslbook.srl.dime_updates.alpha_update` on its agent, drawing the policy noise from
    torch's global stream; eager, compiled (``compile``) or replayed as CUDA graphs."""

    together = False

    def __init__(self, agent: Agent, cfg: DIMEConfig, device: torch.device) -> None:
        self._agent, self.cfg, self.device = agent, cfg, device
        self.graphs = GraphedUpdates(agent) if graphs_wanted(cfg, device) else None
        self.critic_step, self.actor_step = critic_update, actor_update
        if cfg.compile and self.graphs is None:
            self.critic_step = torch.compile(critic_update)
            self.actor_step = torch.compile(actor_update)

    def act(self, seeds: list[SeedState]) -> list[np.ndarray]:
        return [act(self._agent.policy, seeds[0].obs, self.device, graphs=self.graphs)]

    def batch(self, batches: list[Batch]) -> Batch:
        (batch,) = batches
        return batch

    def critic_update(self, seeds: list[SeedState], batch: Batch) -> UpdateStats:
        if self.graphs is None:
            return _seed_axis(self.critic_step(self._agent, batch))
        # the draws the eager step would make, from the same (global) stream
        noise = policy_noise(self._agent.policy, self.cfg.batch_size, None, self.device)
        return _seed_axis(self.graphs.critic_update(batch, noise))

    def actor_alpha_update(self, seeds: list[SeedState], obs: Tensor) -> tuple[UpdateStats, Tensor]:
        if self.graphs is None:
            stats = self.actor_step(self._agent, obs)
            alpha_loss = alpha_update(self._agent, stats.running_cost)
        else:
            noise = policy_noise(self._agent.policy, self.cfg.batch_size, None, self.device)
            stats, alpha_loss = self.graphs.actor_alpha_update(obs, noise)
        return _seed_axis(stats), alpha_loss.unsqueeze(0)

    def agent(self, k: int) -> Agent:
        return self._agent

    def agent_state(self, k: int) -> dict[str, Any]:
        return self._agent.state_dict()

    def eval_graphs(self, k: int) -> GraphedUpdates | None:
        return self.graphs

    def keep(self, positions: list[int]) -> None:
        raise AssertionError("a single seed's divergence ends its run")  # see DimeLoop.fail


class DimeLoop:
    """Algorithm 4's state for the seeds trained together, and its steps as methods.

    Args:
        seeds: each seed's :class:`SeedState`, all at the same environment step.
        learner: their agents (:class:`OneSeed` for one, the seed axis for several).
        schedule: the run's counts at its budget.
        desc: the progress bar's label.
    """

    def __init__(
        self, seeds: list[SeedState], learner: Learner, cfg: DIMEConfig, schedule: Schedule,
        device: torch.device, *, progress: bool = True, desc: str = "dime",
    ) -> None:  # fmt: skip
        self.seeds, self.learner, self.cfg, self.schedule = seeds, learner, cfg, schedule
        self.device = device
        self.live = list(range(len(seeds)))  # indices of the seeds still training
        self.results: list[Any] = [None] * len(seeds)  # summary or DivergenceError per seed
        self.step = seeds[0].step
        self.watch = FiniteWatch(WATCHED, device, seeds=len(seeds))  # positions in `live`
        self.next_checkpoint = schedule.next_checkpoint(self.step)
        self.bar = progress_bar(total=schedule.total_steps, initial=self.step,
                                disable=not progress, desc=desc, unit="steps")  # fmt: skip
        self._clock = (time.perf_counter(), self.step, seeds[0].updates)

    @property
    def own(self) -> list[SeedState]:
        """The live seeds, in order (their positions on the learner's seed axis)."""
        return [self.seeds[i] for i in self.live]

    @property
    def finished(self) -> bool:
        return self.step >= self.schedule.total_steps or not self.live

    # ------------------------------------------------------------------ Algorithm 4
    def collect(self) -> dict[int, bool]:
        """l. 3-5 for every live seed: a ~ π_θ(·|s) (uniform for the first
        ``learning_starts`` steps), s' ~ p(·|s, a), D ← D ∪ {(s, a, r, s', terminated)}.
        Returns, per live seed's index in ``seeds``, whether its episode ended."""
        if self.step < self.schedule.learning_starts:
            actions = [s.exploration_action() for s in self.own]
        else:
            actions = self.learner.act(self.own)  # the step's one host sync
            bad = [pos for pos, a in enumerate(actions) if not np.isfinite(a).all()]
            if bad:  # a diverged update shows here first: name it if the watch saw it
                errors = self.watch.failures()
                for pos in bad:
                    a = actions[pos]
                    errors.setdefault(
                        pos, DivergenceError(self.step + 1, "action", float(a[~np.isfinite(a)][0]))
                    )
                actions = [a for pos, a in enumerate(actions) if pos not in errors]
                self.fail(errors)
        ended = {i: self.seeds[i].step_env(a) for i, a in zip(self.live, actions, strict=True)}
        self.step += 1
        self.bar.update(1)
        return ended

    def update(self) -> None:
        """l. 7-10: ``utd`` critic updates (Eq. 5.21 / 5.24); after every
        ``policy_delay``-th, one actor step (Eq. 5.27) and one α step (Eq. 5.28)."""
        try:
            for _ in range(self.cfg.utd):
                own = self.own
                batch = self.learner.batch([s.sample(self.cfg.batch_size) for s in own])
                critic = self.learner.critic_update(own, batch)  # l. 7
                self.watch.add(self.step, critic_loss=critic.loss, q_mean=critic.value)
                for k, s in enumerate(own):
                    s.updates += 1
                    s.diag.add("critic_loss", critic.loss[k])
                    s.diag.add("q_mean", critic.value[k])
                if own[0].updates % self.cfg.policy_delay == 0:  # l. 8
                    actor, alpha_loss = self.learner.actor_alpha_update(own, batch.obs)  # l. 9-10
                    self.watch.add(self.step, actor_loss=actor.loss,
                                   entropy_bound=actor.value, alpha_loss=alpha_loss)  # fmt: skip
                    for k, s in enumerate(own):
                        s.diag.add("actor_loss", actor.loss[k])
                        s.diag.add("entropy_bound", actor.value[k])
                        s.diag.add("running_cost", actor.running_cost[k].mean())
        except Exception as err:  # an update failing on an earlier update's non-finite
            if not isinstance(err, DivergenceError):  # output says so; else its own error
                self.check_finite()
            raise

    def evaluate(self) -> None:
        """Evaluate every live seed's policy (Section 5.5's learning curves) and log a row
        of ``metrics.jsonl`` per seed (:func:`~vslbook.srl.dime_state.eval_row`)."""
        agents = [self.learner.agent(k) for k in range(len(self.live))]
        errors = {}
        for k, agent in enumerate(agents):
            try:
                require_finite_parameters(self.step, agent)
            except DivergenceError as err:
                errors[k] = err
        agents = [a for k, a in enumerate(agents) if k not in errors]
        self.fail(errors)
        now, (clock, steps_at_clock, updates_at_clock) = time.perf_counter(), self._clock
        elapsed = max(now - clock, 1e-9)
        for k, (s, agent) in enumerate(zip(self.own, agents, strict=True)):
            ret, success = evaluate(
                agent.policy, s.eval_env, seed=s.seed, index=s.evals,
                episodes=self.schedule.eval_episodes, device=self.device,
                graphs=self.learner.eval_graphs(k),
            )  # fmt: skip
            s.evals += 1
            row = eval_row(
                agent, s.diag, ret, success, updates=s.updates, episodes=s.episode,
                updates_per_s=(s.updates - updates_at_clock) / elapsed,
                steps_per_s=(self.step - steps_at_clock) / elapsed,
            )  # fmt: skip
            s.run.log(self.step, **row)
            s.last_eval = {"eval_return": ret, "eval_success": success}
            if k == 0:
                self.bar.set_postfix(ret=f"{ret:.1f}", alpha=f"{row['alpha']:.3g}")
        updates = self.own[0].updates if self.live else 0
        self._clock = (time.perf_counter(), self.step, updates)

    def end_episodes(self, ended: dict[int, bool]) -> None:
        """Reset the live seeds' environments whose episodes ended (:meth:`collect`)."""
        for i in self.live:
            if ended[i]:
                self.seeds[i].end_episode()

    def checkpoint(self, final: bool = False) -> None:
        """Save every live seed into its own run directory (see :mod:`vslbook.srl.dime_state`);
        ``final``: the finished run's networks, without the replay buffer."""
        for k, s in enumerate(self.own):
            s.checkpoint(self.learner.agent_state(k), final=final,
                         keep_previous=self.learner.together)  # fmt: skip
        self.next_checkpoint = self.schedule.next_checkpoint(self.step)

    def finish(self) -> None:
        """The end of the run: the final checkpoint and each live seed's summary."""
        self.bar.close()
        self.check_finite()
        self.checkpoint(final=True)
        for i in self.live:
            self.results[i] = self.seeds[i].summary(self.schedule.total_steps)

    # ------------------------------------------------------------------ divergence
    def check_finite(self) -> None:
        """Read the watch (one host sync): seeds whose updates went non-finite fail."""
        if self.live:
            self.fail(self.watch.failures())

    def fail(self, errors: dict[int, DivergenceError]) -> None:
        """The seeds at these positions diverged: alone, the run raises the error (the caller
        marks it FAILED); on the seed axis, each is marked FAILED and leaves the stack."""
        if not errors:
            return
        if not self.learner.together:
            self.bar.close()
            raise errors[min(errors)]
        for pos, err in errors.items():
            self.seeds[self.live[pos]].run.mark_failed(err)
            self.results[self.live[pos]] = err
        kept = [pos for pos in range(len(self.live)) if pos not in errors]
        self.learner.keep(kept)
        self.live = [self.live[pos] for pos in kept]
        self.watch.keep(kept)


def run_algorithm4(loop: DimeLoop, stop_after: int | None = None) -> bool:
    """Algorithm 4 from ``loop``'s step to the end of the run; True when it got there.

    ``stop_after`` counts environment steps of this call: the loop then stops, checkpointed
    (a single seed at the first episode end after that many steps).
    """
    steps = 0
    while not loop.finished:
        ended = loop.collect()  # l. 3-5
        if not loop.live:
            break
        if loop.step >= loop.schedule.learning_starts:
            loop.update()  # l. 7-10, utd times
        steps += 1
        boundary = loop.learner.together or all(ended.values())  # a checkpoint may be written
        stopping = boundary and stop_after is not None and steps >= stop_after
        checkpointing = boundary and loop.step < loop.schedule.total_steps and (
            stopping or loop.step >= loop.next_checkpoint
            or any(s.run.checkpoint_due() for s in loop.own)
        )  # fmt: skip
        evaluating = loop.schedule.evaluating(loop.step)
        if any(ended.values()) or checkpointing or evaluating:
            loop.check_finite()  # before anything is evaluated or saved
        if evaluating:
            loop.evaluate()
        loop.end_episodes(ended)
        if checkpointing:
            loop.checkpoint()
        if stopping and not loop.finished:
            loop.bar.close()
            return False
    loop.finish()
    return True


def train(
    run: RunDir,
    config: dict,
    budget: Budget,
    *,
    progress: bool = True,
    stop_after: int | None = None,
    config_cls: type[DIMEConfig] = DIMEConfig,
) -> dict | None:
    """Train DIME (or a variant) in ``run``, resuming from its checkpoint if there is one.

    ``config`` holds ``env``, ``seed`` and the fields of ``config_cls``. ``stop_after``
    counts environment steps of this call: the run stops (checkpointed, not finished) at the
    first episode end after that many steps. Returns a summary when finished, None when
    stopped early; raises :class:`~vslbook.results.DivergenceError` when it diverges.
    """
    cfg = config_from_record(config_cls, config)
    if cfg.num_threads:
        torch.set_num_threads(cfg.num_threads)
    device = resolve_device(cfg.device)
    seed = SeedState.create(run, config, cfg, budget, device)  # θ, ϕ, α, D; or resumed
    desc = f"{config.get('algo', 'dime')} {config['env']} s{seed.seed}"
    loop = DimeLoop([seed], OneSeed(seed.agent, cfg, device), cfg, Schedule.of(cfg, budget),
                    device, progress=progress, desc=desc)  # fmt: skip
    run_algorithm4(loop, stop_after)
    return loop.results[0]
