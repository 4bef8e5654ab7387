"""Layout checks of the book site's pages, measured in the browser (``test_book_site.py``).

* Output images: each is shown at ``min(natural width, column width)``, the column being
  the content box of its ``.cell_output`` (the width ``max-width: 100%`` of
  ``book/_static/vslbook.css`` refers to); nothing else shrinks or stretches it.
* Figures: every figure that :func:`vslbook.plots.save_figure` saved during the build has a
  ``<id>.layout.json`` beside it (:func:`vslbook.plots.figure_layout`: panels per row, the
  size and sha256 of the picture a notebook shows). Its image on the site is the file named
  by that hash (MyST-NB's naming), else one of that natural size; a panel is ``rendered
  width / panels per row`` wide, and must be at least :data:`MIN_PANEL_PX` with at most
  :data:`MAX_PANELS_PER_ROW` panels per row.
* Displayed equations (``mjx-container[display="true"]``): the formula lies inside its
  column (the article's content box, or its cell output's), or the equation or an ancestor
  inside the column scrolls horizontally (``overflow-x: auto | scroll``) to all of it. A
  formula that is wider is cut off (or runs over the sidebar): the message names the page,
  the equation's anchor and its TeX.
"""

from __future__ import annotations

import json
from pathlib import Path

from vslbook.figure_files import LAYOUT_SUFFIX

#: A desktop browser window. The theme caps the page at 88rem (1408 px), so a wider window
#: does not widen the columns: with both sidebars shown the article's text, and an output,
#: are 790 px wide; a cell tagged ``full-width`` runs into the right margin (1075 px).
VIEWPORT = {"width": 1440, "height": 900}
MIN_PANEL_PX = 400
MAX_PANELS_PER_ROW = 3
_SLACK_PX = 1.0   # sub-pixel rounding of the layout

# Each output image shown (not in a collapsed output): its natural size, its rendered
# width and the content width of its cell output (the column it may fill).
OUTPUT_IMAGES = """() => Array.from(document.querySelectorAll('.cell_output img'))
    .filter(img => img.getClientRects().length > 0).map(img => {
  const out = img.closest('.cell_output'), s = getComputedStyle(out);
  return {src: (img.currentSrc || img.src).split('/').pop(),
          natural_w: img.naturalWidth, natural_h: img.naturalHeight,
          width: img.getBoundingClientRect().width,
          column: out.clientWidth - parseFloat(s.paddingLeft) - parseFloat(s.paddingRight)};
})"""

# Each displayed equation: its TeX (MathJax keeps the source of what it typeset), the
# nearest anchor, the formula's extent (all its boxes: a tagged equation's own box is the
# column's width whatever its content), its column's content box, and whether the equation
# or an ancestor inside the column scrolls horizontally to all of it (content overflowing
# a scroller's left edge cannot be scrolled to).
EQUATIONS = """() => {
  const tex = new Map();
  for (const item of MathJax.startup.document.math)
    if (item.display && item.typesetRoot) tex.set(item.typesetRoot, item.math);
  const content = e => { const r = e.getBoundingClientRect(), s = getComputedStyle(e);
    return [r.left + e.clientLeft + parseFloat(s.paddingLeft),
            r.left + e.clientLeft + e.clientWidth - parseFloat(s.paddingRight)]; };
  return Array.from(document.querySelectorAll('mjx-container[display="true"]')).map(eq => {
    const col = eq.closest('.cell_output') || eq.closest('article') || document.body;
    const [colLeft, colRight] = content(col);
    let left = Infinity, right = -Infinity;
    for (const e of eq.querySelectorAll('*')) {
      const r = e.getBoundingClientRect();
      if (r.width > 0) { left = Math.min(left, r.left); right = Math.max(right, r.right); }
    }
    let scrolls = false;
    for (let e = eq; e && e !== col && !scrolls; e = e.parentElement) {
      const r = e.getBoundingClientRect();
      scrolls = ['auto', 'scroll'].includes(getComputedStyle(e).overflowX)
        && r.left >= colLeft - 1 && r.right <= colRight + 1 && left >= r.left - 1;
    }
    const block = eq.closest('div.math') || eq, prev = block.previousElementSibling;
    const anchor = (prev && prev.id.startsWith('eq-') && prev.id) || block.id
      || (eq.closest('[id]') || {id: ''}).id;
    return {tex: tex.get(eq) || '', anchor, left, right, col_left: colLeft,
            col_right: colRight, scrolls};
  });
}"""


def load_layouts(folder: Path, budget: str) -> list[dict]:
    """The figure layouts ``save_figure`` wrote to ``folder`` at ``budget``, by id."""
    layouts = (json.loads(p.read_text()) for p in folder.glob(f"*{LAYOUT_SUFFIX}"))
    return sorted((lay for lay in layouts if lay.get("budget") == budget),
                  key=lambda lay: lay["id"])


def image_problems(page: str, images: list[dict]) -> list[str]:
    """Output images shown at another width than ``min(natural, column)``."""
    problems = []
    for img in images:
        if not img["natural_w"]:
            continue   # not loaded: reported by the page check
        expected = min(img["natural_w"], img["column"])
        if abs(img["width"] - expected) > _SLACK_PX:
            problems.append(
                f"{page}: image {img['src'][:16]}... ({img['natural_w']} px wide) is shown at "
                f"{img['width']:.0f} px, expected {expected:.0f} px (natural width, at most "
                f"the {img['column']:.0f} px column)")
    return problems


def figure_problems(layouts: list[dict], shown: list[tuple[str, dict]]) -> list[str]:
    """Saved figures too crowded as rendered; ``shown`` holds ``(page, image)`` pairs.

    A figure is its image file (named by the PNG's sha256), else an image of its natural
    size (a figure changed after it was saved): two figures of one size render at one width,
    so either measures the same panels.
    """
    problems = []
    for lay in layouts:
        match = ([(page, img) for page, img in shown
                  if img["src"].split(".")[0] == lay.get("png_sha256")]
                 or [(page, img) for page, img in shown
                     if abs(img["natural_w"] - lay["width_px"]) <= 1
                     and abs(img["natural_h"] - lay["height_px"]) <= 1])
        if not match:
            if lay["inline"]:   # drawn in a notebook kernel, so it should be on a page
                problems.append(
                    f"figure {lay['id']} ({lay['width_px']}x{lay['height_px']} px) is shown "
                    f"on no page: its {lay['id']}{LAYOUT_SUFFIX} is left from an older build?")
            continue
        page, img = match[0]
        n = lay["panels_per_row"]
        panel = img["width"] / max(n, 1)
        if n > MAX_PANELS_PER_ROW or panel < MIN_PANEL_PX - _SLACK_PX:
            problems.append(
                f"{page}: figure {lay['id']}: {n} panels per row, {panel:.0f} px each as "
                f"rendered (image {lay['width_px']} px wide shown at {img['width']:.0f} px in "
                f"a {img['column']:.0f} px column); needs at most {MAX_PANELS_PER_ROW} per "
                f"row of at least {MIN_PANEL_PX} px")
    return problems


def equation_problems(page: str, equations: list[dict]) -> list[str]:
    """Displayed equations wider than their column that do not scroll (cut off or spilling)."""
    problems = []
    for eq in equations:
        fits = (eq["left"] >= eq["col_left"] - _SLACK_PX
                and eq["right"] <= eq["col_right"] + _SLACK_PX)
        if fits or eq["scrolls"]:
            continue
        where = f"#{eq['anchor']}" if eq["anchor"] else "(no anchor)"
        tex = " ".join(eq["tex"].split())
        problems.append(
            f"{page}: equation {where} is {eq['right'] - eq['left']:.0f} px wide in a "
            f"{eq['col_right'] - eq['col_left']:.0f} px column, without a horizontal "
            f"scrollbar: {tex[:120]}{'...' if len(tex) > 120 else ''}")
    return problems
