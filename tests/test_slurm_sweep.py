"""``vslbook sweep --executor slurm`` on a real single-node SLURM (tests/slurm_cluster.py).

Skipped, with the reason, where SLURM cannot start (not root, ``slurm-wlm`` / ``munge``
missing: ``make slurm``, or the daemons do not come up).
"""

from __future__ import annotations

import json
import subprocess
import sys
import time
from pathlib import Path

import pytest
import yaml
from slurm_cluster import SlurmCluster, SlurmUnavailable

from vslbook.sweep import sweep

pytestmark = pytest.mark.slow

ENV = "vslbook/PointReach-v0"
SEEDS = [0, 1]
ITERATIONS = 3_000_000  # 6000 iterations at the smoke budget (about 15 s): outlasts the
# 5 s between SLURM's SIGTERM (which submitit ignores) and its SIGKILL after a scancel
ARGS = ["sweep", "erl-pg", "--env", ENV, "--seeds", *map(str, SEEDS), "--budget", "smoke",
        "--grid", f"iterations={ITERATIONS}"]  # fmt: skip


@pytest.fixture(scope="module")
def cluster(tmp_path_factory):
    slurm = SlurmCluster(tmp_path_factory.mktemp("slurm"))
    try:
        slurm.start()
    except SlurmUnavailable as err:
        pytest.skip(f"cannot start a SLURM cluster here: {err}")
    try:
        yield slurm
    finally:
        slurm.stop()


def _env(cluster: SlurmCluster) -> dict[str, str]:
    # the runs' code fingerprint must not change under the test when the tree is edited;
    # one thread a job (the jobs inherit this environment): two jobs share the CPUs
    return {**cluster.env(), "VSLBOOK_REUSE_STALE": "1", "OMP_NUM_THREADS": "1"}


def _cli(cluster: SlurmCluster, cwd: Path, *args: str, timeout: float = 900):
    return subprocess.run(
        [sys.executable, "-m", "vslbook.cli", *args], cwd=cwd, env=_env(cluster),
        capture_output=True, text=True, timeout=timeout,
    )  # fmt: skip


def _queue(cluster: SlurmCluster) -> list[str]:
    out = subprocess.run(["squeue", "-h", "-r", "-o", "%i"], env=cluster.env(),
                         capture_output=True, text=True, check=True)  # fmt: skip
    return out.stdout.split()


def _slurm_yaml(folder: Path, **params) -> Path:
    path = folder / "slurm.yaml"
    path.write_text(yaml.safe_dump({"timeout_min": 30, "cpus_per_task": 1, **params}))
    return path


def _wait_for(what: str, check, timeout: float = 300) -> None:
    deadline = time.monotonic() + timeout
    while not check():
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out after {timeout:.0f} s waiting for {what}")
        time.sleep(0.1)


def test_bad_requests_are_one_line_errors_and_queue_nothing(cluster, tmp_path):
    cpus = int(cluster.node.get("CPUs", 1))
    cases = {
        "unknown SLURM partition 'nope'": {"slurm_partition": "nope"},
        f"cpus_per_task={cpus + 1} asks for": {"cpus_per_task": cpus + 1},
        "unknown key 'partition'": {"partition": "debug"},
        "timeout_min in SLURM config": {"timeout_min": "60"},
    }
    for i, (message, params) in enumerate(cases.items()):
        folder = tmp_path / str(i)
        folder.mkdir()
        slurm = _slurm_yaml(folder, **params)
        out = _cli(cluster, folder, *ARGS, "--root", str(folder / "runs"), "--executor", "slurm",
                   "--slurm", str(slurm), timeout=120)  # fmt: skip
        assert out.returncode == 2, (message, out.stdout, out.stderr)
        assert out.stderr.startswith("vslbook: error: ") and out.stderr.count("\n") == 1, out.stderr
        assert message in out.stderr, out.stderr
    assert _queue(cluster) == []


def test_sweep_cancel_resume_matches_a_local_run(cluster, tmp_path, monkeypatch):
    import torch

    monkeypatch.setenv("VSLBOOK_REUSE_STALE", "1")
    threads = torch.get_num_threads()
    torch.set_num_threads(1)  # as the jobs (OMP_NUM_THREADS=1)
    try:
        local = sweep("erl-pg", [ENV], SEEDS, grid={"iterations": [ITERATIONS]}, budget="smoke",
                      root=tmp_path / "local", executor="debug")  # fmt: skip
    finally:
        torch.set_num_threads(threads)
    root = tmp_path / "runs"
    args = [*ARGS, "--root", str(root), "--executor", "slurm", "--slurm",
            str(_slurm_yaml(tmp_path))]  # fmt: skip
    logs = root / "_submitit"

    # --no-wait: the job ids on stdout, the array and the log folder on stderr, at once
    out = _cli(cluster, tmp_path, *args, "--no-wait", timeout=120)
    assert out.returncode == 0, out.stderr
    jobs = out.stdout.split()
    assert len(jobs) == 2 and "submitted 2 SLURM jobs" in out.stderr and str(logs) in out.stderr

    # the same sweep waits for those jobs (no second submission); cancel seed 0 mid-run
    err_file = tmp_path / "wait.err"
    with err_file.open("w") as err:
        waiting = subprocess.Popen(
            [sys.executable, "-m", "vslbook.cli", *args], cwd=tmp_path, env=_env(cluster),
            stdout=subprocess.PIPE, stderr=err, text=True,
        )  # fmt: skip
    try:
        _wait_for("the sweep to find the queued jobs",
                  lambda: "already queued or running" in err_file.read_text())  # fmt: skip
        run0 = root / local[0].name

        def trained_a_while() -> bool:
            metrics = run0 / "metrics.jsonl"
            rows = metrics.read_text().count("\n") if metrics.exists() else 0
            return rows >= 30 and (run0 / "checkpoint").exists()

        _wait_for("seed 0 to write a checkpoint", trained_a_while)
        assert not (run0 / "DONE").exists(), "seed 0 finished before it could be cancelled"
        subprocess.run(["scancel", jobs[0]], env=cluster.env(), check=True)
        stdout, _ = waiting.communicate(timeout=900)
    finally:
        if waiting.poll() is None:
            waiting.kill()
    stderr = err_file.read_text()
    assert waiting.returncode == 1, stderr
    assert "submitted" not in stderr, stderr
    assert f"vslbook: error: job {jobs[0]} " in stderr and "CANCELLED without a result" in stderr
    assert stdout.split() == [str(root / local[1].name)]
    assert not (run0 / "DONE").exists()

    # the re-run skips the finished seed and resumes the cancelled one
    out = _cli(cluster, tmp_path, *args)
    assert out.returncode == 0, out.stderr
    assert "1 of 2 runs already DONE" in out.stderr and "submitted 1 SLURM jobs" in out.stderr
    paths = [Path(p) for p in out.stdout.split()]
    assert [p.name for p in paths] == [p.name for p in local]
    for mine, ref in zip(paths, local, strict=True):
        assert (mine / "DONE").exists()
        assert _rows(mine) == _rows(ref)
        assert json.loads((mine / "DONE").read_text()) == json.loads((ref / "DONE").read_text())
    _wait_for("the queue to empty", lambda: _queue(cluster) == [], timeout=120)


def _rows(path: Path) -> list[dict]:
    return [json.loads(line) for line in (path / "metrics.jsonl").read_text().splitlines()]
