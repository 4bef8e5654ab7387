"""Where and with what code a run was made: git sha, dirty flag, code fingerprint, versions.

:func:`code_fingerprint` names the code that produced a run independently of git; it is
what :attr:`vslbook.results.RunDir.code_matches` compares, so a finished run is reused only
by the code that made it. ``env.json`` records :func:`environment` next to it.
"""

from __future__ import annotations

import functools
import hashlib
import platform
import re
import socket
import subprocess
import sys
from datetime import UTC, datetime
from importlib import metadata
from pathlib import Path
from typing import Any

__all__ = [
    "NOT_RUN_CODE", "RUN_EXPERIMENTS", "TRACKED_PACKAGES", "code_fingerprint", "environment",
    "package_fingerprint",
]  # fmt: skip

#: distributions whose versions go into ``env.json`` (import name -> distribution name)
TRACKED_PACKAGES = {
    "vslbook": "vslbook",
    "torch": "torch",
    "numpy": "numpy",
    "gymnasium": "gymnasium",
    "mujoco": "mujoco",
    "dm_control": "dm-control",
}
_REPO_ROOT = Path(__file__).resolve().parents[1]


def _git_sha() -> str | None:
    try:
        out = subprocess.run(
            ["git", "rev-parse", "HEAD"],
            cwd=_REPO_ROOT,
            capture_output=True,
            text=True,
            timeout=5,
            check=False,
        )
    except (OSError, subprocess.SubprocessError):
        return None
    sha = out.stdout.strip()
    return sha if out.returncode == 0 and re.fullmatch(r"[0-9a-f]{40}", sha) else None


def _git_dirty() -> bool | None:
    """True when the work tree has uncommitted changes (None outside a git checkout)."""
    try:
        out = subprocess.run(
            ["git", "status", "--porcelain", "--untracked-files=no"],
            cwd=_REPO_ROOT, capture_output=True, text=True, timeout=5, check=False,
        )  # fmt: skip
    except (OSError, subprocess.SubprocessError):
        return None
    return bool(out.stdout.strip()) if out.returncode == 0 else None


#: Package paths no training run reads: analysis, figures and the notebooks' numerical checks;
#: and ``progress.py``, which training loops call only to show their progress bars.
#: Editing them never makes a run stale (:func:`code_fingerprint`). ``experiments/`` holds
#: both analysis and run code; the modules of it that runs execute are
#: :data:`RUN_EXPERIMENTS` and count as run code.
NOT_RUN_CODE: tuple[str, ...] = (
    "bounds/", "data.py", "experiments/", "figures.py", "plot_style.py", "plots.py",
    "progress.py", "stats.py",
)  # fmt: skip

#: The modules of ``experiments/`` that training runs execute: the run loops of Chapters 3
#: and 4 and what they call (the figures' counts and presets, the test contexts, the entropy
#: probes, Fig. 3.2e/f's final grid). Editing one of them can change what a run logs, so
#: they are part of :func:`code_fingerprint`. ``tests/test_run_guards.py`` trains smoke
#: runs of every algorithm family in a fresh process and checks that each module of
#: ``experiments/`` it loaded is listed here.
RUN_EXPERIMENTS: tuple[str, ...] = tuple(
    f"experiments/{name}.py"
    for name in (
        "ch3_algorithms", "ch4_algorithms", "diskill_runs", "svsl_beer_pong", "svsl_context",
        "svsl_mixtures", "svsl_planar", "svsl_reacher", "svsl_table_tennis",
        "svsl_table_tennis_4d",
    )
)  # fmt: skip


def code_fingerprint(exclude: tuple[str, ...] | list[str] = ()) -> str:
    """sha256 over the package's Python sources (relative path and bytes of each file).

    It names the code that produced a run independently of git: an uncommitted edit
    changes it, a commit that touches only notebooks or docs does not. Files under
    ``exclude`` (package-relative prefixes such as ``"erl/"``: code an algorithm's runs
    cannot reach, declared by the algorithm's registry entry) are left out, so adding
    Chapter 3 code does not make Chapter 5 runs stale; so are those under
    :data:`NOT_RUN_CODE`, except the run code of :data:`RUN_EXPERIMENTS`. Computed once
    per process and scope, so it names the code this process loaded, even if files change
    on disk later.
    """
    return package_fingerprint(Path(__file__).resolve().parent, tuple(sorted(set(exclude))))


@functools.lru_cache(maxsize=16)
def package_fingerprint(package: Path, exclude: tuple[str, ...] = ()) -> str:
    """:func:`code_fingerprint` of the package at ``package`` (a copy of ``vslbook/``)."""
    digest = hashlib.sha256()
    for path in sorted(package.rglob("*.py")):
        rel = path.relative_to(package).as_posix()
        if rel.startswith(exclude) or (
            rel.startswith(NOT_RUN_CODE) and rel not in RUN_EXPERIMENTS
        ):
            continue
        digest.update(rel.encode("utf-8") + b"\0")
        digest.update(path.read_bytes() + b"\0")
    return digest.hexdigest()


def _cpu() -> str:
    """The CPU model and the SIMD extensions NumPy found on it, e.g. ``"AMD EPYC (NumPy
    SIMD: X86_V3, X86_V4, AVX512_ICL)"``: the same code rounds differently on another CPU
    (:data:`vslbook.replay.RTOL`), so a run's ``env.json`` says which one it ran on."""
    import numpy as np

    model = platform.processor() or platform.machine()
    try:
        with open("/proc/cpuinfo", encoding="utf-8") as f:
            model = next((line.split(":", 1)[1].strip() for line in f
                          if line.startswith("model name")), model)  # fmt: skip
    except OSError:
        pass
    try:
        simd = np.show_config(mode="dicts")["SIMD Extensions"]["found"]
    except (KeyError, TypeError, ValueError):
        simd = []
    return f"{model} (NumPy SIMD: {', '.join(simd)})" if simd else model


def environment(code_exclude: tuple[str, ...] = ()) -> dict[str, Any]:
    """What ``env.json`` records: where and with what a run was started."""
    versions: dict[str, str | None] = {}
    for name, dist in TRACKED_PACKAGES.items():
        try:
            versions[name] = metadata.version(dist)
        except metadata.PackageNotFoundError:
            versions[name] = None
    return {
        "python": sys.version.split()[0],
        "platform": platform.platform(),
        "cpu": _cpu(),
        "hostname": socket.gethostname(),
        "packages": versions,
        "git_sha": _git_sha(),
        "git_dirty": _git_dirty(),
        "code_hash": code_fingerprint(code_exclude),
        "code_excluded": sorted(code_exclude),
        "timestamp": datetime.now(UTC).isoformat(timespec="seconds"),
    }
