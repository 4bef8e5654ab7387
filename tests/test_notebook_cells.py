"""Every code cell of a chapter stays short: library code lives in the package.

The notebooks are jupytext percent files: a cell starts at a line beginning with ``# %%``,
a markdown cell at ``# %% [markdown]``. A code cell of more than ``MAX_LINES`` non-blank
lines fails, naming the notebook, the line of its ``# %%`` marker and its length.
"""

from __future__ import annotations

from pathlib import Path

import pytest

NOTEBOOKS = sorted((Path(__file__).resolve().parents[1] / "notebooks").glob("[0-9][0-9]_*.py"))
MAX_LINES = 30


def code_cells(text: str) -> list[tuple[int, int]]:
    """(1-based line of the cell marker, non-blank lines) of every code cell of ``text``."""
    lines = text.splitlines()
    starts = [i for i, line in enumerate(lines) if line.startswith("# %%")]
    cells = []
    for k, start in enumerate(starts):
        end = starts[k + 1] if k + 1 < len(starts) else len(lines)
        marker = lines[start][len("# %%") :]
        if "[markdown]" in marker or "[md]" in marker:
            continue
        cells.append((start + 1, sum(1 for line in lines[start + 1 : end] if line.strip())))
    return cells


def test_cell_parser_counts_code_cells_only():
    text = "# %% [markdown]\n# text\n# more\n\n# %%\nx = 1\n\ny = 2\n# %% tags=['a']\nz = 3\n"
    assert code_cells(text) == [(5, 2), (9, 1)]


def test_notebooks_found():
    assert len(NOTEBOOKS) >= 6


@pytest.mark.parametrize("notebook", NOTEBOOKS, ids=lambda p: p.name)
def test_code_cells_are_short(notebook: Path):
    long = [(line, n) for line, n in code_cells(notebook.read_text()) if n > MAX_LINES]
    assert not long, "; ".join(
        f"{notebook.name}: the code cell at line {line} has {n} non-blank lines "
        f"(at most {MAX_LINES})"
        for line, n in long
    )
