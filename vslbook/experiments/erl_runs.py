"""Run directories for the episode-based experiments of Chapters 3 and 4.

:func:`open_run` is :func:`vslbook.run_open.open_run` with the code scope of an
episode-based run: its recorded code fingerprint leaves out ``srl/``, which no
episode-based run can reach. The directory comes back locked; the lock is released when
the run directory object is dropped, or by ``rd.release()``.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from vslbook.erl.svsl import CODE_EXCLUDE
from vslbook.results import RunDir
from vslbook.run_open import open_run as _open_locked

__all__ = ["CODE_EXCLUDE", "open_run"]


def open_run(root: str | Path, record: dict[str, Any]) -> RunDir:
    """The run directory of ``record`` under ``root``: locked, new, resumable, or redone if
    stale (:func:`vslbook.run_open.open_run`)."""
    return _open_locked(root, record, code_exclude=CODE_EXCLUDE)
