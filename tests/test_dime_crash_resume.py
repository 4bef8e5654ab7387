"""A DIME run killed with SIGKILL mid-run resumes to exactly the numbers of an uninterrupted one.

``tests/test_dime_loop.py::test_resume_is_exact`` stops a run cleanly (``stop_after``); this
test kills the training *process* at an arbitrary moment after it has written a checkpoint
and logged rows past it, the way a cluster pre-emption or an out-of-memory kill does. Then it
runs the same configuration again (in-process through ``vslbook.training.run``, which the
CLI calls; a new interpreter would add ~10 s of imports), which finds the run directory (its
name is derived from the config), truncates ``metrics.jsonl`` back to the checkpoint and
continues. The resumed run's metrics must equal, row for row, those of the same command run
without interruption in another root (all metrics but the two wall-clock rates), and so must
its ``DONE`` summary.

Sizes: the ``full`` budget (fraction 1.0) is used so every count below is literally a number
of environment steps. Pendulum-v1 episodes are 200 steps long, so with
``checkpoint_every=200`` a checkpoint is written at every episode end (steps 200 and 400;
the final one at 600 drops the replay buffer), and ``eval_every=100`` logs a row every 100
steps, i.e. also mid-episode rows that the truncation on resume has to drop. Updates start
at step 350 (uniform exploration before is nearly free), so the checkpoint at 200 holds an
untrained agent and the one at 400 an agent, optimisers, BatchRenorm statistics and
temperature after about 100 critic and 33 actor updates. The process is killed as soon as
the checkpoint is at step >= ``KILL_AFTER_CHECKPOINT`` (400, the second one, so the resume
starts from a checkpoint that replaced an earlier one) and ``metrics.jsonl`` has more rows
than that checkpoint recorded, i.e. at step 500 or a little later: about 100 steps with two
critic updates each are still to come, a second or more even on a fast machine, against a
50 ms poll. If the
process has nevertheless exited before the kill, or the poll times out, the test fails
saying so; it never passes without a kill.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
import torch

from vslbook.training import run

ENV = "Pendulum-v1"
# Tiny networks (as TINY in tests/test_dime_loop.py); counts are env steps at the full budget.
OVERRIDES = {
    "total_steps": 600,  # three Pendulum episodes
    "learning_starts": 350,  # uniform actions (cheap) for 350 steps, updates from then on
    "critic_hidden": 32,
    "actor_hidden": 32,
    "n_diffusion_steps": 2,
    "batch_size": 32,
    "eval_every": 100,
    "eval_episodes": 1,
    "checkpoint_every": 200,  # at the episode ends at steps 200 and 400 (and at the end)
    "v_min": -1600.0,
    "v_max": 100.0,
    "num_threads": 1,
    "device": "cpu",  # resume is exact on CPU (vslbook.srl.dime)
}
KILL_AFTER_CHECKPOINT = 400
WALL_CLOCK = {"critic_updates_per_s", "env_steps_per_s"}
POLL_TIMEOUT_S = 240.0
RUN_TIMEOUT_S = 600.0


def _command(root: Path) -> list[str]:
    sets = [f"{key}={value}" for key, value in OVERRIDES.items()]
    return [
        sys.executable, "-m", "vslbook.cli", "run", "dime", "--env", ENV, "--seed", "0",
        "--budget", "full", "--root", str(root), "--no-progress", "--set", *sets,
    ]  # fmt: skip


def _start(root: Path) -> subprocess.Popen:
    """Start the CLI run in ``root``; its output goes to ``root``.log (no pipe to fill up)."""
    root.parent.mkdir(parents=True, exist_ok=True)
    with open(_log(root), "w") as log:
        return subprocess.Popen(
            _command(root),
            stdout=log,
            stderr=subprocess.STDOUT,
            env=dict(os.environ, OMP_NUM_THREADS="1"),
        )


def _log(root: Path) -> Path:
    return root.with_name(root.name + ".log")


def _tail(root: Path) -> str:
    return _log(root).read_text(errors="replace")[-3000:]


def _finish(proc: subprocess.Popen, root: Path) -> None:
    try:
        proc.wait(timeout=RUN_TIMEOUT_S)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.wait()
        pytest.fail(f"training subprocess did not finish in {RUN_TIMEOUT_S:.0f} s:\n{_tail(root)}")
    assert proc.returncode == 0, f"training subprocess failed ({proc.returncode}):\n{_tail(root)}"


def _run_dir(root: Path) -> Path | None:
    dirs = [p for p in root.iterdir() if (p / "config.json").is_file()] if root.exists() else []
    assert len(dirs) <= 1, f"expected one run directory in {root}, found {dirs}"
    return dirs[0] if dirs else None


def _lines(path: Path) -> list[str]:
    """Complete lines of a file that another process is appending to."""
    if not path.exists():
        return []
    return [x for x in path.read_text(encoding="utf-8").split("\n")[:-1] if x.strip()]


def _rows(run_dir: Path) -> list[dict]:
    rows = [json.loads(x) for x in _lines(run_dir / "metrics.jsonl")]
    return [{k: v for k, v in row.items() if k not in WALL_CLOCK} for row in rows]


def _wait_past_checkpoint(proc: subprocess.Popen, root: Path) -> tuple[int, int]:
    """Poll until the checkpoint is at step >= KILL_AFTER_CHECKPOINT and metrics.jsonl has
    rows logged after it.

    Returns (checkpoint step, rows in metrics.jsonl when seen). Fails if the process exits
    first or ``POLL_TIMEOUT_S`` passes.
    """
    deadline = time.monotonic() + POLL_TIMEOUT_S
    seen_mtime, state = None, None
    while time.monotonic() < deadline:
        if proc.poll() is not None:
            pytest.fail(
                f"the training process exited (code {proc.returncode}) before it could be "
                f"killed mid-run; the run is too short for this machine or it crashed:\n"
                f"{_tail(root)}"
            )
        run_dir = _run_dir(root)
        state_file = None if run_dir is None else run_dir / "checkpoint" / "state.pt"
        try:
            mtime = state_file.stat().st_mtime_ns if state_file is not None else None
        except FileNotFoundError:
            mtime = None
        if mtime is not None and mtime != seen_mtime:  # a new checkpoint: read its step
            # written to state.pt.tmp and renamed, so an open file is always complete
            state = torch.load(state_file, map_location="cpu", weights_only=False)
            seen_mtime = mtime
        if state is not None and state["step"] >= KILL_AFTER_CHECKPOINT:
            rows = len(_lines(run_dir / "metrics.jsonl"))
            if rows > state["_metrics_lines"]:
                return int(state["step"]), rows
        time.sleep(0.05)
    proc.kill()
    proc.wait()
    pytest.fail(
        f"no checkpoint at step >= {KILL_AFTER_CHECKPOINT} followed by new metrics rows "
        f"within {POLL_TIMEOUT_S:.0f} s"
    )



@pytest.mark.slow
def test_sigkill_mid_run_then_resume_matches_uninterrupted(tmp_path):
    killed_root, reference_root = tmp_path / "killed", tmp_path / "reference"
    # The uninterrupted reference runs beside the one that is killed (two cores).
    reference = _start(reference_root)
    try:
        victim = _start(killed_root)
        try:
            checkpoint_step, rows_seen = _wait_past_checkpoint(victim, killed_root)
            assert victim.poll() is None, "the training process finished before it was killed"
            os.kill(victim.pid, signal.SIGKILL)
            victim.wait(timeout=60)
        finally:
            if victim.poll() is None:
                victim.kill()
                victim.wait()
        assert victim.returncode == -signal.SIGKILL, "the process was not the one killed"
        run_dir = _run_dir(killed_root)
        assert not (run_dir / "DONE").exists(), "the killed run is marked DONE"
        killed_rows = _rows(run_dir)
        assert killed_rows[-1]["step"] < OVERRIDES["total_steps"], "the killed run reached the end"
        assert killed_rows[-1]["step"] > checkpoint_step and len(killed_rows) >= rows_seen

        # Resume: the same run through the Python entry point (the CLI's ``run`` calls it with
        # the --set strings, converted to the same config, hence the same directory name).
        # In-process because a fresh interpreter spends ~10 s importing on a loaded 2-core box.
        resumed = run(
            "dime", ENV, 0, "full", root=killed_root, overrides=OVERRIDES, progress=False
        )  # fmt: skip
        assert resumed.path == run_dir, "the resume did not find the killed run's directory"
        _finish(reference, reference_root)
    finally:
        if reference.poll() is None:
            reference.kill()
            reference.wait()
    reference_dir = _run_dir(reference_root)
    assert run_dir.name == reference_dir.name
    assert resumed.done and (reference_dir / "DONE").is_file()

    resumed_rows, uninterrupted = _rows(run_dir), _rows(reference_dir)
    steps = list(range(OVERRIDES["eval_every"], OVERRIDES["total_steps"] + 1, 100))
    assert [r["step"] for r in uninterrupted] == steps
    assert resumed_rows == uninterrupted
    # the rows logged before the kill, including those after the checkpoint that the resume
    # dropped and logged again, are a prefix of the final ones
    assert killed_rows == uninterrupted[: len(killed_rows)]
    done = json.loads((run_dir / "DONE").read_text())
    assert done == json.loads((reference_dir / "DONE").read_text())
