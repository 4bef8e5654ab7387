"""Build the vslbook site: ``python book/build.py [--budget B]`` (what ``make book`` runs).

1. Stage the sources in ``build/book-src/``: the jupytext notebooks of ``notebooks/`` as
   ``.ipynb`` (``00_index`` becomes the landing page ``index``, with the table of contents
   appended),
   the pages of ``book/`` and a MathJax 3 copy, so the site typesets math offline.
2. Run Sphinx (MyST-NB, sphinx-book-theme) into ``build/site/`` (``build/site-<budget>/``
   for a budget other than ``reduced``). Each notebook executes at the budget through a
   jupyter-cache store of that budget (``build/book-cache/<budget>``): a notebook whose
   code has not changed is not executed again.
3. Print the page to open.

A failing check inside a notebook fails the build (``nb_execution_raise_on_error``), and
so does any Sphinx warning (``-W``).

The notebooks execute with ``VSLBOOK_PROGRESS=summary`` (:mod:`vslbook.progress`; ``off``
is kept if set): a static page cannot redraw a progress bar, so each run set prints one
plain line when it ends instead of bars frozen at ``0%``. MyST-NB's jupyter-cache executor
starts each kernel with this process's environment, so the kernels see the mode. The cache
key is the notebooks' code only, so a cache stamped with another output format
(:data:`CACHE_FORMAT`, e.g. outputs executed with live bars) is emptied once.
"""

from __future__ import annotations

import argparse
import filecmp
import os
import shutil
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
BOOK = ROOT / "book"
BUDGETS = ("smoke", "reduced", "full")
# Pages of book/ that are part of the site, after the chapter notebooks.
EXTRA_PAGES = ("bibliography.md",)
# The MathJax files the site serves: the TeX-to-CHTML component, the extensions it loads
# on demand, and its web fonts.
MATHJAX_PARTS = ("tex-chtml.js", "input/tex/extensions", "output/chtml/fonts/woff-v2",
                 "ui", "a11y", "adaptors")
#: How the cached outputs were made (bumped when the kernels' environment changes what a
#: notebook prints): a cache without this stamp is emptied before the build.
CACHE_FORMAT = "progress=summary"
CACHE_STAMP = "vslbook-cache-format.txt"


def site_dir(budget: str) -> Path:
    """Where the site of ``budget`` is written."""
    return ROOT / "build" / ("site" if budget == "reduced" else f"site-{budget}")


def find_mathjax() -> Path:
    """The ``es5`` folder of an installed MathJax 3 (``make setup`` installs it with npm)."""
    candidates = [os.environ.get("VSLBOOK_MATHJAX", ""),
                  ROOT / ".venv" / "mathjax" / "node_modules" / "mathjax" / "es5"]
    for cand in candidates:
        if cand and (Path(cand) / "tex-chtml.js").is_file():
            return Path(cand)
    raise FileNotFoundError(
        f"MathJax 3 not found (looked in {[str(c) for c in candidates if c]}); expected the "
        "es5/ folder of the npm package mathjax@3: run `make setup`, or set VSLBOOK_MATHJAX")


def _sync(src: Path, dst: Path) -> None:
    """Copy ``src`` to ``dst`` only if the content differs (Sphinx rebuilds by mtime)."""
    if dst.exists() and filecmp.cmp(src, dst, shallow=False):
        return
    dst.parent.mkdir(parents=True, exist_ok=True)
    shutil.copy2(src, dst)


def chapter_notebooks() -> list[Path]:
    """The book's notebooks in reading order (``NN_name.py``)."""
    return sorted(p for p in (ROOT / "notebooks").glob("[0-9][0-9]_*.py"))


def _write_if_changed(path: Path, text: str) -> None:
    if not path.exists() or path.read_text() != text:
        path.write_text(text)


def stage(src: Path) -> list[str]:
    """Write the Sphinx source tree into ``src``; return the documents in reading order.

    Each jupytext notebook becomes the ``.ipynb`` that ``make notebooks`` would write, so a
    link such as ``[Chapter 5](05_dime.ipynb)`` works the same in Jupyter and on the site.
    """
    import jupytext
    import nbformat

    src.mkdir(parents=True, exist_ok=True)
    notebooks = chapter_notebooks()
    if not notebooks or notebooks[0].stem != "00_index":
        raise FileNotFoundError(f"expected notebooks/00_index.py first, found {notebooks[:1]}")
    docs = [nb.stem for nb in notebooks[1:]] + [Path(p).stem for p in EXTRA_PAGES]
    wanted = {*EXTRA_PAGES, "references.bib"}
    for nb_path in notebooks:
        nb = jupytext.read(nb_path)
        name = "index" if nb_path == notebooks[0] else nb_path.stem
        if name == "index":   # the site's table of contents, invisible in Jupyter
            toc = "\n".join(["```{toctree}", ":hidden:", ":maxdepth: 2", "", *docs, "```"])
            nb.cells.append(nbformat.v4.new_markdown_cell(toc))
        _write_if_changed(src / f"{name}.ipynb", jupytext.writes(nb, fmt="ipynb"))
        wanted.add(f"{name}.ipynb")
    for page in EXTRA_PAGES + ("references.bib",):
        _sync(BOOK / page, src / page)
    for stale in src.glob("*"):
        if stale.is_file() and stale.name not in wanted:
            stale.unlink()
    return ["index", *docs]


def stage_static(static: Path) -> None:
    """The MathJax subset, served from the site's ``_static/mathjax``."""
    es5 = find_mathjax()
    target = static / "mathjax"
    for part in MATHJAX_PARTS:
        p = es5 / part
        if p.is_file():
            _sync(p, target / part)
        else:
            for f in p.rglob("*"):
                if f.is_file():
                    _sync(f, target / part / f.relative_to(p))


def progress_mode_for_site() -> str:
    """``$VSLBOOK_PROGRESS`` for the executed notebooks: ``summary`` (``off`` if so set)."""
    return "off" if os.environ.get("VSLBOOK_PROGRESS", "").strip().lower() == "off" else "summary"


def prepare_cache(cache: Path) -> None:
    """Empty ``cache`` if its outputs were made in another format (:data:`CACHE_FORMAT`)."""
    stamp = cache / CACHE_STAMP
    if cache.exists() and any(cache.iterdir()):
        if stamp.is_file() and stamp.read_text().strip() == CACHE_FORMAT:
            return
        print(f"{cache}: its outputs predate {CACHE_FORMAT!r} (e.g. progress bars frozen on "
              "the page); emptied, every notebook executes again (finished runs are reused)")
        shutil.rmtree(cache)
    cache.mkdir(parents=True, exist_ok=True)
    stamp.write_text(CACHE_FORMAT + "\n")


def build(budget: str, *, quiet: bool = False) -> Path:
    """Build the site of ``budget``; return its landing page."""
    if budget not in BUDGETS:
        raise ValueError(f"budget {budget!r} is not one of {BUDGETS}")
    from sphinx.cmd.build import build_main

    work = ROOT / "build" / "book-src"
    src, static = work / budget / "src", work / budget / "static"
    stage(src)
    stage_static(static)
    out = site_dir(budget)
    os.environ["VSLBOOK_BUDGET"] = budget
    os.environ["VSLBOOK_BOOK_STATIC"] = str(static)
    cache = ROOT / "build" / "book-cache" / budget
    prepare_cache(cache)
    os.environ["VSLBOOK_BOOK_CACHE"] = str(cache)
    # one plain line per run set instead of progress bars frozen on the page
    os.environ["VSLBOOK_PROGRESS"] = progress_mode_for_site()
    os.environ.setdefault("VSLBOOK_BOOK_TIMEOUT", "2400" if budget == "smoke" else "-1")
    os.environ.setdefault("VSLBOOK_FIGURES", str(ROOT / "build" / "figures"))
    # The kernels draw inline (figures become page images), whatever a caller exported for
    # headless scripts (the Makefile exports MPLBACKEND=Agg for the tests).
    os.environ["MPLBACKEND"] = "module://matplotlib_inline.backend_inline"
    os.environ.setdefault("MUJOCO_GL", "disable")
    args = ["-b", "html", "-c", str(BOOK), "-d", str(work / budget / "doctrees"),
            "-W", "--keep-going", "-j", "1",
            str(src), str(out)]
    if quiet:
        args.insert(0, "-q")
    t0 = time.perf_counter()
    rc = build_main(args)
    if rc != 0:
        raise SystemExit(f"the {budget} site did not build (sphinx exit {rc})")
    index = out / "index.html"
    print(f"{budget} site built in {time.perf_counter() - t0:.0f} s; open {index}")
    return index


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--budget", default=os.environ.get("VSLBOOK_BUDGET", "reduced"),
                        choices=BUDGETS)
    parser.add_argument("-q", "--quiet", action="store_true")
    args = parser.parse_args(argv)
    build(args.budget, quiet=args.quiet)
    return 0


if __name__ == "__main__":
    sys.exit(main())
