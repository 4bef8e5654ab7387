"""DIME update throughput at humanoid-run sizes (obs 67, act 21, batch 256, UTD schedule).

Times the real update functions of :mod:`vslbook.srl.dime` on random replay data: a loop of
critic updates with an actor and temperature update after every ``policy_delay``-th one,
exactly the schedule of Algorithm 4 without the environment. Reports critic and actor
updates per second (the actor rate is a third of the critic rate by construction) for

    paper   16 diffusion steps, 2048-wide critic (Table C.2)
    16x256  16 diffusion steps, 256-wide critic
    4x256   4 diffusion steps, 256-wide critic

next to the official JAX implementation's numbers on a 2-core AMD EPYC CPU (float32, from
the project's algorithm notes). Warm-up updates are excluded from the timing.

With ``--seeds S`` a second table times the same schedule for S seeds in one process
(:class:`vslbook.srl.seed_axis.SeedStack`: every tensor with a seed axis) and for one seed
through the same path: updates per second per seed and in aggregate, and the wall time of S
seeds' update against one seed's (the target of 1.5x is a CPU with 2 cores at 4x256).

With ``--compile`` and ``--graphs`` (CUDA only) each configuration is also timed with the
updates compiled by ``torch.compile`` and replayed as CUDA graphs
(:class:`vslbook.srl.cuda_graphs.GraphedUpdates`, the training loop's default on a GPU),
with the speed-up over eager; with ``--seeds`` too, the seed axis is timed in both modes.

With ``--run-set BUDGET`` it instead trains the Chapter 5 notebook's live run sets
(:func:`vslbook.experiments.dime_runs.chapter5_run_sets`: cheetah-run, the Pendulum
ablations, the point-mass α panels) at that budget from scratch in ``--root`` (default: a
new temporary folder) and prints the wall time of each set and of all of them, i.e. what
the notebook's training costs at that budget (the seeds of a variant train together on the
seed axis where the algorithm can).

    python benchmarks/dime_throughput.py --device cpu --steps 30 --seconds 60
    python benchmarks/dime_throughput.py --configs 4x256 --seeds 3
    python benchmarks/dime_throughput.py --device cuda --graphs --seeds 10
    python benchmarks/dime_throughput.py --run-set reduced
    python benchmarks/dime_throughput.py --run-set reduced --sets ablations pointmass
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import tempfile
import time
from pathlib import Path

import numpy as np
import torch

from vslbook.srl.cuda_graphs import GraphedUpdates
from vslbook.srl.dime import (
    DIMEConfig,
    actor_update,
    alpha_update,
    critic_update,
    make_agent,
    resolve_device,
)
from vslbook.srl.dime_updates import policy_noise
from vslbook.srl.replay import Batch, ReplayBuffer
from vslbook.srl.seed_axis import SeedStack

OBS_DIM, ACT_DIM, BATCH = 67, 21, 256
#: name -> (diffusion steps, critic width, reference critic/s, reference actor/s)
CONFIGS = {
    "paper": (16, 2048, 2.6, 0.9),
    "16x256": (16, 256, 10.5, 3.5),
    "4x256": (4, 256, 16.5, 5.5),
}


def physical_cores() -> int:
    """Physical CPU cores available to this process (falls back to logical CPUs)."""
    try:
        pairs = set()
        for cpu in os.sched_getaffinity(0):
            base = f"/sys/devices/system/cpu/cpu{cpu}/topology"
            with open(f"{base}/core_id") as a, open(f"{base}/physical_package_id") as b:
                pairs.add((a.read().strip(), b.read().strip()))
        return max(len(pairs), 1)
    except (OSError, AttributeError):
        return os.cpu_count() or 1


def measure(
    n_steps: int,
    width: int,
    *,
    device: torch.device,
    updates: int,
    seconds: float,
    compile_updates: bool = False,
    graphs: bool = False,
    seed: int = 0,
) -> dict[str, float]:
    """Critic and actor updates per second of the UTD/policy-delay schedule (eager, compiled
    with ``torch.compile``, or replayed as CUDA graphs)."""
    cfg = DIMEConfig(
        n_diffusion_steps=n_steps, critic_hidden=width, v_min=-200.0, v_max=200.0,
        compile=compile_updates,
    )  # fmt: skip
    torch.manual_seed(seed)
    rng = np.random.default_rng(seed)
    agent = make_agent(OBS_DIM, ACT_DIM, cfg, v_min=cfg.v_min, v_max=cfg.v_max, device=device)
    buffer = _filled_buffer(device, rng)
    # replay indices on the device where there is one (no host-to-device copy per batch)
    indices = rng if device.type == "cpu" else torch.Generator(device=device).manual_seed(seed)
    critic_step, actor_step = critic_update, actor_update
    if compile_updates:
        critic_step, actor_step = torch.compile(critic_update), torch.compile(actor_update)
    alpha_step = alpha_update
    if graphs:  # the training loop's graphed path: noise drawn outside, steps replayed
        replay = GraphedUpdates(agent)

        def critic_step(agent, batch):
            return replay.critic_update(batch, policy_noise(agent.policy, BATCH, None, device))

        def actor_step(agent, obs):
            stats, _ = replay.actor_alpha_update(obs, policy_noise(agent.policy, BATCH, None,
                                                                   device))  # fmt: skip
            return stats

        def alpha_step(agent, running_cost):
            return None  # taken inside the actor graph

    def sync() -> None:
        if device.type == "cuda":
            torch.cuda.synchronize(device)

    def schedule(k: int) -> tuple[int, float, float]:
        """k critic updates, actor + α after every policy_delay-th; returns time split."""
        n_actor, t_critic, t_actor = 0, 0.0, 0.0
        for i in range(1, k + 1):
            t0 = time.perf_counter()
            batch = buffer.sample(cfg.batch_size, indices)
            critic_step(agent, batch)
            sync()
            t1 = time.perf_counter()
            t_critic += t1 - t0
            if i % cfg.policy_delay == 0:
                stats = actor_step(agent, batch.obs)
                alpha_step(agent, stats.running_cost)
                sync()
                t_actor += time.perf_counter() - t1
                n_actor += 1
        return n_actor, t_critic, t_actor

    schedule(2 * cfg.policy_delay)  # warm-up: allocator, kernels, compilation
    n_critic, n_actor, t_critic, t_actor = 0, 0, 0.0, 0.0
    start = time.perf_counter()
    while n_critic < updates and time.perf_counter() - start < seconds:
        a, tc, ta = schedule(cfg.policy_delay)
        n_critic += cfg.policy_delay
        n_actor += a
        t_critic += tc
        t_actor += ta
    wall = time.perf_counter() - start
    return {
        "critic_per_s": n_critic / wall,
        "actor_per_s": n_actor / wall,
        "ms_per_critic_update": 1e3 * t_critic / n_critic,
        "ms_per_actor_update": 1e3 * t_actor / max(n_actor, 1),
        "critic_updates": n_critic,
    }


def _filled_buffer(device: torch.device, rng: np.random.Generator) -> ReplayBuffer:
    """10,000 random transitions (standard normal states, uniform actions, 1 % terminal)."""
    n = 10_000
    buffer = ReplayBuffer(n, OBS_DIM, ACT_DIM, device)
    state = {
        "obs": rng.standard_normal((n, OBS_DIM)), "action": rng.uniform(-1, 1, (n, ACT_DIM)),
        "reward": rng.normal(size=n), "next_obs": rng.standard_normal((n, OBS_DIM)),
        "terminated": (rng.random(n) < 0.01).astype(np.float64),
    }  # fmt: skip
    state = {k: torch.as_tensor(v, dtype=torch.float32) for k, v in state.items()}
    buffer.load_state_dict({**state, "capacity": n, "ptr": 0, "size": n})
    return buffer


def measure_seeds(
    n_steps: int, width: int, seeds: int, *, device: torch.device, updates: int, seconds: float,
    graphs: bool = False,
) -> dict[str, float]:
    """The schedule of :func:`measure` for ``seeds`` seeds updated as one (seed axis), eager
    or replayed as CUDA graphs."""
    cfg = DIMEConfig(n_diffusion_steps=n_steps, critic_hidden=width, v_min=-200.0, v_max=200.0)
    agents = []
    for s in range(seeds):
        torch.manual_seed(s)
        agents.append(make_agent(OBS_DIM, ACT_DIM, cfg, v_min=-200.0, v_max=200.0, device=device))
    stack = SeedStack(agents)
    rngs = [np.random.default_rng(s) for s in range(seeds)]
    buffers = [_filled_buffer(device, r) for r in rngs]
    gens = [torch.Generator(device=device).manual_seed(s) for s in range(seeds)]
    indices = [torch.Generator(device=device).manual_seed(100 + s) for s in range(seeds)]
    if device.type == "cpu":
        indices = rngs
    replay = GraphedUpdates(stack) if graphs else None

    def schedule(k: int) -> None:
        for i in range(1, k + 1):
            parts = [b.sample(cfg.batch_size, r) for b, r in zip(buffers, indices, strict=True)]
            batch = Batch(*[torch.stack(x) for x in zip(*parts, strict=True)])
            noise = stack.noise(gens, cfg.batch_size)
            if replay is None:
                stack.critic_update(batch, noise)
            else:
                replay.critic_update(batch, noise)
            if i % cfg.policy_delay == 0:
                noise = stack.noise(gens, cfg.batch_size)
                if replay is None:
                    stats = stack.actor_update(batch.obs, noise)
                    stack.alpha_update(stats.running_cost)
                else:
                    replay.actor_alpha_update(batch.obs, noise)
        if device.type == "cuda":
            torch.cuda.synchronize(device)

    schedule(2 * cfg.policy_delay)
    n, start = 0, time.perf_counter()
    while n < updates and time.perf_counter() - start < seconds:
        schedule(cfg.policy_delay)
        n += cfg.policy_delay
    wall = time.perf_counter() - start
    return {"critic_per_s_per_seed": n / wall, "critic_per_s": seeds * n / wall,
            "ms_per_update": 1e3 * wall / n}  # fmt: skip


def time_run_sets(budget_name: str, root: str | None, only: list[str] | None = None) -> None:
    """Train the Chapter 5 run sets at ``budget_name`` in ``root`` and print their wall times
    (``only``: these sets, by name)."""
    from vslbook.budget import get_budget
    from vslbook.experiments.dime_runs import chapter5_run_sets

    budget = get_budget(budget_name)
    sets = chapter5_run_sets(budget)
    unknown = sorted(set(only or ()) - set(sets))
    if unknown:
        raise SystemExit(f"unknown run set(s) {unknown}; the sets are {list(sets)}")
    base = Path(root) if root else Path(tempfile.mkdtemp(prefix="ch5-run-set-"))
    if (base / "runs").exists() and any((base / "runs").iterdir()):
        print(f"note: {base / 'runs'} already holds runs; finished ones are reused, not timed")
    print(f"Chapter 5 run sets at budget {budget.name!r} ({budget.seeds} seeds) in {base}")
    print(f"torch {torch.__version__}, {torch.get_num_threads()} threads")
    total = 0.0
    for name, run_set in sets.items():
        if only and name not in only:
            continue
        start = time.perf_counter()
        out = run_set.run(budget, base / "runs", base / "tables" / name, progress=False)
        wall = time.perf_counter() - start
        total += wall
        n_runs = sum(len(r) for r in out.runs.values())
        print(
            f"{name:10s} {run_set.env:30s} {len(run_set.variants)} variant(s) x "
            f"{run_set.seeds} seed(s) = {n_runs} runs, {wall / 60:6.1f} min",
            flush=True,
        )
        if out.unusable:
            print(f"{'':10s} not finished: {out.unusable}")
    print(f"{'all':10s} {total / 60:6.1f} min")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--device", default="auto", help="auto | cpu | cuda | cuda:N")
    parser.add_argument("--steps", type=int, default=30, help="timed critic updates per config")
    parser.add_argument(
        "--seconds", type=float, default=60.0, help="time cap per config (stops earlier)"
    )
    parser.add_argument("--configs", nargs="+", default=list(CONFIGS), choices=list(CONFIGS))
    parser.add_argument(
        "--threads", type=int, default=0, help="torch CPU threads (0: physical cores)"
    )
    parser.add_argument("--compile", action="store_true", help="also time torch.compile")
    parser.add_argument(
        "--graphs", action="store_true", help="also time CUDA-graph replay (CUDA devices only)"
    )
    parser.add_argument(
        "--tf32", action="store_true",
        help="let CUDA float32 matrix products use TF32 (a precision change; off in training)",
    )  # fmt: skip
    parser.add_argument(
        "--seeds", type=int, default=0, help="also time S seeds in one process (seed axis)"
    )
    parser.add_argument(
        "--run-set", metavar="BUDGET", default=None,
        help="time the Chapter 5 run sets at this budget instead (smoke | reduced | full)",
    )  # fmt: skip
    parser.add_argument("--root", default=None, help="folder for --run-set (default: a temp dir)")
    parser.add_argument(
        "--sets", nargs="+", default=None, metavar="NAME",
        help="with --run-set: only these sets (cheetah, ablations, pointmass)",
    )  # fmt: skip
    args = parser.parse_args()
    if args.run_set is not None:
        if args.threads:
            torch.set_num_threads(args.threads)
        time_run_sets(args.run_set, args.root, args.sets)
        return
    if args.steps < 1 or args.seconds <= 0:
        parser.error(f"need --steps >= 1 and --seconds > 0, got {args.steps}, {args.seconds}")

    device = resolve_device(args.device)
    torch.set_num_threads(args.threads or physical_cores())
    if (args.graphs or args.tf32) and device.type != "cuda":
        parser.error(f"--graphs and --tf32 need a CUDA device, got {device}")
    if args.tf32:
        torch.backends.cuda.matmul.allow_tf32 = True
        print("TF32 matrix products: float32 inputs rounded to 10-bit mantissas")
    print(
        f"device {device}"
        + (f" ({torch.cuda.get_device_name(device)})" if device.type == "cuda" else "")
        + f", torch {torch.__version__}, {torch.get_num_threads()} threads, "
        f"obs {OBS_DIM}, act {ACT_DIM}, batch {BATCH}"
    )
    modes = ["eager"] + (["compile"] if args.compile else []) + (["graphs"] if args.graphs else [])
    header = (
        f"{'config':8s} {'mode':8s} {'critic/s':>9s} {'actor/s':>8s} {'ms/critic':>10s} "
        f"{'ms/actor':>9s} {'x eager':>8s} | {'reference critic/s':>18s} {'actor/s':>8s}"
    )
    print(header)
    print("-" * len(header))
    for name in args.configs:
        n_steps, width, ref_critic, ref_actor = CONFIGS[name]
        eager = None
        for mode in modes:
            r = measure(
                n_steps, width, device=device, updates=args.steps, seconds=args.seconds,
                compile_updates=mode == "compile", graphs=mode == "graphs",
            )  # fmt: skip
            eager = eager or r["critic_per_s"]
            print(
                f"{name:8s} {mode:8s} {r['critic_per_s']:9.2f} {r['actor_per_s']:8.2f} "
                f"{r['ms_per_critic_update']:10.2f} {r['ms_per_actor_update']:9.2f} "
                f"{r['critic_per_s'] / eager:8.2f} | {ref_critic:18.1f} {ref_actor:8.1f}",
                flush=True,
            )
    print("reference: official JAX implementation, 2-core AMD EPYC CPU, float32")
    if args.seeds > 0:
        print(f"\nseed axis: 1 and {args.seeds} seeds in one process (critic updates)")
        head = (f"{'config':8s} {'mode':8s} {'seeds':>5s} {'per seed/s':>10s} "
                f"{'aggregate/s':>11s} {'ms/update':>9s} {'wall x 1 seed':>13s} "
                f"{'aggregate x 1 seed':>18s}")  # fmt: skip
        print(head)
        print("-" * len(head))
        for name in args.configs:
            n_steps, width = CONFIGS[name][:2]
            for mode in [m for m in modes if m != "compile"]:
                one = None
                for s in sorted({1, args.seeds}):
                    r = measure_seeds(n_steps, width, s, device=device, updates=args.steps,
                                      seconds=args.seconds, graphs=mode == "graphs")  # fmt: skip
                    one = one or r
                    print(
                        f"{name:8s} {mode:8s} {s:5d} {r['critic_per_s_per_seed']:10.2f} "
                        f"{r['critic_per_s']:11.2f} {r['ms_per_update']:9.2f} "
                        f"{r['ms_per_update'] / one['ms_per_update']:13.2f} "
                        f"{r['critic_per_s'] / one['critic_per_s']:18.2f}",
                        flush=True,
                    )
        print("'x 1 seed': against one seed through the same path and mode")
    _ = dataclasses  # keeps the import for readers extending the configs


if __name__ == "__main__":
    main()
