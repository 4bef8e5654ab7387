"""Figure files: where figures are saved (:func:`figures_dir`), saving them without dates in
their metadata (:func:`save_figure`), and the layout file beside each
(:func:`figure_layout`: panels per row and the size a notebook shows), which the site's
browser test checks rendered widths against. Re-exported by :mod:`vslbook.plots`.
"""

from __future__ import annotations

import hashlib
import io
import json
import os
import re
import struct
import tempfile
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import matplotlib as mpl
from matplotlib.figure import Figure

from vslbook.budget import get_budget

__all__ = ["FIGURES_ENV_VAR", "LAYOUT_SUFFIX", "figure_layout", "figures_dir", "save_figure"]

FIGURES_ENV_VAR = "VSLBOOK_FIGURES"
LAYOUT_SUFFIX = ".layout.json"
_REPO_ROOT = Path(__file__).resolve().parents[1]
_FIGURE_ID = re.compile(r"[A-Za-z0-9_-][A-Za-z0-9._-]*")



def figures_dir() -> Path:
    """Where figures are saved: ``$VSLBOOK_FIGURES`` if set, else ``build/figures``."""
    env = os.environ.get(FIGURES_ENV_VAR)
    if env:
        return Path(env).expanduser()
    return _REPO_ROOT / "build" / "figures"


def save_figure(
    fig: Figure,
    figure_id: str,
    formats: Sequence[str] = ("png", "pdf"),
    out_dir: str | Path | None = None,
) -> list[Path]:
    """Save ``fig`` as ``<out_dir or figures_dir()>/<figure_id>.<fmt>``; return the paths.

    ``figure_id`` may contain letters, digits, ``-``, ``_`` and ``.`` (not leading).
    File metadata carries no creation date, so the same figure gives the same file.
    Beside them goes ``<figure_id>.layout.json`` (:func:`figure_layout`: panels per row and
    the size shown in a notebook), which the site's browser test checks widths against.
    """
    if not isinstance(figure_id, str) or not _FIGURE_ID.fullmatch(figure_id):
        raise ValueError(
            f"figure_id {figure_id!r} is not valid; expected letters, digits, '-', '_' "
            "or '.' (not leading), e.g. 'fig5-3_dog_run'"
        )
    allowed = {"png", "pdf", "svg"}
    bad = [f for f in formats if f not in allowed]
    if bad or not formats:
        raise ValueError(f"formats {list(formats)}: expected some of {sorted(allowed)}")
    out = Path(out_dir) if out_dir is not None else figures_dir()
    out.mkdir(parents=True, exist_ok=True)
    metadata = {"png": {"Software": None}, "pdf": {"CreationDate": None}, "svg": {"Date": None}}
    paths = []
    for fmt in formats:
        path = out / f"{figure_id}.{fmt}"
        fig.savefig(path, format=fmt, metadata=metadata[fmt])
        paths.append(path)
    _write_atomically(out / f"{figure_id}{LAYOUT_SUFFIX}",
                      json.dumps(figure_layout(fig, figure_id), indent=1) + "\n")
    return paths


def figure_layout(fig: Figure, figure_id: str = "") -> dict[str, Any]:
    """How ``fig`` is laid out and how large a notebook shows it (what ``save_figure``
    writes to ``<figure_id>.layout.json``, which the site's browser test reads).

    ``panels_per_row``: the most panels side by side, over the axes placed on the figure's
    grid (colorbars, insets and twin axes are not panels). ``width_px``/``height_px`` and
    ``png_sha256``: the picture Jupyter's inline backend draws of it (the tight box at the
    figure's dpi), which is the image on the site (MyST-NB names it by that hash);
    ``budget``: the active budget; ``inline``: whether the figure was drawn under the
    inline backend (so it is shown on a page).
    """
    buf = io.BytesIO()   # as IPython's print_figure draws it for the inline backend
    fig.canvas.print_figure(buf, format="png", dpi=fig.dpi, bbox_inches="tight",
                            facecolor=fig.get_facecolor(), edgecolor=fig.get_edgecolor())
    png = buf.getvalue()
    width_px, height_px = struct.unpack(">II", png[16:24])  # the PNG's IHDR
    try:
        budget: str | None = get_budget().name
    except ValueError:
        budget = None
    return {
        "id": figure_id,
        "budget": budget,
        "inline": "inline" in mpl.get_backend(),
        "panels_per_row": _panels_per_row(fig),
        "dpi": float(fig.dpi),
        "width_in": round(width_px / fig.dpi, 3),
        "height_in": round(height_px / fig.dpi, 3),
        "width_px": width_px,
        "height_px": height_px,
        "png_sha256": hashlib.sha256(png).hexdigest(),
    }


def _panels_per_row(fig: Figure) -> int:
    """The most grid axes that a horizontal line through one of them crosses."""
    # boxes on the whole figure (subfigures included); twin axes share one box
    boxes = {(round(b.x0, 1), round(b.x1, 1), b.y0, b.y1)
             for b in (ax.bbox for ax in fig.axes
                       if ax.get_subplotspec() is not None and ax.get_visible()
                       and ax.get_label() != "<colorbar>")}
    rows = [{(x0, x1) for x0, x1, y0, y1 in boxes if y0 < (b[2] + b[3]) / 2 < y1}
            for b in boxes]
    return max((len(r) for r in rows), default=0)


def _write_atomically(path: Path, text: str) -> None:
    """Write ``text`` to ``path`` through a temporary file: a reader never sees half of it."""
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "w") as f:
            f.write(text)
        os.chmod(tmp, 0o644)  # as the figure files beside it (mkstemp makes it private)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
