"""Open a run directory for training: the one way every algorithm's runs are started.

:func:`open_run` does, in order:

1. **Lock** the run directory (:class:`vslbook.run_lock.RunLock`): a second process on
   the same run refuses with the holder's pid and host, or waits (``wait=True``).
2. **Restart** on request: the old directory is moved to ``<root>/_restarted/`` (nothing
   is deleted) and the run starts afresh.
3. **Create** it, or reopen it when its ``config.json`` is the same.
4. **Stale code**: a run made by other code (its ``env.json`` code fingerprint differs)
   is first checked by ``verify`` (:func:`vslbook.replay.replay_matches`: today's code
   replays its first rows); if they match, the run is kept and today's fingerprint added
   to it. Otherwise it is moved to ``<root>/_stale/`` and started afresh, or reused with a
   warning when ``reuse_stale`` (or ``$VSLBOOK_REUSE_STALE=1``).
5. **Check** a finished run: its ``DONE`` must match its metrics
   (:meth:`vslbook.results.RunDir.check_done`), else a one-line error says ``--restart``.
6. **Rewind** an unfinished one: rows logged after the last checkpoint (all rows, when
   there is none yet) are dropped, so a resumed run never repeats a row.

The returned :class:`~vslbook.results.RunDir` holds the lock (``rd.lock``) until
``rd.release()``, or until the process ends, however it ends.
"""

from __future__ import annotations

import os
import shutil
import time
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

from vslbook.provenance import code_fingerprint
from vslbook.results import RunDir
from vslbook.run_lock import RunLock

__all__ = ["REUSE_STALE_ENV", "open_run"]

REUSE_STALE_ENV = "VSLBOOK_REUSE_STALE"


def _reuse_from_env() -> bool:
    return os.environ.get(REUSE_STALE_ENV, "").strip().lower() in ("1", "true", "yes")


def _move_aside(rd: RunDir, root: Path, folder: str, tag: str) -> Path:
    target = root / folder / f"{rd.name}-{tag}-{int(time.time())}"
    target.parent.mkdir(parents=True, exist_ok=True)
    shutil.move(str(rd.path), str(target))
    return target


def _locked(root: Path, name: str, wait: bool) -> tuple[RunDir, RunLock]:
    lock = RunLock(root / name, wait=wait).acquire()
    return RunDir(root / name), lock


def open_run(
    root: str | os.PathLike[str],
    record: Mapping[str, Any],
    *,
    code_exclude: tuple[str, ...] = (),
    reuse_stale: bool | None = None,
    wait: bool = False,
    restart: bool = False,
    verify: Callable[[RunDir], str | None] | None = None,
) -> RunDir:
    """The run directory of ``record`` under ``root``, locked and ready to train or reuse.

    Args:
        record: the run's configuration (``algo``, ``env``, ``seed``, ``budget`` and the
            algorithm's fields); its :meth:`RunDir.name_for` names the directory.
        code_exclude: package paths the run's code cannot reach (left out of its code
            fingerprint, :func:`vslbook.provenance.code_fingerprint`).
        reuse_stale: reuse a run made by other code (None: ``$VSLBOOK_REUSE_STALE``).
        wait: wait for another process's lock instead of raising.
        restart: move an existing directory aside and start afresh.
        verify: ``verify(rd)`` for a run made by other code: None when today's code
            reproduces it (it is kept), else the reason it does not.

    Raises:
        vslbook.run_lock.RunLockedError: another process trains the run (``wait`` False).
        vslbook.results.RunDirError: a ``DONE`` its metrics do not back, an unreadable
            ``config.json``.
        ValueError: the directory holds a run with another configuration.
        OSError: ``root`` cannot hold run directories (a file, not writable).
    """
    root = Path(root)
    name = RunDir.name_for(record)
    rd, lock = _locked(root, name, wait)
    try:
        if restart and any(p.name != lock.path.name for p in rd.path.iterdir()):
            target = _move_aside(rd, root, "_restarted", "restart")
            print(f"run {name} moved to {target}; training it afresh")
            lock.release()
            rd, lock = _locked(root, name, wait)
        rd = RunDir.create(root, record, name=name, code_exclude=code_exclude)
        if not rd.code_matches:
            old = (rd.code_hash or "unknown")[:12]
            new = code_fingerprint(tuple(rd.env.get("code_excluded", code_exclude)))[:12]
            what = f"run {name} ({rd.status}) was made by other code (code hash {old}, now {new})"
            why = "not checked" if verify is None or rd.failed else verify(rd)
            if why is None:
                rd.add_verified_code()
                print(f"{what}; its first rows replay identically with today's code: kept")
            elif reuse_stale if reuse_stale is not None else _reuse_from_env():
                print(f"WARNING: {what}; reusing it (reuse_stale / ${REUSE_STALE_ENV})")
            else:
                target = _move_aside(rd, root, "_stale", old)
                print(f"{what}; replay: {why}; moved to {target} and starting afresh")
                lock.release()
                rd, lock = _locked(root, name, wait)
                rd = RunDir.create(root, record, name=name, code_exclude=code_exclude)
        if rd.done:
            rd.check_done()
        elif not rd.failed:
            rd.rewind()
    except BaseException:
        lock.release()
        raise
    rd.lock = lock
    return rd
