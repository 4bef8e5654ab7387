"""Algorithm 4 for S seeds in one process: the loop of :func:`vslbook.srl.dime.train` over a
seed axis (:class:`~vslbook.srl.seed_axis.SeedStack`).

Each seed has its own run directory, environment, replay buffer, numpy generator (uniform
exploration, replay indices) and torch generator (policy noise), seeded as its single-seed
run seeds them, and its own evaluations and diagnostics; only the network updates are
batched. Per seed the numbers are those of a single-seed run up to float rounding (batched
matrix products round differently), which the tests check update by update.

Checkpoints. All seeds are checkpointed at the same environment step (every
``checkpoint_every`` steps, and when ``stop_after`` stops the run), each into its own run
directory in the single-seed format, plus the actions of each seed's unfinished episode:
on resume the environment is reset with that episode's seed and the actions are replayed
(the simulators are deterministic), so no simulator state is pickled and an episode may be
cut anywhere. A seed whose losses or parameters stop being finite is marked FAILED and
leaves the stack; the others go on. Configurations with a target network (an ablation)
have no seed axis: their seeds are trained one after the other by the single-seed loop.
"""

from __future__ import annotations

import os
import time
from collections.abc import Callable
from typing import Any

import numpy as np
import torch
from tqdm.auto import tqdm

from vslbook.budget import Budget
from vslbook.registry import config_from_record
from vslbook.results import DivergenceError, RunDir
from vslbook.rng_state import restore_rng_state, rng_state
from vslbook.seeding import seed_everything
from vslbook.srl import dime
from vslbook.srl.cuda_graphs import GraphedUpdates, graphs_wanted
from vslbook.srl.dime_config import DIMEConfig
from vslbook.srl.dime_updates import make_agent, resolve_device
from vslbook.srl.divergence import WATCHED, FiniteWatch
from vslbook.srl.replay import Batch, ReplayBuffer, replay_generator
from vslbook.srl.seed_axis import SeedStack

__all__ = ["train_seeds"]


class _Seed:
    """What one seed owns: its run directory, streams, environments, buffer and counters."""

    def __init__(self, run: RunDir, record: dict, cfg: DIMEConfig, budget: Budget, device) -> None:
        self.run, self.seed = run, int(record["seed"])
        env_id = record["env"]
        seed_everything(self.seed, deterministic_torch=False)  # as a single-seed run does
        self.rng = np.random.default_rng(self.seed)
        self.env, self.eval_env = dime.make_env(env_id), dime.make_env(env_id)
        obs_dim, act_dim = self.env.observation_space.shape[0], self.env.action_space.shape[0]
        v_min, v_max = cfg.v_min, cfg.v_max
        if cfg.critic == "distributional" and v_min is None:
            v_min, v_max = dime.default_value_range(env_id)
        self.v_range = (v_min, v_max)
        self.agent = make_agent(obs_dim, act_dim, cfg, v_min=v_min, v_max=v_max, device=device)
        self.generator = torch.Generator(device=device)
        self.generator.set_state(_global_rng(device))  # the global stream after the init
        total = budget.scale(cfg.total_steps)
        self.buffer = ReplayBuffer(min(cfg.buffer_size, total), obs_dim, act_dim, device)
        self.indices = replay_generator(
            cfg.replay_sampler, device, dime._stream_seed(self.seed, dime.REPLAY_INDICES)
        )
        self.diag = dime._Means(device)
        self.step = self.episode = self.updates = self.evals = 0
        self.last_eval: dict[str, Any] = {}
        self.actions: list[np.ndarray] = []  # this episode's actions so far
        self.episode_return = 0.0
        self.load(run.load_checkpoint())

    def load(self, state: dict | None) -> None:
        """Continue from a checkpoint's ``state`` (None: from the start)."""
        device = self.generator.device
        if state is not None:
            self.agent.load_state_dict(state["agent"])
            if state["replay"] is not None:
                self.buffer.load_state_dict(state["replay"])
            self.diag.load_state_dict(state["diagnostics"])
            self.step, self.episode, self.updates, self.evals = (
                state[k] for k in ("step", "episode", "updates", "evals")
            )
            self.last_eval = state["last_eval"]
            restore_rng_state(state["rng"], self.rng)
            self.generator.set_state(_global_rng(device))
            if self.indices is not None:
                self.indices.set_state(state["replay_indices"])
            self.actions = [np.asarray(a, np.float32) for a in state.get("episode_actions", [])]
            self.episode_return = float(state.get("episode_return", 0.0))
        self.obs = self._replay()

    def _replay(self) -> np.ndarray:
        """Reset to this episode's start and replay its actions so far (after a resume)."""
        obs, _ = self.env.reset(seed=dime._stream_seed(self.seed, dime.TRAIN_RESETS, self.episode))
        for a in self.actions:
            obs, *_ = self.env.step(dime._to_env_action(a, self.env.action_space))
        return obs

    def checkpoint(self, stack: SeedStack, index: int, final: bool = False) -> None:
        device = self.generator.device
        torch_state = _global_rng(device)
        _set_global_rng(device, self.generator.get_state())  # the single-seed format
        try:
            rng = rng_state(self.rng)
        finally:
            _set_global_rng(device, torch_state)
        self.run.save_checkpoint(
            {
                "agent": stack.agent_state(index),
                "replay": None if final else self.buffer.state_dict(),
                "diagnostics": self.diag.state_dict(),
                "step": self.step,
                "episode": self.episode,
                "updates": self.updates,
                "evals": self.evals,
                "last_eval": self.last_eval,
                "rng": rng,
                "replay_indices": None if self.indices is None else self.indices.get_state(),
                "episode_actions": [a.tolist() for a in self.actions],
                "episode_return": self.episode_return,
            },
            keep_previous=True,  # the seeds write one after another: see _align
        )


def _global_rng(device: torch.device) -> torch.Tensor:
    """The state of torch's global stream that a single-seed run on ``device`` draws its
    policy noise from (the CPU generator, or the device's default CUDA generator)."""
    if device.type == "cuda":
        return torch.cuda.get_rng_state(device)
    return torch.get_rng_state()


def _set_global_rng(device: torch.device, state: torch.Tensor) -> None:
    if device.type == "cuda":
        torch.cuda.set_rng_state(state, device)
    else:
        torch.set_rng_state(state)


def train_seeds(
    runs: list[RunDir],
    records: list[dict],
    budget: Budget,
    *,
    progress: bool = True,
    stop_after: int | None = None,
    config_cls: type[DIMEConfig] = DIMEConfig,
) -> list[dict | None]:
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
                out.append(dime.train(run, rec, budget, progress=progress,
                                      stop_after=stop_after, config_cls=config_cls))  # fmt: skip
            except DivergenceError as err:
                run.mark_failed(err)
                out.append(err)
        return out
    if cfg.num_threads:
        torch.set_num_threads(cfg.num_threads)
    device = resolve_device(cfg.device)
    seeds = [_Seed(run, rec, cfg, budget, device) for run, rec in zip(runs, records, strict=True)]
    _align(seeds, lambda i: _Seed(runs[i], records[i], cfg, budget, device))
    groups: dict[int, list[int]] = {}  # checkpoints at different steps: one group per step
    for i, s in enumerate(seeds):
        groups.setdefault(s.step, []).append(i)
    results: list[Any] = [None] * len(seeds)
    for _, members in sorted(groups.items()):
        out = _train_group([seeds[i] for i in members], records[0], cfg, budget, device,
                           progress=progress, stop_after=stop_after)  # fmt: skip
        for i, result in zip(members, out, strict=True):
            results[i] = result
    return results


def _align(seeds: list[_Seed], fresh: Callable[[int], _Seed]) -> None:
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


def _train_group(
    seeds: list[_Seed], record: dict, cfg: DIMEConfig, budget: Budget, device: torch.device, *,
    progress: bool, stop_after: int | None,
) -> list[Any]:  # fmt: skip
    """Algorithm 4 for ``seeds``, all at one environment step, updated as one stack."""
    total_steps = budget.scale(cfg.total_steps)
    learning_starts = min(cfg.learning_starts, total_steps)
    eval_every = dime._scaled(budget, cfg.eval_every)
    checkpoint_every = dime._scaled(budget, cfg.checkpoint_every)
    eval_episodes = cfg.eval_episodes or budget.eval_episodes
    step = seeds[0].step
    results: list[Any] = [None] * len(seeds)
    live = list(range(len(seeds)))  # indices of the seeds still training
    stack = SeedStack([s.agent for s in seeds])
    act_dim = seeds[0].env.action_space.shape[0]
    env_id = record["env"]
    bar = tqdm(total=total_steps, initial=step, disable=not progress,
               desc=f"{record.get('algo', 'dime')} {env_id} seeds "
                    f"{','.join(str(s.seed) for s in seeds)}")  # fmt: skip
    clock, steps_at_clock = time.perf_counter(), step
    updates_at_clock = seeds[0].updates
    next_checkpoint = (step // checkpoint_every + 1) * checkpoint_every
    steps_this_call = 0

    watch = FiniteWatch(WATCHED, device, seeds=len(live))  # positions in `live`
    use_graphs = graphs_wanted(cfg, device)
    graphs: GraphedUpdates | None = None  # the stack's graphs (captured again after a drop)
    eval_graphs = {id(s): GraphedUpdates(s.agent) for s in seeds} if use_graphs else {}

    def graphed() -> GraphedUpdates | None:
        nonlocal graphs
        if use_graphs and (graphs is None or graphs.learner is not stack):
            graphs = GraphedUpdates(stack)
        return graphs

    def drop(errors: dict[int, DivergenceError]) -> None:
        """Mark the seeds at these positions in ``live`` FAILED and stack the others again."""
        nonlocal stack
        if not errors:
            return
        for pos, err in errors.items():
            seeds[live[pos]].run.mark_failed(err)
            results[live[pos]] = err
        kept = [pos for pos in range(len(live)) if pos not in errors]
        states = {live[pos]: stack.agent_state(pos) for pos in kept}
        for i, state in states.items():
            seeds[i].agent.load_state_dict(state)
        live[:] = list(states)
        watch.keep(kept)
        if live:
            stack = SeedStack([seeds[i].agent for i in live])

    while step < total_steps and live:
        own = [seeds[i] for i in live]
        if step < learning_starts:
            actions = [s.rng.uniform(-1.0, 1.0, size=act_dim).astype(np.float32) for s in own]
        else:
            obs = torch.as_tensor(np.stack([s.obs for s in own]), dtype=torch.float32,
                                  device=device)  # fmt: skip
            noise = stack.noise([s.generator for s in own], 1)
            g = graphed()
            actions = stack.act(obs, noise) if g is None else g.act(obs, noise)
            actions = list(actions.cpu().numpy())  # the env step's host sync
            bad = [pos for pos, a in enumerate(actions) if not np.isfinite(a).all()]
            if bad:  # a diverged seed shows here first: name its update if the watch saw it
                errors = watch.failures()
                for pos in bad:
                    a = actions[pos]
                    errors.setdefault(
                        pos, DivergenceError(step + 1, "action", float(a[~np.isfinite(a)][0]))
                    )
                actions = [a for pos, a in enumerate(actions) if pos not in errors]
                drop(errors)
                own = [seeds[i] for i in live]
                if not live:
                    break
        ended: dict[int, bool] = {}  # seed index -> its episode ended at this step
        for i, s, a in zip(live, own, actions, strict=True):
            next_obs, reward, terminated, truncated, _ = s.env.step(
                dime._to_env_action(a, s.env.action_space)
            )
            s.buffer.add(s.obs, a, reward, next_obs, terminated)
            s.obs, s.episode_return = next_obs, s.episode_return + float(reward)
            s.actions.append(np.asarray(a))
            s.step += 1
            ended[i] = terminated or truncated
        step += 1
        steps_this_call += 1

        if step >= learning_starts:
            for _ in range(cfg.utd):
                batches = [
                    s.buffer.sample(cfg.batch_size, s.rng if s.indices is None else s.indices)
                    for s in own
                ]
                batch = Batch(*[torch.stack(x) for x in zip(*batches, strict=True)])
                noise = stack.noise([s.generator for s in own], cfg.batch_size)
                g = graphed()
                critic_stats = (stack.critic_update(batch, noise) if g is None
                                else g.critic_update(batch, noise))  # fmt: skip
                for s in own:
                    s.updates += 1
                watch.add(step, critic_loss=critic_stats.loss, q_mean=critic_stats.value)
                for k, s in enumerate(own):
                    s.diag.add("critic_loss", critic_stats.loss[k])
                    s.diag.add("q_mean", critic_stats.value[k])
                if own[0].updates % cfg.policy_delay == 0:
                    noise = stack.noise([s.generator for s in own], cfg.batch_size)
                    if g is None:
                        actor_stats = stack.actor_update(batch.obs, noise)
                        alpha_loss = stack.alpha_update(actor_stats.running_cost)
                    else:
                        actor_stats, alpha_loss = g.actor_alpha_update(batch.obs, noise)
                    watch.add(step, actor_loss=actor_stats.loss, entropy_bound=actor_stats.value,
                              alpha_loss=alpha_loss)  # fmt: skip
                    for k, s in enumerate(own):
                        s.diag.add("actor_loss", actor_stats.loss[k])
                        s.diag.add("entropy_bound", actor_stats.value[k])
                        s.diag.add("running_cost", actor_stats.running_cost[k].mean())

        stopping = stop_after is not None and steps_this_call >= stop_after
        checkpointing = step < total_steps and (step >= next_checkpoint or stopping)
        evaluating = step % eval_every == 0 or step == total_steps
        if any(ended.values()) or checkpointing or evaluating or step == total_steps:
            drop(watch.failures())  # before anything is evaluated or saved
            own = [seeds[i] for i in live]
        if evaluating:
            errors = {}
            for k, s in enumerate(own):
                s.agent.load_state_dict(stack.agent_state(k))  # its policy, as one module
                try:
                    dime._require_finite_parameters(step, s.agent)
                except DivergenceError as err:
                    errors[k] = err
            drop(errors)
            own = [seeds[i] for i in live]
            now = time.perf_counter()
            elapsed = max(now - clock, 1e-9)
            for s in own:
                ret, success = dime.evaluate(
                    s.agent.policy, s.eval_env, seed=s.seed, index=s.evals,
                    episodes=eval_episodes, device=device, graphs=eval_graphs.get(id(s)),
                )  # fmt: skip
                s.evals += 1
                row = dime.eval_row(
                    s.agent, s.diag, ret, success, updates=s.updates, episodes=s.episode,
                    updates_per_s=(s.updates - updates_at_clock) / elapsed,
                    steps_per_s=(step - steps_at_clock) / elapsed,
                )  # fmt: skip
                s.run.log(step, **row)
                s.last_eval = {"eval_return": ret, "eval_success": success}
            clock, steps_at_clock = time.perf_counter(), step
            updates_at_clock = seeds[live[0]].updates if live else 0
        bar.update(1)

        for i in live:
            s = seeds[i]
            if ended[i]:
                s.diag.add("train_return", s.episode_return)
                s.episode += 1
                s.actions, s.episode_return = [], 0.0
                s.obs, _ = s.env.reset(
                    seed=dime._stream_seed(s.seed, dime.TRAIN_RESETS, s.episode)
                )
        if checkpointing:
            for k, i in enumerate(live):
                seeds[i].checkpoint(stack, k)
            next_checkpoint = (step // checkpoint_every + 1) * checkpoint_every
        if stopping and step < total_steps:
            bar.close()
            return results
    bar.close()
    for k, i in enumerate(live):
        s = seeds[i]
        s.checkpoint(stack, k, final=True)
        results[i] = {
            "env_steps": total_steps, "critic_updates": s.updates, "episodes": s.episode,
            **s.last_eval, "v_min": s.v_range[0], "v_max": s.v_range[1],
        }  # fmt: skip
    return results
