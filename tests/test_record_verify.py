"""``vslbook results --verify`` on another machine: where today's replay differs from the
record, the code that made the run is replayed here too; the run is verified only if the two
replays agree and the record is within rounding of them.

The "code that made the run" is a commit of a throwaway git repository holding a copy of
today's package: as it is, with a comment added (no number changes), and with one logged
number changed."""

from __future__ import annotations

import gzip
import json
import shutil
import subprocess
from pathlib import Path

import pandas as pd
import pytest

import vslbook
from vslbook.data import register_file
from vslbook.experiments.record import record, recorded_dir
from vslbook.experiments.record_verify import (
    MACHINE_RTOL,
    replay_rows,
    replay_with_recording_code,
    verify_recorded,
)
from vslbook.experiments.run_plan import figure_runs
from vslbook.provenance import package_fingerprint
from vslbook.replay import RTOL, numeric_row, rows_match
from vslbook.training import run

PLANAR = "vslbook/PlanarReacher-v0"
LOGGED = '"mean_return": float(np.mean(r_new)),'


def _git(repo: Path, *args: str) -> str:
    return subprocess.run(["git", "-C", str(repo), "-c", "user.email=t@t", "-c", "user.name=t",
                           *args], check=True, capture_output=True, text=True).stdout.strip()


@pytest.fixture(scope="module")
def repo(tmp_path_factory):
    """(repository, commits): ``same`` today's package, ``comment`` the same with a comment
    added to its command line, ``changed`` with HiREPS's logged mean return plus 1."""
    root = tmp_path_factory.mktemp("repo")
    shutil.copytree(Path(vslbook.__file__).parent, root / "vslbook",
                    ignore=shutil.ignore_patterns("__pycache__"))  # fmt: skip
    _git(root, "init", "-q")
    commits = {}
    for name, edit in [("same", None), ("comment", "cli"), ("changed", "hireps")]:
        if edit == "cli":
            with (root / "vslbook" / "cli.py").open("a") as f:
                f.write("# a comment, which changes no number\n")
        elif edit == "hireps":
            path = root / "vslbook" / "erl" / "hireps.py"
            text = path.read_text()
            assert LOGGED in text
            path.write_text(text.replace(LOGGED, LOGGED[:-1] + " + 1.0,"))
        _git(root, "add", "-A")
        _git(root, "commit", "-q", "-m", name)
        sha = _git(root, "rev-parse", "HEAD")
        commits[name] = (sha, _fingerprint(root, sha, ("srl/",),
                                           tmp_path_factory.mktemp(name) / "code"))
    return root, commits


def _fingerprint(root: Path, sha: str, excluded: tuple[str, ...], into: Path) -> str:
    """The code fingerprint of commit ``sha``'s package (as ``vslbook.provenance`` takes it),
    from a copy in the new folder ``into`` (the fingerprint is cached per folder)."""
    tar = subprocess.run(["git", "-C", str(root), "archive", "--format=tar", sha, "vslbook"],
                         check=True, capture_output=True).stdout  # fmt: skip
    into.mkdir()
    subprocess.run(["tar", "-x", "-C", str(into)], input=tar, check=True)
    return package_fingerprint(into / "vslbook", tuple(sorted(set(excluded))))


@pytest.fixture(scope="module")
def hireps_run(tmp_path_factory):
    """A two-iteration HiREPS run on the planar reacher: (config, numeric rows)."""
    rd = run("hireps", PLANAR, seed=3, budget="smoke", progress=False, stop_after=2,
             root=tmp_path_factory.mktemp("runs"))  # fmt: skip
    return rd.config, [numeric_row(r) for r in rd.metrics()]


def _entry(config, commit, dirty=False):
    sha, code_hash = commit
    return {"config": config, "git_sha": sha, "git_dirty": dirty, "code_hash": code_hash,
            "code_excluded": ["srl/"]}  # fmt: skip


def _scaled(rows, factor):
    out = [dict(r) for r in rows]
    out[1]["mean_return"] *= factor
    return out


def test_a_replay_in_a_separate_process_gives_the_runs_rows(hireps_run):
    config, rows = hireps_run
    again = replay_rows(config)
    assert len(again) == len(rows) == 2 and rows_match(rows, again, rtol=0.0) is None


def test_rounding_passes_a_change_of_numbers_does_not(repo, hireps_run):
    root, commits = repo
    config, rows = hireps_run
    for commit in ("same", "comment"):
        entry = _entry(config, commits[commit])
        assert replay_with_recording_code(entry, rows, root) is None
        # the record as another machine rounded it: beyond RTOL, within MACHINE_RTOL
        assert replay_with_recording_code(entry, _scaled(rows, 1 + 10 * RTOL), root) is None
    why = replay_with_recording_code(_entry(config, commits["same"]),
                                     _scaled(rows, 1 + 10 * MACHINE_RTOL), root)  # fmt: skip
    assert why.startswith("the record differs by more than rounding: row 2, mean_return")
    why = replay_with_recording_code(_entry(config, commits["changed"]), rows, root)
    assert why.startswith("today's code computes other numbers than the code that made the "
                          "run: row 1, mean_return")  # fmt: skip


def test_without_the_recording_code_it_says_why(repo, hireps_run):
    root, commits = repo
    config, rows = hireps_run
    sha, code_hash = commits["same"]
    assert replay_with_recording_code(_entry(config, commits["same"], dirty=True), rows,
                                      root) == "made by uncommitted code, which cannot be replayed"
    why = replay_with_recording_code(_entry(config, ("0" * 40, code_hash)), rows, root)
    assert why.startswith("git cannot give commit 000000000000")
    why = replay_with_recording_code(_entry(config, (sha, "f" * 64)), rows, root)
    assert why == f"commit {sha[:12]} does not hold the code that made the run"


def _rewrite(path: Path, data: bytes) -> None:
    registry = json.loads((path.parent / "registry.json").read_text())
    path.write_bytes(data)
    register_file(path, registry[path.name]["description"])


def test_verify_marks_a_run_rounded_elsewhere_verified(repo, tmp_path, monkeypatch):
    """A recorded BBRL hopper-jump run (Fig. 4.4a, smoke), made "elsewhere": by the commit
    with the comment, its first rows rounded 10 * RTOL apart. Verify replays it twice and
    keeps it; the same record 10 * MACHINE_RTOL apart stays stale."""
    root, commits = repo
    monkeypatch.setenv("VSLBOOK_DATA", str(tmp_path / "data"))
    monkeypatch.setenv("VSLBOOK_WORKERS", "1")
    bbrl = next(r for r in figure_runs("fig4-4a", "smoke") if r.algo == "bbrl")
    bbrl.train(tmp_path / "runs")
    record("fig4-4a", "smoke", tmp_path / "runs")
    directory = recorded_dir("fig4-4a", "smoke")
    provenance = json.loads((directory / "provenance.json").read_text())
    sha, _ = commits["comment"]
    entry = provenance["runs"][bbrl.name]
    entry |= {"git_sha": sha, "git_dirty": False, "code_hash": _fingerprint(
        root, sha, tuple(entry["code_excluded"]), tmp_path / "comment")}  # fmt: skip
    _rewrite(directory / "provenance.json",
             (json.dumps(provenance, indent=2, sort_keys=True) + "\n").encode())
    evals = pd.read_csv(directory / "evals.csv.gz")
    original = evals.copy()
    for factor, state in [(1 + 10 * RTOL, "verified"), (1 + 10 * MACHINE_RTOL, "stale")]:
        evals = original.copy()
        first = evals[(evals["run"] == bbrl.name) & (evals["metric"] == "mean_return")].index[0]
        evals.loc[first, "value"] *= factor
        _rewrite(directory / "evals.csv.gz",
                 gzip.compress(evals.to_csv(index=False, lineterminator="\n").encode(), mtime=0))
        (row,) = verify_recorded(["fig4-4a"], ["smoke"], progress=False, repo=root)
        assert row.state == state, row.detail
        if state == "verified":
            assert row.detail.startswith("this machine rounds differently from the record (")
            assert "mean_return" in row.detail
            kept = json.loads((directory / "provenance.json").read_text())["runs"][bbrl.name]
            assert len(kept["code_hashes_verified"]) == 1
            _rewrite(directory / "provenance.json",
                     (json.dumps(provenance, indent=2, sort_keys=True) + "\n").encode())
        else:
            assert "the record differs by more than rounding" in row.detail
