"""An exclusive lock per run directory, so that two processes never train one run.

The lock is ``fcntl.flock`` on ``<run>/LOCK``, a file that also names its holder (pid,
host, start time) for the message a second process prints. The kernel releases a flock
when its holder exits, however it exits (SIGKILL included), so a lock left by a killed
process is taken over by the next one without any cleanup; a ``LOCK`` file whose flock
is free is just a name tag of the last holder.

On a shared file system (NFS v4, Lustre, BeeGFS with ``flock`` enabled, which is what a
SLURM cluster's home or scratch usually is) the flock holds across hosts too.

    with RunLock(run_path):            # raises RunLockedError if another process holds it
        ...train...
    with RunLock(run_path, wait=True): # waits until the holder lets go
        ...
"""

from __future__ import annotations

import fcntl
import json
import os
import socket
import time
from pathlib import Path
from types import TracebackType

__all__ = ["RunLock", "RunLockedError"]

LOCK_NAME = "LOCK"


class RunLockedError(RuntimeError):
    """Another process holds the run directory's lock (its pid and host in the message)."""


def _holder(path: Path, patience: float = 1.0) -> str:
    """Who holds the lock at ``path``, as recorded in it ("pid 12 on host h since ...").

    A holder writes its name tag just after it takes the lock, so a process that finds the
    lock taken may read the file between the two, empty or cut short: it reads again for up
    to ``patience`` seconds before it settles for what is there.
    """
    deadline = time.monotonic() + patience
    while True:
        try:
            info = json.loads(path.read_text(encoding="utf-8") or "{}")
        except (OSError, ValueError):
            info = None
        if (info and "pid" in info) or time.monotonic() >= deadline:
            break
        time.sleep(0.02)
    if info is None:
        return "an unknown process"
    since = info.get("since")
    when = time.strftime("%Y-%m-%d %H:%M:%S", time.localtime(since)) if since else "?"
    return f"pid {info.get('pid', '?')} on host {info.get('host', '?')} (since {when})"


class RunLock:
    """The exclusive lock of the run directory ``run_path`` (created if missing).

    Args:
        run_path: the run directory.
        wait: block until the lock is free instead of raising; a line saying whom it
            waits for is printed once.
        poll: seconds between attempts while waiting.
    """

    def __init__(self, run_path: str | os.PathLike[str], *, wait: bool = False,
                 poll: float = 2.0) -> None:  # fmt: skip
        self.run_path = Path(run_path)
        self.path = self.run_path / LOCK_NAME
        self.wait = wait
        self.poll = float(poll)
        self._fd: int | None = None

    @property
    def held(self) -> bool:
        """True while this object holds the lock."""
        return self._fd is not None

    def acquire(self) -> RunLock:
        """Take the lock (see the class docstring for ``wait``).

        Raises:
            RunLockedError: another process holds it and ``wait`` is False.
        """
        if self._fd is not None:
            return self
        self.run_path.mkdir(parents=True, exist_ok=True)
        fd = os.open(self.path, os.O_RDWR | os.O_CREAT, 0o644)
        told = False
        while True:
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
                break
            except BlockingIOError:
                holder = _holder(self.path)
                if not self.wait:
                    os.close(fd)
                    raise RunLockedError(
                        f"run {self.run_path} is being trained by {holder}; wait for it "
                        "(--wait) or stop that process"
                    ) from None
                if not told:
                    print(f"waiting for {holder} to release {self.run_path}", flush=True)
                    told = True
                time.sleep(self.poll)
        info = {"pid": os.getpid(), "host": socket.gethostname(), "since": time.time()}
        os.ftruncate(fd, 0)
        os.pwrite(fd, (json.dumps(info) + "\n").encode("utf-8"), 0)
        self._fd = fd
        return self

    def release(self) -> None:
        """Let go of the lock (idempotent)."""
        if self._fd is None:
            return
        fd, self._fd = self._fd, None
        try:
            fcntl.flock(fd, fcntl.LOCK_UN)
        finally:
            os.close(fd)

    def __enter__(self) -> RunLock:
        return self.acquire()

    def __exit__(
        self, kind: type[BaseException] | None, err: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.release()

    def __del__(self) -> None:  # a dropped lock object must not keep the run locked
        try:
            self.release()
        except Exception:  # noqa: BLE001 - interpreter shutdown: the OS releases it anyway
            pass
