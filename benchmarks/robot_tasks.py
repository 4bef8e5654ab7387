"""Episodes per second of each robot task next to the bare physics it needs.

For every task in :data:`vslbook.envs.robot.TASKS` (or those named on the command line) this
evaluates a batch of episodes with small random parameters in one process, counts the
``mujoco.mj_step`` calls the batch made (physics steps, ``nstep`` included), and then times
exactly that many bare ``mj_step`` calls on the task's own model. The ratio is the overhead
of everything around the physics (trajectory generation, validity check, control, contacts,
reward); the target is under 20 %. A second line evaluates the same batch through the worker
pool (``--workers``, default: the machine's cores). ``--repeat N`` times the batch and the
bare steps N times each and keeps the fastest of each (steadier on a machine shared with
other jobs).

    python benchmarks/robot_tasks.py --episodes 50
    python benchmarks/robot_tasks.py --episodes 20 --workers 1 --repeat 5
    python benchmarks/robot_tasks.py planar-reacher --episodes 100000
"""

from __future__ import annotations

import argparse
import math
import time

import mujoco
import numpy as np

from vslbook.envs.robot import TASKS, make_task
from vslbook.envs.robot.task import resolve_workers


class _CountSteps:
    """Wraps ``mujoco.mj_step`` (and ``mj_step2``, the second half of a split step) and
    counts physics steps, ``nstep`` included."""

    def __init__(self) -> None:
        self.real, self.real2 = mujoco.mj_step, mujoco.mj_step2
        self.steps = 0

    def step(self, model, data, nstep: int = 1) -> None:
        self.steps += int(nstep)
        self.real(model, data, nstep)

    def step2(self, model, data) -> None:
        self.steps += 1
        self.real2(model, data)

    def __enter__(self) -> _CountSteps:
        mujoco.mj_step, mujoco.mj_step2 = self.step, self.step2
        return self

    def __exit__(self, *exc) -> None:
        mujoco.mj_step, mujoco.mj_step2 = self.real, self.real2


def _model_of(task) -> mujoco.MjModel | None:
    """The task's MuJoCo model: an attribute, or an attribute of one of its attributes."""
    for value in vars(task).values():
        if isinstance(value, mujoco.MjModel):
            return value
        inner = getattr(value, "model", None)
        if isinstance(inner, mujoco.MjModel):
            return inner
    return None


#: A typical valid θ needs the learned duration / start time inside its bounds.
_TIMING = {
    "table-tennis-4d": {0: 1.0, 1: 0.3},  # τ, delay
    "table-tennis-hard": {0: 1.0, 1: 0.3},
    "table-tennis-ch3": {0: 1.0},  # movement duration in seconds
    "beer-pong": {0: 0.6},
    "mini-golf": {0: 1.0},  # τ
}


def bench(name: str, episodes: int, workers: int, scale: float, seed: int, repeat: int) -> None:
    task = make_task(name)
    rng = np.random.default_rng(seed)
    contexts = task.sample_contexts(episodes, rng)
    theta = scale * rng.standard_normal((episodes, task.n_params))
    for column, value in _TIMING.get(name, {}).items():
        theta[:, column] = value
    wall = math.inf
    for _ in range(repeat):
        with _CountSteps() as counter:
            start = time.perf_counter()
            out = task.evaluate(theta, contexts, workers=0)
            wall = min(wall, time.perf_counter() - start)
    line = f"{name:28s} {episodes / wall:10.1f} episodes/s  ({out.n_executed} executed)"
    model = _model_of(task)
    if model is not None and counter.steps:
        bare = math.inf
        for _ in range(repeat):
            data = mujoco.MjData(model)
            start = time.perf_counter()
            for _ in range(counter.steps):
                mujoco.mj_step(model, data)
            # (the model's default state, uncontrolled: its steps can cost more or less than
            # the episodes' (mini golf's about twice as much, table tennis's about 20 % more,
            # measured by replaying episodes' controls with mujoco.rollout), so the overhead
            # printed is approximate and can be negative)
            bare = min(bare, time.perf_counter() - start)
        line += (
            f"; physics {counter.steps / episodes:.0f} steps/episode, bare mj_step "
            f"{counter.steps / bare:9.0f} steps/s, overhead {100 * (wall - bare) / bare:5.1f} %"
        )
    print(line, flush=True)
    if workers > 1:
        start = time.perf_counter()
        task.evaluate(theta, contexts, workers=workers)
        rate = episodes / (time.perf_counter() - start)
        print(f"{'':28s} {rate:10.1f} episodes/s with {workers} workers")
    task.close()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("tasks", nargs="*", help=f"default: all of {', '.join(TASKS)}")
    parser.add_argument("--episodes", type=int, default=50)
    parser.add_argument("--workers", type=int, default=None)
    parser.add_argument("--scale", type=float, default=0.1, help="std of the random θ")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument(
        "--repeat", type=int, default=1, help="time N times, keep the fastest (default 1)"
    )
    args = parser.parse_args()
    if args.repeat < 1:
        parser.error(f"--repeat must be at least 1, got {args.repeat}")
    workers = resolve_workers(args.workers)
    for name in args.tasks or list(TASKS):
        bench(name, args.episodes, workers, args.scale, args.seed, args.repeat)


if __name__ == "__main__":
    main()
