"""Episodes per second of each robot task next to the bare physics it needs.

For every task in :data:`vslbook.envs.robot.TASKS` (or those named on the command line) this
evaluates a batch of episodes with small random parameters in one process and counts the
``mujoco.mj_step`` calls the batch made (physics steps, ``nstep`` included). A second,
untimed pass records MuJoCo's integration state (positions, velocities, controls, applied
forces, warm start, ...) before every one of those steps; the bare physics is then timed by
replaying exactly those steps, ``mj_setState`` + ``mj_step`` each, less the time of the
``mj_setState`` calls alone. So the bare time is that of the very steps the episodes took,
contacts and all. The ratio is the overhead of everything around the physics (trajectory
generation, validity check, control, reward); the target is under 20 %. (Timing the same
number of steps from the model's default, uncontrolled state instead, as this benchmark
once did, misjudges the physics: table tennis's episode steps cost about 20 % more than
those, mini golf's about twice as much.) A second line evaluates the same batch through the worker
pool (``--workers``, default: the machine's cores). ``--repeat N`` times the batch and the
bare steps N times each and keeps the fastest of each (steadier on a machine shared with
other jobs). Table tennis runs its sub-step loop compiled (numba, calling MuJoCo's C
``mj_step`` directly): its steps are the task's own count, and its states are recorded by a
twin task running the same loop in Python.

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

_STATE = mujoco.mjtState.mjSTATE_INTEGRATION


class _CountSteps:
    """Wraps ``mujoco.mj_step`` (and ``mj_step2``, the second half of a split step) and
    counts physics steps, ``nstep`` included; with ``record`` it also keeps the model and the
    integration state before every ``mj_step``, and before every ``mj_step2`` (beer pong
    pins the ball between ``mj_step1`` and ``mj_step2``: a full step from the state with the
    pin applied costs what the episode's split step cost)."""

    def __init__(self, record: bool = False) -> None:
        self.real, self.real2 = mujoco.mj_step, mujoco.mj_step2
        self.steps = 0
        self.record = record
        self.states: list[tuple[mujoco.MjModel, np.ndarray]] = []

    def step(self, model, data, nstep: int = 1) -> None:
        if self.record:
            for _ in range(int(nstep)):
                state = np.empty(mujoco.mj_stateSize(model, _STATE))
                mujoco.mj_getState(model, data, state, _STATE)
                self.states.append((model, state))
                self.real(model, data)
            self.steps += int(nstep)
            return
        self.steps += int(nstep)
        self.real(model, data, nstep)

    def step2(self, model, data) -> None:
        if self.record:
            state = np.empty(mujoco.mj_stateSize(model, _STATE))
            mujoco.mj_getState(model, data, state, _STATE)
            self.states.append((model, state))
        self.steps += 1
        self.real2(model, data)

    def __enter__(self) -> _CountSteps:
        mujoco.mj_step, mujoco.mj_step2 = self.step, self.step2
        return self

    def __exit__(self, *exc) -> None:
        mujoco.mj_step, mujoco.mj_step2 = self.real, self.real2


def _bare_physics(states: list[tuple[mujoco.MjModel, np.ndarray]], repeat: int) -> float:
    """Seconds of the recorded steps alone: (set state + step) less (set state), fastest of
    ``repeat``."""
    datas = {id(model): mujoco.MjData(model) for model, _ in states}
    best = math.inf
    for _ in range(repeat):
        start = time.perf_counter()
        for model, state in states:
            data = datas[id(model)]
            mujoco.mj_setState(model, data, state, _STATE)
            mujoco.mj_step(model, data)
        replay = time.perf_counter() - start
        start = time.perf_counter()
        for model, state in states:
            mujoco.mj_setState(model, datas[id(model)], state, _STATE)
        best = min(best, replay - (time.perf_counter() - start))
    return best


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
    steps, twin = counter.steps, task
    if getattr(task, "compiled", False):
        # A compiled loop calls MuJoCo's C step directly, past the Python counter: its steps
        # come from the task's own count, and a twin running the same loop in Python (the
        # same numbers, tested) records the states for the bare replay.
        before = task.sim_steps
        task.evaluate(theta, contexts, workers=0)
        steps, twin = task.sim_steps - before, make_task(name, compiled=False)
    if steps:
        with _CountSteps(record=True) as recorder:
            twin.evaluate(theta, contexts, workers=0)
        if recorder.steps != steps or len(recorder.states) != steps:
            raise RuntimeError(
                f"{name}: the recording pass took {recorder.steps} steps "
                f"({len(recorder.states)} recorded), the timed pass {steps}"
            )
        bare = _bare_physics(recorder.states, repeat)
        line += (
            f"; physics {steps / episodes:.0f} steps/episode, bare mj_step "
            f"{steps / bare:9.0f} steps/s, overhead {100 * (wall - bare) / bare:5.1f} %"
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
