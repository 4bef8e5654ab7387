"""A throw-away single-node SLURM cluster for tests: munged, slurmctld and slurmd.

Everything lives in one folder (configuration, state, spool, logs, the MUNGE key and
socket); the daemons listen on 127.0.0.1 only and are stopped by their pids. No
accounting (``sacct`` has nothing to report), no cgroups (``proctrack/linuxproc``,
``task/none``). Needs root and Debian's ``slurm-wlm`` and ``munge`` (``make slurm``).

    with SlurmCluster(tmp_path) as cluster:     # raises SlurmUnavailable with a reason
        env = cluster.env()                      # os.environ with SLURM_CONF set

Run ``python tests/slurm_cluster.py`` to start one by hand and keep it until Ctrl-C.
"""

from __future__ import annotations

import os
import re
import shutil
import signal
import socket
import subprocess
import time
from pathlib import Path

DAEMONS = ("munged", "slurmctld", "slurmd", "sinfo", "sbatch", "squeue", "scancel", "srun")
NODE = "vslnode"
PARTITION = "debug"


class SlurmUnavailable(RuntimeError):
    """SLURM cannot be started here (the message says why)."""


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _tail(path: Path, lines: int = 8) -> str:
    try:
        text = path.read_text(errors="replace").splitlines()[-lines:]
    except OSError:
        return f"{path.name}: (no log)"
    return f"{path.name}: " + " | ".join(line.strip() for line in text)


def missing_binaries() -> list[str]:
    return [name for name in DAEMONS if shutil.which(name) is None]


def _node_config() -> dict[str, str]:
    """This machine's CPUs, cores and memory as ``slurmd -C`` reports them."""
    out = subprocess.run(["slurmd", "-C"], capture_output=True, text=True, timeout=30).stdout
    fields = dict(re.findall(r"(\w+)=(\S+)", out.splitlines()[0] if out else ""))
    keep = ("CPUs", "Boards", "SocketsPerBoard", "CoresPerSocket", "ThreadsPerCore", "RealMemory")
    return {key: fields[key] for key in keep if key in fields}


class SlurmCluster:
    """munged + slurmctld + slurmd on 127.0.0.1, all files under ``folder``."""

    def __init__(self, folder: str | os.PathLike[str], *, timeout_s: float = 60.0) -> None:
        self.folder = Path(folder)
        self.timeout_s = timeout_s
        self.pids: dict[str, int] = {}
        self.conf = self.folder / "etc" / "slurm.conf"
        self.log = self.folder / "log"
        self.node = _node_config() if shutil.which("slurmd") else {}

    # -- files ---------------------------------------------------------------------------

    def _write_files(self) -> None:
        for sub in ("etc", "state", "spool", "log", "run", "munge"):
            (self.folder / sub).mkdir(parents=True, exist_ok=True)
        munge = self.folder / "munge"
        munge.chmod(0o755)  # munged wants its socket's folder reachable by all
        key = munge / "munge.key"
        if not key.exists():
            key.write_bytes(os.urandom(1024))
        key.chmod(0o400)
        node = " ".join(f"{k}={v}" for k, v in self.node.items())
        run, log = self.folder / "run", self.log
        self.conf.write_text(
            "\n".join([
                "ClusterName=vsltest",
                "SlurmctldHost=localhost(127.0.0.1)",
                f"SlurmctldPort={_free_port()}",
                f"SlurmdPort={_free_port()}",
                "SlurmUser=root",
                "SlurmdUser=root",
                "AuthType=auth/munge",
                "CredType=cred/munge",
                f"AuthInfo=socket={munge / 'munge.socket'}",
                f"StateSaveLocation={self.folder / 'state'}",
                f"SlurmdSpoolDir={self.folder / 'spool'}",
                f"SlurmctldPidFile={run / 'slurmctld.pid'}",
                f"SlurmdPidFile={run / 'slurmd.pid'}",
                f"SlurmctldLogFile={log / 'slurmctld.log'}",
                f"SlurmdLogFile={log / 'slurmd.log'}",
                "SlurmctldDebug=info",
                "SlurmdDebug=info",
                "ProctrackType=proctrack/linuxproc",
                "TaskPlugin=task/none",
                "AccountingStorageType=accounting_storage/none",
                "JobAcctGatherType=jobacct_gather/none",
                "JobCompType=jobcomp/none",
                "SchedulerType=sched/backfill",
                "SelectType=select/cons_tres",
                "SelectTypeParameters=CR_Core",
                "MpiDefault=none",
                "ReturnToService=2",
                "SlurmctldTimeout=30",
                "SlurmdTimeout=30",
                "InactiveLimit=0",
                "KillWait=5",
                "MinJobAge=300",
                f"NodeName={NODE} NodeAddr=127.0.0.1 NodeHostname=localhost {node} State=UNKNOWN",
                f"PartitionName={PARTITION} Nodes={NODE} Default=YES MaxTime=INFINITE State=UP",
                "",
            ])
        )  # fmt: skip

    def env(self) -> dict[str, str]:
        """``os.environ`` with this cluster's ``SLURM_CONF``."""
        return {**os.environ, "SLURM_CONF": str(self.conf)}

    # -- daemons -------------------------------------------------------------------------

    def _spawn(self, name: str, argv: list[str], pid_file: Path) -> None:
        out = subprocess.run(argv, env=self.env(), capture_output=True, text=True, timeout=30)
        deadline = time.monotonic() + 10
        pid = None
        while pid is None and time.monotonic() < deadline:  # the file is written after it exists
            text = pid_file.read_text().split() if pid_file.exists() else []
            pid = int(text[0]) if text and text[0].isdigit() else None
            if pid is None:
                time.sleep(0.1)
        if out.returncode != 0 or pid is None:
            raise SlurmUnavailable(
                f"{name} did not start (exit {out.returncode}: {out.stderr.strip()[-300:]}); "
                + self.log_tails()
            )
        self.pids[name] = pid

    def log_tails(self) -> str:
        return "; ".join(
            _tail(self.log / f"{name}.log") for name in ("munged", "slurmctld", "slurmd")
        )

    def start(self) -> SlurmCluster:
        if os.geteuid() != 0:
            raise SlurmUnavailable("starting slurmd and munged needs root")
        missing = missing_binaries()
        if missing:
            raise SlurmUnavailable(f"missing {', '.join(missing)} (install with `make slurm`)")
        self._write_files()
        munge, run = self.folder / "munge", self.folder / "run"
        try:
            self._spawn("munged", [
                "munged", "--force", f"--key-file={munge / 'munge.key'}",
                f"--socket={munge / 'munge.socket'}", f"--pid-file={run / 'munged.pid'}",
                f"--log-file={self.log / 'munged.log'}", f"--seed-file={munge / 'munged.seed'}",
            ], run / "munged.pid")  # fmt: skip
            self._spawn("slurmctld", ["slurmctld", "-i"], run / "slurmctld.pid")
            self._spawn("slurmd", ["slurmd", "-N", NODE], run / "slurmd.pid")
            self._wait_idle()
        except BaseException:
            self.stop()
            raise
        return self

    def _wait_idle(self) -> None:
        """Wait until the node is idle (registered and schedulable)."""
        deadline = time.monotonic() + self.timeout_s
        state = ""
        while time.monotonic() < deadline:
            out = subprocess.run(
                ["sinfo", "-h", "-N", "-o", "%t"], env=self.env(), capture_output=True, text=True,
                timeout=30,
            )  # fmt: skip
            state = (out.stdout or out.stderr).strip()
            if state == "idle":
                return
            for name, pid in self.pids.items():
                if not _alive(pid):
                    raise SlurmUnavailable(f"{name} exited; " + self.log_tails())
            time.sleep(0.5)
        raise SlurmUnavailable(
            f"node not idle after {self.timeout_s:.0f} s (sinfo: {state!r}); " + self.log_tails()
        )

    def stop(self) -> None:
        """Stop the daemons by their pids (slurmd, slurmctld, munged), SIGKILL after 10 s."""
        for name in ("slurmd", "slurmctld", "munged"):
            pid = self.pids.pop(name, None)
            if pid is None:
                continue
            try:
                os.kill(pid, signal.SIGTERM)
            except ProcessLookupError:
                continue
            deadline = time.monotonic() + 10
            while _alive(pid) and time.monotonic() < deadline:
                time.sleep(0.1)
            if _alive(pid):
                os.kill(pid, signal.SIGKILL)

    def __enter__(self) -> SlurmCluster:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    # a zombie (our exited child) counts as gone
    try:
        return Path(f"/proc/{pid}/stat").read_text().split(") ")[1][0] != "Z"
    except (OSError, IndexError):
        return False


if __name__ == "__main__":  # pragma: no cover
    import sys
    import tempfile

    folder = Path(sys.argv[1]) if len(sys.argv) > 1 else Path(tempfile.mkdtemp(prefix="slurm-"))
    signal.signal(signal.SIGTERM, signal.default_int_handler)  # `kill` stops the daemons too
    with SlurmCluster(folder) as cluster:
        print(f"export SLURM_CONF={cluster.conf}   # Ctrl-C stops the daemons", flush=True)
        try:
            signal.pause()
        except KeyboardInterrupt:
            pass
