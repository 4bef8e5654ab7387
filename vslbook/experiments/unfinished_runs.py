"""Unfinished runs carried between machines: ``python -m vslbook.experiments.unfinished_runs
pack|unpack --root DIR``.

A full-budget run set trains for days, a few hours at a time, and the machine that trains
it need not keep its runs folder from one sitting to the next. The repository does keep
what is committed, so an unfinished run travels with it:

* :func:`pack` (``... pack --root DIR``) writes every unfinished run of ``DIR`` that
  has a checkpoint (no ``DONE``, no ``FAILED``) to ``data/unfinished/<run>.tar.gz``: its
  ``config.json``, ``env.json``, ``metrics.jsonl`` and ``checkpoint/``, taken under the
  run's lock (:mod:`vslbook.run_lock`), so a run being trained is skipped, never packed
  half-written. Each archive is registered (sha256) in ``data/unfinished/registry.json``.
  A run that has finished in ``DIR`` is packed too, with its ``DONE``, until it is
  recorded (a ``done`` row of some ``data/results/*/*/runs.csv``,
  :func:`recorded_runs`): the runs folder may not outlive the sitting, and a finished run
  that is neither recorded nor carried would be lost. Once it is recorded, or if it
  failed, its archive is removed.
* :func:`unpack` (``... unpack --root DIR``) writes each archive back as a run
  directory of ``DIR`` where ``DIR`` has no such run, or has it at an earlier checkpoint
  (that copy is moved to ``DIR/_replaced/``, nothing is deleted). Training it again
  (``vslbook run`` / ``vslbook train``) resumes from the state it was packed in: the files
  are the same bytes, and resuming rewinds the rows logged after the checkpoint
  (:func:`vslbook.run_open.open_run`). On a machine that rounds like the one that packed
  it, the rows are those of an uninterrupted run; on another CPU its float32 network
  updates round differently from the checkpoint on (:mod:`vslbook.experiments.record_verify`).

An archive's bytes depend on the run's files alone (sorted members, fixed times, owners and
gzip header), so packing an unchanged run again changes nothing in the repository.

The commands live here, not in ``vslbook.cli``, because the command line is part of the
code fingerprint a recorded run carries (:mod:`vslbook.provenance`): adding them there would
mark every recorded set for a replay, for a change that moves no number.
"""

from __future__ import annotations

import argparse
import io
import os
import shutil
import sys
import tarfile
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

from vslbook.data import data_dir, gzip_bytes, register_file, unregister_file, verify_file
from vslbook.jsonfiles import atomic_write
from vslbook.results import RunDir
from vslbook.run_lock import RunLock, RunLockedError

__all__ = ["ARCHIVE_SUFFIX", "Carried", "archive_bytes", "main", "pack", "recorded_runs",
           "unfinished_dir", "unpack"]  # fmt: skip

#: the file name of a run's archive is ``<run><ARCHIVE_SUFFIX>``
ARCHIVE_SUFFIX = ".tar.gz"
#: the files of a run directory an archive holds (plus everything under ``checkpoint/``);
#: ``DONE`` only in the archive of a finished run that is not recorded yet
_RUN_FILES = (RunDir.CONFIG, RunDir.ENV, RunDir.METRICS, RunDir.DONE)
_DESCRIPTION = ("an unfinished run's directory (config.json, env.json, metrics.jsonl, "
                "checkpoint/), tar + gzip; written by `python -m "
                "vslbook.experiments.unfinished_runs pack`, read by its `unpack`")


@dataclass(frozen=True)
class Carried:
    """What :func:`pack` or :func:`unpack` did with one run: ``action`` is one of
    ``packed``, ``unchanged``, ``removed``, ``skipped`` (pack) or ``unpacked``, ``kept``,
    ``skipped`` (unpack); ``detail`` says why where it is not obvious."""

    run: str
    action: str
    detail: str = ""

    def __str__(self) -> str:
        return f"{self.action:9s} {self.run}" + (f"  ({self.detail})" if self.detail else "")


def unfinished_dir() -> Path:
    """``data/unfinished/`` (under :func:`vslbook.data.data_dir`)."""
    return data_dir() / "unfinished"


def _members(run: Path) -> list[Path]:
    files = [run / name for name in _RUN_FILES if (run / name).is_file()]
    ckpt = run / RunDir.CHECKPOINT_DIR
    files += [p for p in ckpt.rglob("*") if p.is_file()]
    return sorted(files, key=lambda p: p.relative_to(run).as_posix())


def archive_bytes(run: str | os.PathLike[str]) -> bytes:
    """The run directory ``run`` as deterministic ``.tar.gz`` bytes: its config, env,
    metrics and checkpoint files under ``<run name>/``, sorted, with mtime 0, mode 0644 and
    no owner names."""
    run = Path(run)
    buffer = io.BytesIO()
    with tarfile.open(fileobj=buffer, mode="w", format=tarfile.PAX_FORMAT) as tar:
        for path in _members(run):
            data = path.read_bytes()
            info = tarfile.TarInfo(f"{run.name}/{path.relative_to(run).as_posix()}")
            info.size, info.mtime, info.mode = len(data), 0, 0o644
            tar.addfile(info, io.BytesIO(data))
    return gzip_bytes(buffer.getvalue())


def _checkpoint_step(run: Path) -> int:
    """The step a resume of ``run`` starts from (0 without a checkpoint)."""
    from vslbook.experiments.train_figure import checkpoint_step

    if not (run / RunDir.CHECKPOINT_DIR / RunDir.CHECKPOINT).is_file():
        return 0
    return checkpoint_step(run)


def recorded_runs() -> set[str]:
    """The names of the runs recorded as finished in any set of ``data/results/``
    (``status`` ``done`` in its ``runs.csv``; probes are not counted)."""
    from vslbook.data import results_dir
    from vslbook.experiments.record import read_set

    names: set[str] = set()
    for table in sorted(results_dir().glob("*/*/runs.csv")):
        runs, _, _ = read_set(table.parent)
        names |= set(runs.loc[runs["status"] == "done", "run"])
    return names


def _check_root(root: Path, *, must_exist: bool) -> None:
    if root.exists() and not root.is_dir():
        raise ValueError(f"root {str(root)!r} is not a folder; expected a folder of run "
                         "directories")  # fmt: skip
    if must_exist and not root.is_dir():
        raise ValueError(f"root {str(root)!r} does not exist; expected a folder of run "
                         "directories")  # fmt: skip


def pack(root: str | os.PathLike[str], out: str | os.PathLike[str] | None = None,
         report=print, recorded: set[str] | None = None) -> list[Carried]:  # fmt: skip
    """Archive every unfinished run of ``root`` into ``out`` (default
    :func:`unfinished_dir`), and every finished one that is not in ``recorded`` (default
    :func:`recorded_runs`); remove the archives of runs that are recorded or failed.
    ``report(line)`` is called once per run. See the module's docstring."""
    root = Path(root)
    _check_root(root, must_exist=True)
    out = Path(out) if out is not None else unfinished_dir()
    runs = sorted(p for p in root.iterdir() if (p / RunDir.CONFIG).is_file())
    if recorded is None and any(RunDir(p).done for p in runs):
        recorded = recorded_runs()
    done: list[Carried] = []
    for path in runs:
        target = out / f"{path.name}{ARCHIVE_SUFFIX}"
        rd = RunDir(path)
        if rd.failed or (rd.done and path.name in (recorded or set())):
            if target.exists():
                target.unlink()
                unregister_file(target)
                done.append(Carried(path.name, "removed", "recorded" if rd.done else "failed"))
            continue
        if not (path / RunDir.CHECKPOINT_DIR / RunDir.CHECKPOINT).is_file():
            continue  # nothing a resume could start from
        try:
            with RunLock(path):
                data = archive_bytes(path)
                step = _checkpoint_step(path)
        except RunLockedError as err:
            done.append(Carried(path.name, "skipped", str(err)))
            continue
        if target.exists() and target.read_bytes() == data:
            done.append(Carried(path.name, "unchanged", f"checkpoint at {step}"))
            continue
        out.mkdir(parents=True, exist_ok=True)
        atomic_write(target, data)
        register_file(target, _DESCRIPTION)
        state = "finished, not recorded yet" if rd.done else f"checkpoint at {step}"
        done.append(Carried(path.name, "packed", f"{state}, {len(data):,} bytes"))
    for item in done:
        report(str(item))
    return done


def _safe_extract(data: bytes, name: str, into: Path) -> Path:
    """Extract an archive of run ``name`` into ``into``; returns ``into/name``. Refuses any
    member outside ``name/`` and anything that is not a regular file."""
    with tarfile.open(fileobj=io.BytesIO(data), mode="r:gz") as tar:
        for member in tar.getmembers():
            parts = Path(member.name).parts
            if (not member.isfile() or member.name.startswith("/") or ".." in parts
                    or len(parts) < 2 or parts[0] != name):  # fmt: skip
                raise ValueError(f"archive of {name} holds {member.name!r}; expected only "
                                 f"regular files under {name}/")  # fmt: skip
        tar.extractall(into, filter="data")
    return into / name


def unpack(root: str | os.PathLike[str], source: str | os.PathLike[str] | None = None,
           report=print) -> list[Carried]:  # fmt: skip
    """Write each archive of ``source`` (default :func:`unfinished_dir`) back into ``root``
    where ``root`` lacks the run or holds it at an earlier checkpoint. See the module's
    docstring.

    Raises:
        vslbook.data.DataIntegrityError: an archive does not match its registered sha256.
        ValueError: ``root`` is a file, or an archive holds a path outside its run.
    """
    root = Path(root)
    _check_root(root, must_exist=False)
    source = Path(source) if source is not None else unfinished_dir()
    archives = sorted(source.glob(f"*{ARCHIVE_SUFFIX}")) if source.is_dir() else []
    done: list[Carried] = []
    for archive in archives:
        name = archive.name[: -len(ARCHIVE_SUFFIX)]
        verify_file(archive)
        root.mkdir(parents=True, exist_ok=True)
        with tempfile.TemporaryDirectory(dir=root, prefix="_unpacking-") as tmp:
            fresh = _safe_extract(archive.read_bytes(), name, Path(tmp))
            theirs = _checkpoint_step(fresh)
            here = root / name
            if (here / RunDir.CONFIG).is_file():
                mine = RunDir(here)
                ours = _checkpoint_step(here)
                if mine.done or mine.failed or ours >= theirs:
                    state = ("done" if mine.done else "failed" if mine.failed
                             else f"checkpoint at {ours}")  # fmt: skip
                    done.append(Carried(name, "kept", f"{state} here; archive at {theirs}"))
                    continue
                try:
                    with RunLock(here):
                        moved = root / "_replaced" / f"{name}-{time.strftime('%Y%m%d-%H%M%S')}"
                        moved.parent.mkdir(parents=True, exist_ok=True)
                        shutil.move(str(here), str(moved))
                except RunLockedError as err:
                    done.append(Carried(name, "skipped", str(err)))
                    continue
            shutil.move(str(fresh), str(here))
            done.append(Carried(name, "unpacked", f"checkpoint at {theirs}"))
    for item in done:
        report(str(item))
    return done


def main(argv: list[str] | None = None) -> int:
    """``python -m vslbook.experiments.unfinished_runs pack|unpack [--root DIR]``; bad input
    ends in one line ``unfinished_runs: error: ...`` and exit status 2."""
    parser = argparse.ArgumentParser(
        prog="python -m vslbook.experiments.unfinished_runs",
        description="pack: archive ROOT's unfinished runs into data/unfinished/; unpack: "
        "write them back into ROOT (where it lacks them or holds them at an earlier "
        "checkpoint), to resume them exactly.",
    )  # fmt: skip
    parser.add_argument("command", choices=["pack", "unpack"])
    parser.add_argument("--root", default="runs", help="folder of run directories")
    args = parser.parse_args(argv)
    try:
        carried = (pack if args.command == "pack" else unpack)(args.root)
    except (ValueError, OSError) as err:
        print(f"unfinished_runs: error: {err}", file=sys.stderr)
        return 2
    if not carried:
        print(f"nothing to {args.command}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
