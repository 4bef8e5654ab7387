"""`python -m vslbook.experiments.unfinished_runs pack / unpack`: an unfinished run carried
to a fresh root resumes exactly, finished runs drop out, a run being trained is never packed,
bad archives and bad roots are errors that name them."""

from __future__ import annotations

import io
import json
import tarfile

import pytest

from vslbook.data import DataIntegrityError, gzip_bytes, register_file
from vslbook.experiments.unfinished_runs import archive_bytes, main, pack, recorded_runs, unpack
from vslbook.run_lock import RunLock
from vslbook.training import run

PLANAR = "vslbook/PlanarReacher-v0"
# varies between two runs of the same seed: wall-clock fields
_CLOCK = {"iteration_seconds", "wall_time", "time"}


def _rows(path):
    rows = [json.loads(x) for x in (path / "metrics.jsonl").read_text().splitlines()]
    return [{k: v for k, v in r.items() if k not in _CLOCK} for r in rows]


def _partial(root, stop_after=7):
    return run("hireps", PLANAR, seed=2, budget="smoke", root=root, progress=False,
               stop_after=stop_after)  # fmt: skip


def test_a_packed_run_resumes_exactly_in_a_fresh_root(tmp_path):
    whole = run("hireps", PLANAR, seed=2, budget="smoke", root=tmp_path / "a", progress=False)
    part = _partial(tmp_path / "b")
    assert not part.done
    trained = (part.path / "metrics.jsonl").read_text().splitlines()
    carried = pack(tmp_path / "b", tmp_path / "carried", report=lambda line: None)
    assert [(c.run, c.action) for c in carried] == [(part.path.name, "packed")]
    # the machine that trained it is gone: only the archive travels
    unpack(tmp_path / "c", tmp_path / "carried", report=lambda line: None)
    resumed = run("hireps", PLANAR, seed=2, budget="smoke", root=tmp_path / "c",
                  progress=False)  # fmt: skip
    assert resumed.done and resumed.path.name == whole.path.name
    # it went on from the checkpoint: the first 7 rows are the packed ones, wall clock too
    assert (resumed.path / "metrics.jsonl").read_text().splitlines()[:7] == trained
    assert _rows(resumed.path) == _rows(whole.path)
    assert len(_rows(whole.path)) > 7


def test_pack_is_deterministic_and_drops_runs_that_finished(tmp_path):
    part = _partial(tmp_path / "b")
    out = tmp_path / "carried"
    pack(tmp_path / "b", out, report=lambda line: None)
    archive = out / f"{part.path.name}.tar.gz"
    first = archive.read_bytes()
    assert archive_bytes(part.path) == first
    again = pack(tmp_path / "b", out, report=lambda line: None)
    assert [c.action for c in again] == ["unchanged"] and archive.read_bytes() == first
    with tarfile.open(fileobj=io.BytesIO(first)) as tar:
        names = tar.getnames()
        assert {m.mtime for m in tar.getmembers()} == {0}
    assert names == sorted(names) and f"{part.path.name}/checkpoint/state.pt" in names
    assert f"{part.path.name}/LOCK" not in names
    run("hireps", PLANAR, seed=2, budget="smoke", root=tmp_path / "b", progress=False)
    lines = []
    gone = pack(tmp_path / "b", out, report=lines.append, recorded={part.path.name})
    assert [(c.action, c.detail) for c in gone] == [("removed", "recorded")]
    assert not archive.exists() and lines == [f"removed   {part.path.name}  (recorded)"]
    assert not (out / "registry.json").exists()  # its only entry went with it


def test_a_finished_run_is_carried_until_it_is_recorded(tmp_path):
    whole = run("hireps", PLANAR, seed=2, budget="smoke", root=tmp_path / "a", progress=False)
    out = tmp_path / "carried"
    lines = []
    kept = pack(tmp_path / "a", out, report=lines.append, recorded={"another-run"})
    assert [c.action for c in kept] == ["packed"]
    assert lines[0].startswith(f"packed    {whole.path.name}  (finished, not recorded yet, ")
    # the runs folder is gone; the archive brings the finished run back, DONE and all
    unpack(tmp_path / "c", out, report=lambda line: None)
    back = tmp_path / "c" / whole.path.name
    for name in ("config.json", "metrics.jsonl", "DONE", "checkpoint/state.pt"):
        assert (back / name).read_bytes() == (whole.path / name).read_bytes(), name
    assert pack(tmp_path / "c", out, report=lambda line: None,
                recorded=set())[0].action == "unchanged"  # fmt: skip
    gone = pack(tmp_path / "c", out, report=lambda line: None, recorded={whole.path.name})
    assert [c.action for c in gone] == ["removed"] and not list(out.glob("*.tar.gz"))


def test_a_run_being_trained_is_skipped(tmp_path):
    part = _partial(tmp_path / "b")
    with RunLock(part.path):
        carried = pack(tmp_path / "b", tmp_path / "carried", report=lambda line: None)
    assert [c.action for c in carried] == ["skipped"]
    assert "being trained" in carried[0].detail
    assert not (tmp_path / "carried").exists()


def test_unpack_keeps_a_copy_that_is_as_far_or_further(tmp_path):
    early = _partial(tmp_path / "early", stop_after=3)
    late = _partial(tmp_path / "late", stop_after=7)
    pack(tmp_path / "early", tmp_path / "carried", report=lambda line: None)
    # the root's own copy is further on: it stays
    kept = unpack(tmp_path / "late", tmp_path / "carried", report=lambda line: None)
    assert [(c.action, c.detail) for c in kept] == [("kept", "checkpoint at 7 here; "
                                                             "archive at 3")]  # fmt: skip
    assert len(_rows(late.path)) == 7
    # a copy behind the archive is moved aside, never deleted
    pack(tmp_path / "late", tmp_path / "later", report=lambda line: None)
    done = unpack(tmp_path / "early", tmp_path / "later", report=lambda line: None)
    assert [c.action for c in done] == ["unpacked"]
    assert len(_rows(early.path)) == 7
    aside = list((tmp_path / "early" / "_replaced").iterdir())
    assert len(aside) == 1 and len(_rows(aside[0])) == 3
    assert [p.name for p in (tmp_path / "early").iterdir() if p.name.startswith("_unp")] == []


def test_a_damaged_or_hostile_archive_is_refused(tmp_path):
    part = _partial(tmp_path / "b")
    out = tmp_path / "carried"
    pack(tmp_path / "b", out, report=lambda line: None)
    archive = out / f"{part.path.name}.tar.gz"
    archive.write_bytes(archive.read_bytes()[:-8] + b"\0" * 8)
    with pytest.raises(DataIntegrityError, match="sha256"):
        unpack(tmp_path / "c", out, report=lambda line: None)
    # a registered archive that reaches outside its run's folder
    buffer = io.BytesIO()
    with tarfile.open(fileobj=buffer, mode="w") as tar:
        info = tarfile.TarInfo(f"{part.path.name}/../escape.txt")
        info.size = 2
        tar.addfile(info, io.BytesIO(b"hi"))
    archive.write_bytes(gzip_bytes(buffer.getvalue()))
    register_file(archive, "test")
    with pytest.raises(ValueError, match=r"escape\.txt.*expected only regular files"):
        unpack(tmp_path / "c", out, report=lambda line: None)
    assert not (tmp_path / "escape.txt").exists()


def test_command_line(tmp_path, capsys, monkeypatch):
    monkeypatch.setenv("VSLBOOK_DATA", str(tmp_path / "data"))
    part = _partial(tmp_path / "b")
    assert main(["pack", "--root", str(tmp_path / "b")]) == 0
    assert f"packed    {part.path.name}  (checkpoint at 7" in capsys.readouterr().out
    assert (tmp_path / "data" / "unfinished" / f"{part.path.name}.tar.gz").is_file()
    assert main(["unpack", "--root", str(tmp_path / "c")]) == 0
    assert f"unpacked  {part.path.name}  (checkpoint at 7)" in capsys.readouterr().out
    (tmp_path / "empty").mkdir()
    assert main(["pack", "--root", str(tmp_path / "empty")]) == 0
    assert capsys.readouterr().out == "nothing to pack\n"
    assert main(["pack", "--root", str(tmp_path / "nowhere")]) == 2
    err = capsys.readouterr().err
    assert "nowhere' does not exist; expected a folder of run directories" in err
    (tmp_path / "file").write_text("x")
    assert main(["unpack", "--root", str(tmp_path / "file")]) == 2
    assert "is not a folder" in capsys.readouterr().err


def test_recorded_runs_are_the_finished_rows_of_every_recorded_set():
    import csv

    from vslbook.data import results_dir

    done, probes = set(), set()
    for table in results_dir().glob("*/*/runs.csv"):
        with table.open(newline="") as fh:
            for row in csv.DictReader(fh):
                (done if row["status"] == "done" else probes).add(row["run"])
    assert done and probes  # the repository holds both: finished sets and probes
    assert recorded_runs() == done
