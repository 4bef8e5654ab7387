"""Build the vslbook site: ``python book/build.py [--budget B] [--retrain]`` (``make book``).

Where the long run sets come from (:mod:`vslbook.experiments.figure_sources`):

* no ``--budget`` (``make book``): each figure draws its recorded runs (``data/results/``,
  the largest budget recorded) or the finished runs of ``runs/``; a figure with neither
  trains its runs now at ``smoke`` and says so. The rest of the book (derivations, checks,
  cheap live runs) executes at ``reduced``. The site goes to ``build/site/``.
* ``--budget B`` (``make book VSLBOOK_BUDGET=B``): the same at B alone; a figure with
  nothing recorded or finished at B trains its runs at B. Into ``build/site-B/``.
* ``--retrain`` (``make book RETRAIN=1``): every run of the budget is trained (finished ones
  reused); the core-hours that takes are printed first (``vslbook plan``).

1. Stage the sources in ``build/book-src/``: the jupytext notebooks of ``notebooks/`` as
   ``.ipynb`` (``00_index`` becomes the landing page ``index``, with the table of contents
   appended),
   the pages of ``book/`` and a MathJax 3 copy, so the site typesets math offline.
2. Run Sphinx (MyST-NB, sphinx-book-theme) into the site's folder. Each notebook executes
   through a jupyter-cache store of that build (``build/book-cache/<label>``): a notebook
   whose code has not changed is not executed again, unless the recorded results changed
   (the cache's stamp holds their registries' fingerprint, :func:`cache_stamp`).
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


def build_label(budget: str | None, retrain: bool = False) -> str:
    """The name of a build: ``default`` (no budget named), the budget, ``<budget>-retrain``."""
    if retrain:
        return f"{budget or 'reduced'}-retrain"
    return budget or "default"


def site_dir(budget: str | None, retrain: bool = False) -> Path:
    """Where a site is written: ``build/site`` for ``make book``, else ``build/site-<label>``."""
    label = build_label(budget, retrain)
    return ROOT / "build" / ("site" if label == "default" else f"site-{label}")


def results_fingerprint() -> str:
    """sha256 over the registries of ``data/results/`` (changes whenever a set is recorded)."""
    import hashlib

    from vslbook.data import results_dir

    digest = hashlib.sha256()
    results = results_dir()
    for reg in sorted(results.rglob("registry.json")) if results.is_dir() else ():
        digest.update(str(reg.relative_to(results)).encode() + b"\0" + reg.read_bytes())
    return digest.hexdigest()


def cache_stamp(retrain: bool) -> str:
    """What a cache's outputs were made with: :data:`CACHE_FORMAT` and, unless retraining,
    the recorded results (:func:`results_fingerprint`) the figures read."""
    return CACHE_FORMAT if retrain else f"{CACHE_FORMAT} results={results_fingerprint()[:16]}"


def retrain_estimate(budget: str, root: Path) -> str:
    """What ``make book RETRAIN=1`` will train: core-hours per figure (``vslbook plan``)."""
    import math

    from vslbook.experiments.run_plan import FIGURE_MODULES, plan

    lines, total, untimed = [], 0.0, 0
    for figure in FIGURE_MODULES:
        todo = [r for r in plan(figure, budget, root) if r.state in ("partial", "missing")]
        hours = sum(r.hours_left for r in todo if not math.isnan(r.hours_left))
        unknown = sum(math.isnan(r.hours_left) for r in todo)
        total, untimed = total + hours, untimed + unknown
        note = f", {unknown} not yet timed" if unknown else ""
        lines.append(f"  {figure}: {len(todo)} runs to train, {hours:.1f} core-hours{note}")
    lines.append(f"retraining at {budget}: {total:.1f} core-hours measured"
                 + (f" plus {untimed} runs not yet timed" if untimed else "")
                 + " (vslbook plan FIGURE lists each run)")
    return "\n".join(lines)


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


def prepare_cache(cache: Path, stamp_text: str = CACHE_FORMAT) -> None:
    """Empty ``cache`` if its outputs were made otherwise (another :data:`CACHE_FORMAT`, or
    other recorded results, :func:`cache_stamp`)."""
    stamp = cache / CACHE_STAMP
    if cache.exists() and any(cache.iterdir()):
        if stamp.is_file() and stamp.read_text().strip() == stamp_text:
            return
        print(f"{cache}: its outputs were made with other recorded results or in another "
              "format; emptied, every notebook executes again (finished runs are reused)")
        shutil.rmtree(cache)
    cache.mkdir(parents=True, exist_ok=True)
    stamp.write_text(stamp_text + "\n")


def build(budget: str | None = None, *, retrain: bool = False, quiet: bool = False) -> Path:
    """Build the site (see the module's docstring); return its landing page.

    ``budget``: None builds the default book (recorded results, the rest at ``reduced``).
    """
    if budget is not None and budget not in BUDGETS:
        raise ValueError(f"budget {budget!r} is not one of {BUDGETS}")
    from sphinx.cmd.build import build_main

    label = build_label(budget, retrain)
    live = budget or "reduced"
    if retrain:
        print(retrain_estimate(live, ROOT / "runs"), flush=True)
    work = ROOT / "build" / "book-src"
    src, static = work / label / "src", work / label / "static"
    stage(src)
    stage_static(static)
    out = site_dir(budget, retrain)
    os.environ["VSLBOOK_BUDGET"] = live
    os.environ["VSLBOOK_SOURCE"] = "retrain" if retrain else ("budget" if budget else "best")
    os.environ["VSLBOOK_BOOK_STATIC"] = str(static)
    cache = ROOT / "build" / "book-cache" / label
    prepare_cache(cache, cache_stamp(retrain))
    os.environ["VSLBOOK_BOOK_CACHE"] = str(cache)
    # one plain line per run set instead of progress bars frozen on the page
    os.environ["VSLBOOK_PROGRESS"] = progress_mode_for_site()
    os.environ.setdefault("VSLBOOK_BOOK_TIMEOUT", "2400" if live == "smoke" else "-1")
    os.environ.setdefault("VSLBOOK_FIGURES", str(ROOT / "build" / "figures"))
    # The kernels draw inline (figures become page images), whatever a caller exported for
    # headless scripts (the Makefile exports MPLBACKEND=Agg for the tests).
    os.environ["MPLBACKEND"] = "module://matplotlib_inline.backend_inline"
    os.environ.setdefault("MUJOCO_GL", "disable")
    args = ["-b", "html", "-c", str(BOOK), "-d", str(work / label / "doctrees"),
            "-W", "--keep-going", "-j", "1",
            str(src), str(out)]
    if quiet:
        args.insert(0, "-q")
    t0 = time.perf_counter()
    rc = build_main(args)
    if rc != 0:
        raise SystemExit(f"the {label} site did not build (sphinx exit {rc})")
    index = out / "index.html"
    print(f"{label} site built in {time.perf_counter() - t0:.0f} s; open {index}")
    return index


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--budget", default=os.environ.get("VSLBOOK_BUDGET") or None,
                        choices=BUDGETS, help="train what is not recorded at this budget "
                        "(default: recorded results, else smoke runs)")
    parser.add_argument("--retrain", action="store_true",
                        help="train every run of the budget (default reduced); prints the plan")
    parser.add_argument("-q", "--quiet", action="store_true")
    args = parser.parse_args(argv)
    build(args.budget, retrain=args.retrain, quiet=args.quiet)
    return 0


if __name__ == "__main__":
    sys.exit(main())
