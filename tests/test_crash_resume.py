"""Crash harness: runs SIGKILLed at random points resume to exactly the uninterrupted rows.

For each algorithm (SVSL, Di-SkilL, PPO, DIME and DIME's seed axis) the same ``vslbook run``
command trains twice, side by side on the two cores: once without interruption (the
reference), and once killed with SIGKILL at five or more points and restarted after each
kill (the victim). The kill points come from a seeded RNG: a number of rows in
``metrics.jsonl`` to wait for (the first one before the run's first checkpoint, so the rows
logged before any checkpoint must be dropped on restart), or, for PPO, whose rows are written
when it finishes, a time after the start. After the last restart the victim runs to the end,
and its ``metrics.jsonl`` must equal the reference's row for row, wall-clock fields aside,
with no row repeated; its ``DONE`` must hold.

A kill the process outran (it finished first) is not counted; the test fails if fewer than
five kills landed, so it never passes without crashing the runs.
"""

from __future__ import annotations

import json
import os
import random
import re
import signal
import subprocess
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

import pytest

pytestmark = pytest.mark.slow

#: metrics that measure the machine, not the run
WALL_CLOCK = re.compile(r"seconds|_per_s$|^time|fps")
RUN_TIMEOUT_S = 900.0
KILLS = 5

# DIME at the full budget (fraction 1: counts are environment steps) with tiny networks on
# Pendulum (200-step episodes): a checkpoint at every episode end, a row every 100 steps.
DIME_SETS = [
    "total_steps=800", "learning_starts=350", "critic_hidden=32", "actor_hidden=32",
    "n_diffusion_steps=2", "batch_size=32", "eval_every=100", "eval_episodes=1",
    "checkpoint_every=200", "v_min=-1600.0", "v_max=100.0", "num_threads=1", "device=cpu",
]  # fmt: skip


@dataclass(frozen=True)
class Case:
    """One algorithm's command and how to kill it.

    Attributes:
        args: ``vslbook run`` arguments after ``run``.
        first_rows: the first kill waits for a row count drawn from this range (before the
            first checkpoint); later ones for counts above it.
        rows: how many rows the finished run has (one run directory; per seed with --seeds).
        seconds: kill by time after the start instead of rows (PPO writes its rows at the end).
        env: extra environment variables (the checkpoint interval).
    """

    args: list[str]
    first_rows: tuple[int, int] = (1, 2)
    rows: int = 0
    seconds: tuple[float, float] | None = None
    env: dict[str, str] = field(default_factory=dict)


CASES = {
    # 110 rows; checkpoints every 50 iterations: the first kill lands before the first one
    "svsl": Case(["svsl", "--env", "vslbook/PlanarReacher-v0", "--budget", "smoke"],
                 first_rows=(3, 45), rows=110),
    # 7 rows (iteration 0 to 6), a checkpoint after every iteration ($VSLBOOK_CHECKPOINT_SECONDS=0)
    "diskill": Case(["diskill", "--env", "vslbook/Reacher5-v0", "--budget", "smoke",
                     "--set", "iterations=6"], first_rows=(1, 2), rows=7,
                    env={"VSLBOOK_CHECKPOINT_SECONDS": "0"}),
    # twenty rollouts of 16384 steps (about 1.5 s each), a checkpoint after each; killed by
    # time, counted from the start of the process (about 4 s of imports)
    "ppo": Case(["ppo-ch4", "--env", "vslbook/Reacher5SparseStep-v0", "--budget", "smoke",
                 "--set", "total_steps=327680"], seconds=(5.0, 9.0)),
    "dime": Case(["dime", "--env", "Pendulum-v1", "--budget", "full", "--set", *DIME_SETS],
                 first_rows=(1, 2), rows=8),
    "dime-seeds": Case(["dime", "--env", "Pendulum-v1", "--budget", "full",
                        "--set", *DIME_SETS], first_rows=(1, 2), rows=8),
}  # fmt: skip
SEEDS = {"dime-seeds": ["--seeds", "0", "1"]}


def _command(name: str, root: Path) -> list[str]:
    seeds = SEEDS.get(name, ["--seed", "0"])
    return [sys.executable, "-m", "vslbook.cli", "run", *CASES[name].args, *seeds,
            "--root", str(root), "--no-progress"]  # fmt: skip


def _start(name: str, root: Path, log: Path) -> subprocess.Popen:
    root.mkdir(parents=True, exist_ok=True)
    env = dict(os.environ, OMP_NUM_THREADS="1", **CASES[name].env)
    with open(log, "a") as out:
        return subprocess.Popen(_command(name, root), stdout=out, stderr=subprocess.STDOUT,
                                env=env)  # fmt: skip


def _finish(proc: subprocess.Popen, log: Path) -> None:
    try:
        proc.wait(timeout=RUN_TIMEOUT_S)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.wait()
        pytest.fail(f"run did not finish in {RUN_TIMEOUT_S:.0f} s:\n{log.read_text()[-3000:]}")
    assert proc.returncode == 0, f"run failed ({proc.returncode}):\n{log.read_text()[-3000:]}"


def _lines(path: Path) -> list[str]:
    if not path.exists():
        return []
    return [x for x in path.read_text(encoding="utf-8").split("\n")[:-1] if x.strip()]


def _row_count(root: Path) -> int:
    """The fewest rows over the run directories in ``root`` (one per seed)."""
    dirs = [p for p in root.iterdir() if (p / "config.json").is_file()] if root.exists() else []
    return min((len(_lines(d / "metrics.jsonl")) for d in dirs), default=0)


def _rows(run_dir: Path) -> list[dict]:
    rows = [json.loads(x) for x in _lines(run_dir / "metrics.jsonl")]
    return [{k: v for k, v in r.items() if not WALL_CLOCK.search(k)} for r in rows]


def _kill_when(proc: subprocess.Popen, root: Path, rows: int | None, seconds: float | None,
               delay: float) -> bool:  # fmt: skip
    """SIGKILL ``proc`` once ``root`` has ``rows`` rows (or ``seconds`` have passed), plus
    ``delay``; False if the process finished first."""
    start = time.monotonic()
    while proc.poll() is None:
        if time.monotonic() - start > RUN_TIMEOUT_S:
            proc.kill()
            pytest.fail(f"no {rows} rows in {root} within {RUN_TIMEOUT_S:.0f} s")
        reached = (time.monotonic() - start >= seconds) if seconds is not None else (
            _row_count(root) >= rows)  # fmt: skip
        if reached:
            time.sleep(delay)
            if proc.poll() is not None:
                return False
            os.kill(proc.pid, signal.SIGKILL)
            proc.wait(timeout=60)
            return True
        time.sleep(0.01)
    return False


@pytest.mark.parametrize("name", sorted(CASES))
def test_sigkill_at_random_points_then_resume_matches_uninterrupted(tmp_path, name):
    case = CASES[name]
    rng = random.Random(f"crash-{name}")
    ref_root, victim_root = tmp_path / "reference", tmp_path / "victim"
    reference = _start(name, ref_root, tmp_path / "reference.log")
    log = tmp_path / "victim.log"
    landed, points = 0, []
    try:
        for k in range(KILLS + 3):  # a few spare attempts for kills the run outran
            if landed >= KILLS:
                break
            if case.seconds is not None:
                rows, seconds = None, rng.uniform(*case.seconds)
            else:
                low, high = case.first_rows if k == 0 else (case.first_rows[1], case.rows)
                rows, seconds = rng.randrange(low, max(low + 1, high)), None
            delay = rng.uniform(0.0, 0.05)
            victim = _start(name, victim_root, log)
            if _kill_when(victim, victim_root, rows, seconds, delay):
                landed += 1
                points.append(rows if rows is not None else round(seconds, 1))
            else:
                _finish(victim, log)
                break
        victim = _start(name, victim_root, log)
        _finish(victim, log)
        _finish(reference, tmp_path / "reference.log")
    finally:
        for proc in (reference,):
            if proc.poll() is None:
                proc.kill()
    assert landed >= KILLS, f"only {landed} kills landed before {name} finished: {points}"
    ref_dirs = sorted(p for p in ref_root.iterdir() if (p / "DONE").is_file())
    victim_dirs = sorted(p for p in victim_root.iterdir() if (p / "config.json").is_file())
    assert [p.name for p in victim_dirs] == [p.name for p in ref_dirs] and ref_dirs
    from vslbook.results import RunDir

    for ref, got in zip(ref_dirs, victim_dirs, strict=True):
        rd = RunDir.open(got)
        assert rd.done, f"{got} is not DONE after the kills at {points}"
        rd.check_done()
        expected, rows = _rows(ref), _rows(got)
        steps = [r["step"] for r in rows]
        assert steps == sorted(set(steps)), f"repeated or reordered steps {steps}"
        assert rows == expected, f"{name}: resumed rows differ after kills at {points}"
        if case.rows:
            assert len(rows) == case.rows
