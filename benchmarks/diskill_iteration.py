"""One Di-SkilL iteration (Algorithm 2) split into physics, expert update, critic, context model
and the rest, at the thesis's sizes; and the throughput of seeds side by side.

For each task (and method: ``diskill``, ``bbrl``, ...) this builds the model of
:func:`vslbook.erl.diskill_config.diskill_config` (K, samples per expert, network widths,
5000 contexts from p(c), 100 epochs of each update, the networks' dtype), runs ``--warmup``
untimed iterations (numba's compilation, the worker pool's start) and then times
``--iterations`` iterations of :meth:`vslbook.erl.diskill.DiSkill.iterate`, split into

* physics: the episodes (``task.evaluate``, line 6), in ``--workers`` processes;
* expert: the trust-region update of the experts (Eq. 4.7, line 7);
* critic: the value critics' regression (line 7);
* context: the energy networks' PPO update (Eq. 4.8, line 8);
* rest: everything else (drawing contexts and θ, the responsibilities, bookkeeping).

"networks" is expert + critic + context, the part that runs serially while the episode
workers wait. ``--clock cpu`` times this process's CPU time instead of the wall clock: with
``--workers 1`` (episodes in this process) it is steadier on a machine shared with other
jobs; with more workers the physics runs elsewhere, so wall time is the only meaningful one.

The model starts where training spends its time: every expert's mean at the task's example
θ (:data:`vslbook.envs.robot.examples.EXAMPLES`) with standard deviation ``--std``, so that
the episodes run, as they do once training has found valid movements (``--state fresh``:
the initial model, whose table-tennis θ are mostly rejected without simulation).

``--side-by-side`` instead compares throughputs on two cores: two seeds at once with one
worker each against one seed with two workers (each in its own process, both started
together after their warm-up), and prints iterations per second of each and the ratio.
With physics p and networks n per iteration on one core, that ratio is at most
(p + 2n)/(p + n) = 1 + the networks' share, plus what two workers lose to uneven episodes
and messages: faster networks make side by side gain less.

    python benchmarks/diskill_iteration.py --tasks table-tennis-4d reacher5 --iterations 3
    python benchmarks/diskill_iteration.py --workers 2 --clock wall
    python benchmarks/diskill_iteration.py --tasks table-tennis-4d --side-by-side
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

PHASES = ("physics", "expert", "critic", "context", "rest")
NETWORKS = ("expert", "critic", "context")
TASKS = ("table-tennis-4d", "reacher5", "table-tennis-hard", "hopper-jump")
#: tiny sizes for a smoke run (the test suite): the loop's code at a fraction of the cost
SMOKE = {
    "samples_per_expert": 4, "env_contexts": 64, "epochs": 2, "critic_epochs": 2,
    "context_epochs": 2, "normaliser_contexts": 64, "test_contexts": 4,
}  # fmt: skip


def build(task_name: str, method: str, seed: int, workers: int, state: str, std: float,
          overrides: dict[str, Any]):  # fmt: skip
    """The task and a :class:`~vslbook.erl.diskill.DiSkill` model of ``method`` on it."""
    import torch

    from vslbook.envs.robot import make_task
    from vslbook.envs.robot.examples import EXAMPLES
    from vslbook.erl.diskill import DiSkill
    from vslbook.erl.diskill_config import diskill_config

    task = make_task(task_name)
    model = DiSkill(task, diskill_config(task_name, method, **overrides), seed, workers=workers)
    example = EXAMPLES.get(task_name)
    if state == "trained" and example is not None and len(example.theta) == task.n_params:
        experts = model.experts
        with torch.no_grad():  # μ_o(c) ≈ the example θ (the head's gain is 0.01), Σ = std² I
            experts.mean_net.biases[-1].copy_(
                torch.as_tensor(example.theta, dtype=experts.dtype).expand_as(
                    experts.mean_net.biases[-1]
                )
            )
            eye = torch.eye(task.n_params, dtype=experts.dtype)
            experts.set_chol(std * eye.expand(experts.n_experts, -1, -1))
    return task, model


class PhaseTimer:
    """Wraps the model's phases (and the task's episodes) to add up their times."""

    def __init__(self, model, clock: str) -> None:
        self.now = time.process_time if clock == "cpu" else time.perf_counter
        self.seconds = dict.fromkeys(PHASES, 0.0)
        self._wrap(model.task, "evaluate", "physics")
        for name, phase in (("update_experts", "expert"), ("update_critics", "critic"),
                            ("update_contexts", "context")):  # fmt: skip
            self._wrap(model, name, phase)

    def _wrap(self, obj: Any, name: str, phase: str) -> None:
        inner = getattr(obj, name)

        def timed(*args, **kwargs):
            start = self.now()
            try:
                return inner(*args, **kwargs)
            finally:
                self.seconds[phase] += self.now() - start

        setattr(obj, name, timed)


def time_iterations(model, iterations: int, warmup: int, clock: str) -> dict[str, float]:
    """Seconds per iteration of each phase (mean over ``iterations`` after ``warmup``)."""
    for _ in range(warmup):
        model.iterate()
    timer = PhaseTimer(model, clock)
    start = timer.now()
    for _ in range(iterations):
        model.iterate()
    total = timer.now() - start
    out = {k: v / iterations for k, v in timer.seconds.items()}
    out["rest"] = total / iterations - sum(out[k] for k in PHASES if k != "rest")
    out["iteration"] = total / iterations
    return out


def _header() -> str:
    cols = "".join(f"{p:>16s}" for p in (*PHASES, "networks"))
    return f"{'task':18s} {'method':9s} {'K':>3s} {'n':>4s} {'dtype':>8s} {'iter s':>8s}{cols}"


def _row(task: str, method: str, cfg, t: dict[str, float]) -> str:
    total = t["iteration"]
    net = sum(t[k] for k in NETWORKS)
    cells = (
        "".join(f"{t[p]:9.3f} ({100 * t[p] / total:3.0f}%)" for p in PHASES)
        + f"{net:9.3f} ({100 * net / total:3.0f}%)"
    )
    return (f"{task:18s} {method:9s} {cfg.n_experts:3d} {cfg.samples_per_expert:4d} "
            f"{getattr(cfg, 'dtype', 'float64'):>8s} {total:8.3f}{cells}")  # fmt: skip


def bench(task: str, method: str = "diskill", *, iterations: int = 2, warmup: int = 1,
          workers: int = 1, clock: str = "wall", state: str = "trained", std: float = 0.05,
          seed: int = 0, sizes: str = "thesis", header: bool = True,
          overrides: dict[str, Any] | None = None) -> dict[str, float]:  # fmt: skip
    """Time ``iterations`` iterations of ``method`` on ``task`` and print one table row."""
    extra = (SMOKE if sizes == "smoke" else {}) | (overrides or {})
    t_task, model = build(task, method, seed, workers, state, std, extra)
    try:
        t = time_iterations(model, iterations, warmup, clock)
    finally:
        t_task.close()
    if header:
        print(_header())
    print(_row(task, method, model.config, t), flush=True)
    return t


# ------------------------------------------------------------------ seeds side by side


def _child(args: argparse.Namespace) -> None:
    """One seed in this process: warm up, say ``ready``, wait for ``go``, time, report."""
    import torch

    torch.set_num_threads(args.threads)
    extra = (SMOKE if args.sizes == "smoke" else {}) | json.loads(args.overrides)
    task, model = build(args.tasks[0], args.methods[0], args.seed, args.workers, args.state,
                        args.std, extra)  # fmt: skip
    try:
        for _ in range(args.warmup):
            model.iterate()
        print("ready", flush=True)
        sys.stdin.readline()
        start = time.perf_counter()
        for _ in range(args.iterations):
            model.iterate()
        print(json.dumps({"seconds": time.perf_counter() - start}), flush=True)
    finally:
        task.close()


def _start(args: argparse.Namespace, seed: int, workers: int, threads: int) -> subprocess.Popen:
    cmd = [sys.executable, str(Path(__file__).resolve()), "--child", "--tasks", args.tasks[0],
           "--methods", args.methods[0], "--seed", str(seed), "--workers", str(workers),
           "--threads", str(threads), "--iterations", str(args.iterations),
           "--warmup", str(args.warmup), "--state", args.state, "--std", str(args.std),
           "--sizes", args.sizes, "--overrides", args.overrides]  # fmt: skip
    env = dict(os.environ, OMP_NUM_THREADS=str(threads))
    return subprocess.Popen(cmd, stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True, env=env)


def _together(args: argparse.Namespace, setups: list[tuple[int, int, int]]) -> float:
    """Start one process per (seed, workers, threads), release them together once all are
    warm; returns iterations per second of all of them together."""
    procs = [_start(args, *s) for s in setups]
    try:
        for p in procs:
            line = p.stdout.readline()
            if line.strip() != "ready":
                raise RuntimeError(f"a benchmark process did not start: {line!r}")
        for p in procs:
            p.stdin.write("go\n")
            p.stdin.flush()
        seconds = [json.loads(p.stdout.readline())["seconds"] for p in procs]
    finally:
        for p in procs:
            p.wait()
    return len(procs) * args.iterations / max(seconds)


def side_by_side(args: argparse.Namespace) -> float:
    """Throughput of two seeds with one worker each over one seed with two workers."""
    one = _together(args, [(args.seed, 2, args.threads)])
    two = _together(args, [(args.seed, 1, 1), (args.seed + 1, 1, 1)])
    print(f"{args.tasks[0]} {args.methods[0]}: one seed with 2 workers {one:.3f} it/s; "
          f"2 seeds side by side, 1 worker each {two:.3f} it/s; ratio {two / one:.2f}",
          flush=True)  # fmt: skip
    return two / one


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--tasks", nargs="+", default=list(TASKS))
    parser.add_argument("--methods", nargs="+", default=["diskill"])
    parser.add_argument("--iterations", type=int, default=2, help="timed iterations")
    parser.add_argument("--warmup", type=int, default=1, help="untimed iterations first")
    parser.add_argument("--workers", type=int, default=1, help="episode processes")
    parser.add_argument("--threads", type=int, default=1, help="torch threads")
    parser.add_argument("--clock", choices=("wall", "cpu"), default="wall")
    parser.add_argument("--state", choices=("trained", "fresh"), default="trained")
    parser.add_argument("--std", type=float, default=0.05, help="experts' std (trained state)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--sizes", choices=("thesis", "smoke"), default="thesis")
    parser.add_argument("--dtype", default=None, help="the networks' dtype (default: config)")
    parser.add_argument("--overrides", default="{}", help="config fields as JSON")
    parser.add_argument("--side-by-side", action="store_true")
    parser.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.dtype is not None:
        args.overrides = json.dumps(json.loads(args.overrides) | {"dtype": args.dtype})
    if args.child:
        _child(args)
        return
    import torch

    torch.set_num_threads(args.threads)
    print(f"torch {torch.__version__}, {torch.get_num_threads()} thread(s), "
          f"{os.cpu_count()} cores, clock {args.clock}, {args.workers} worker(s), "
          f"state {args.state}", flush=True)  # fmt: skip
    first = True
    for task in args.tasks:
        for method in args.methods:
            if args.side_by_side:
                side_by_side(argparse.Namespace(**{**vars(args), "tasks": [task],
                                                   "methods": [method]}))  # fmt: skip
                continue
            bench(task, method, iterations=args.iterations, warmup=args.warmup,
                  workers=args.workers, clock=args.clock, state=args.state, std=args.std,
                  seed=args.seed, sizes=args.sizes, header=first,
                  overrides=json.loads(args.overrides))  # fmt: skip
            first = False


if __name__ == "__main__":
    main()
