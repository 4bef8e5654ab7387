"""Run directories for the episode-based experiments of Chapters 3 and 4.

:func:`open_run` creates (or reopens, to resume) a run directory for an episode-based
algorithm and applies the stale-run rule of :func:`vslbook.training.run`: a run made by
other code is moved to ``root/_stale`` and started afresh (``$VSLBOOK_REUSE_STALE=1``
reuses it with a warning). The recorded code fingerprint leaves out ``srl/``, which no
episode-based run can reach.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from vslbook.erl.svsl import CODE_EXCLUDE
from vslbook.results import RunDir
from vslbook.training import _stale

__all__ = ["CODE_EXCLUDE", "open_run"]


def open_run(root: str | Path, record: dict[str, Any]) -> RunDir:
    """The run directory of ``record`` under ``root``, new, resumable, or redone if stale."""
    rd = RunDir.create(root, record, code_exclude=CODE_EXCLUDE)
    if not rd.code_matches:
        rd = _stale(rd, root, record, None, CODE_EXCLUDE)
    return rd
