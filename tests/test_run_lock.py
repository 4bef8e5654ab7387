"""Two processes never train one run: the run-directory lock, ``--wait``, ``--restart``,
``--dry-run`` and the one-line errors of damaged run directories."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from vslbook.cli import main
from vslbook.results import RunDir
from vslbook.run_lock import RunLock, RunLockedError

SVSL = ["svsl", "--env", "vslbook/PlanarReacher-v0", "--seed", "0", "--budget", "smoke",
        "--no-progress"]  # fmt: skip


def _cli(root: Path, *extra: str) -> list[str]:
    return [sys.executable, "-m", "vslbook.cli", "run", *SVSL, "--root", str(root), *extra]


def _env() -> dict[str, str]:
    return dict(os.environ, OMP_NUM_THREADS="1", VSLBOOK_REUSE_STALE="1")


def _only_run(root: Path) -> RunDir:
    dirs = [p for p in root.iterdir() if (p / "config.json").is_file()]
    assert len(dirs) == 1, dirs
    return RunDir.open(dirs[0])


def test_a_lock_names_its_holder_and_a_killed_holder_lets_go(tmp_path):
    holder = subprocess.Popen(
        [sys.executable, "-c", "import sys, time; from vslbook.run_lock import RunLock; "
         f"lock = RunLock({str(tmp_path / 'r')!r}).acquire(); print('held', flush=True); "
         "time.sleep(600)"],
        stdout=subprocess.PIPE, text=True,
    )  # fmt: skip
    try:
        assert holder.stdout.readline().strip() == "held"
        with pytest.raises(RunLockedError, match=rf"being trained by pid {holder.pid} on host "):
            RunLock(tmp_path / "r").acquire()
    finally:
        os.kill(holder.pid, signal.SIGKILL)
        holder.wait()
    with RunLock(tmp_path / "r") as lock:  # the kernel released the killed holder's lock
        assert lock.held
        assert json.loads((tmp_path / "r" / "LOCK").read_text())["pid"] == os.getpid()
    assert not lock.held


def test_waiting_for_a_lock_ends_when_the_holder_lets_go(tmp_path):
    first = RunLock(tmp_path / "r").acquire()
    holder = subprocess.Popen(
        [sys.executable, "-c", "from vslbook.run_lock import RunLock; "
         f"RunLock({str(tmp_path / 'r')!r}, wait=True, poll=0.05).acquire(); print('got it')"],
        stdout=subprocess.PIPE, text=True,
    )  # fmt: skip
    time.sleep(1.0)
    assert holder.poll() is None  # still waiting
    first.release()
    out, _ = holder.communicate(timeout=60)
    assert "waiting for pid" in out and out.strip().endswith("got it")


@pytest.mark.slow
def test_the_same_run_started_twice_at_once_ends_in_one_clean_run(tmp_path):
    root = tmp_path / "runs"
    longer = ("--set", "iterations_per_expert=600")  # 1210 rows, about 10 s
    procs = [subprocess.Popen(_cli(root, *longer), stdout=subprocess.PIPE,
                              stderr=subprocess.PIPE, text=True, env=_env())
             for _ in range(2)]  # fmt: skip
    outs = [p.communicate(timeout=300) for p in procs]
    codes = sorted(p.returncode for p in procs)
    assert codes == [0, 2], [o[1][-2000:] for o in outs]
    winner = next(p for p in procs if p.returncode == 0)
    lines = outs[procs.index(next(p for p in procs if p.returncode == 2))][1].strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("vslbook: error: run ")
    assert f"is being trained by pid {winner.pid} on host" in lines[0] and "--wait" in lines[0]
    rd = _only_run(root)
    rows = rd.metrics()
    assert rd.done and [r["step"] for r in rows] == list(range(1, 1211))
    rd.check_done()
    # --wait: a third waits for nobody now and reuses the finished run unchanged
    before = rd.metrics_path.read_bytes()
    c = subprocess.run(_cli(root, *longer, "--wait"), capture_output=True, text=True,
                       env=_env(), timeout=300)  # fmt: skip
    assert c.returncode == 0 and rd.metrics_path.read_bytes() == before


def test_dry_run_prints_the_name_and_creates_nothing(tmp_path, capsys):
    root = tmp_path / "runs"
    assert main(["run", *SVSL, "--root", str(root), "--dry-run"]) == 0
    name = capsys.readouterr().out.strip()
    assert name.startswith("svsl-vslbook_PlanarReacher-v0-s0-") and not root.exists()
    from vslbook.training import run_name

    assert run_name("svsl", "vslbook/PlanarReacher-v0", 0, "smoke") == name


def _finished_run(tmp_path: Path) -> RunDir:
    """A small finished run (erl-pg, a few seconds) to damage."""
    from vslbook.training import run

    return run("erl-pg", "vslbook/PointReach-v0", 0, "smoke", root=tmp_path / "runs",
               progress=False)  # fmt: skip


PG = ["run", "erl-pg", "--env", "vslbook/PointReach-v0", "--seed", "0", "--budget", "smoke",
      "--no-progress"]  # fmt: skip


def _one_error_line(capsys) -> str:
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("vslbook: error: "), err
    return err[0]


def test_damaged_run_directories_are_one_line_errors_and_restart_recovers(tmp_path, capsys):
    rd = _finished_run(tmp_path)
    root = str(tmp_path / "runs")
    capsys.readouterr()
    # DONE without the metrics it records
    rows = rd.metrics_path.read_bytes()
    rd.metrics_path.unlink()
    assert main([*PG, "--root", root]) == 2
    assert "marked DONE but" in _one_error_line(capsys)
    # a truncated checkpoint of an unfinished run
    rd.metrics_path.write_bytes(rows)
    (rd.path / "DONE").unlink()
    data = rd.checkpoint_path.read_bytes()
    rd.checkpoint_path.write_bytes(data[: len(data) // 2])
    assert main([*PG, "--root", root]) == 2
    line = _one_error_line(capsys)
    assert str(rd.checkpoint_path) in line and "--restart" in line
    # a broken config.json
    config = (rd.path / "config.json").read_text()
    (rd.path / "config.json").write_text("{broken")
    assert main([*PG, "--root", root]) == 2
    assert "config.json is not valid JSON" in _one_error_line(capsys)
    (rd.path / "config.json").write_text(config)
    # --restart moves the damaged run aside (nothing deleted) and trains it afresh
    assert main([*PG, "--root", root, "--restart"]) == 0
    assert RunDir.open(rd.path).done and RunDir.open(rd.path).metrics_path.read_bytes() == rows
    moved = list((tmp_path / "runs" / "_restarted").iterdir())
    assert len(moved) == 1 and (moved[0] / "metrics.jsonl").is_file()


def test_a_root_that_cannot_hold_runs_is_one_line(tmp_path, capsys):
    afile = tmp_path / "afile"
    afile.write_text("")
    assert main([*PG, "--root", str(afile)]) == 2
    assert "Not a directory" in _one_error_line(capsys)
    if os.geteuid() != 0:  # root writes anywhere
        locked = tmp_path / "ro"
        locked.mkdir(mode=0o500)
        assert main([*PG, "--root", str(locked / "runs")]) == 2
        assert "Permission denied" in _one_error_line(capsys)


def test_a_missing_env_json_means_unknown_code(tmp_path, capsys):
    rd = _finished_run(tmp_path)
    (rd.path / "env.json").unlink()
    assert not rd.code_matches  # nothing says which code made it
    assert main([*PG, "--root", str(tmp_path / "runs")]) == 0
    assert "was made by other code" in capsys.readouterr().out
    assert RunDir.open(rd.path).done and (rd.path / "env.json").is_file()


def test_a_refusal_names_a_holder_that_has_not_written_its_name_yet(tmp_path):
    """The holder takes the lock, then writes its name tag: a process refused in between
    reads the tag again until it is there, instead of naming pid "?"."""
    import fcntl
    import threading

    (tmp_path / "r").mkdir()
    fd = os.open(tmp_path / "r" / "LOCK", os.O_RDWR | os.O_CREAT, 0o644)
    fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)  # taken, the tag not written yet
    tag = json.dumps({"pid": 4242, "host": "elsewhere", "since": time.time()})
    late = threading.Timer(0.3, lambda: os.pwrite(fd, tag.encode(), 0))
    late.start()
    try:
        with pytest.raises(RunLockedError, match="being trained by pid 4242 on host elsewhere"):
            RunLock(tmp_path / "r").acquire()
    finally:
        late.join()
        os.close(fd)
