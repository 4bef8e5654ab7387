"""Sphinx configuration of the vslbook site (`make book`; built by ``book/build.py``).

The sources are the jupytext notebooks of ``notebooks/``, staged by ``build.py`` next to
the pages of this folder. MyST-NB executes each notebook at the active budget
(``VSLBOOK_BUDGET``) through a jupyter-cache store kept per budget, so an unchanged
notebook is not executed again. Math is typeset by a MathJax 3 copy served from the
site itself: a page fetches nothing from the network when it is viewed.
"""

from __future__ import annotations

import os

project = "vslbook"
author = "the vslbook authors"
copyright = "the vslbook authors (MIT)"  # noqa: A001  (Sphinx reads this name)
root_doc = "index"

extensions = ["myst_nb", "sphinxcontrib.bibtex"]

# --- notebooks ------------------------------------------------------------------------
# build.py stages the jupytext notebooks of notebooks/ as .ipynb (without outputs).
exclude_patterns = ["**.ipynb_checkpoints", "_build"]
nb_execution_mode = os.environ.get("VSLBOOK_BOOK_EXECUTION", "cache")  # "off": layout only
nb_execution_cache_path = os.environ.get("VSLBOOK_BOOK_CACHE", "_cache")
# A budget's notebook may run for hours (the reduced Chapter 5 set); smoke has a ceiling.
nb_execution_timeout = int(os.environ.get("VSLBOOK_BOOK_TIMEOUT", "-1"))
nb_execution_raise_on_error = True   # a failed check stops the book, as in the notebook
nb_execution_show_tb = True
nb_merge_streams = True
nb_execution_in_temp = False
# Progress bars are ipywidgets in a live kernel; on a static page their text form is shown
# and no widget script (served from a CDN) is loaded.
nb_mime_priority_overrides = [("html", "application/vnd.jupyter.widget-view+json", None),
                              ("html", "application/vnd.jupyter.widget-state+json", None)]
nb_ipywidgets_js = {}

# --- markdown and math ----------------------------------------------------------------
myst_enable_extensions = ["dollarmath", "amsmath", "colon_fence"]
myst_heading_anchors = 3
# Equations carry the thesis's numbers through \tag{...} and labels (eq-N-M)=; Sphinx's own
# equation counter is therefore not used.
math_numfig = False
mathjax_path = "mathjax/tex-chtml.js"   # served from _static, see build.py
mathjax3_config = {
    "tex": {"tags": "none", "macros": {"KL": r"\operatorname{KL}"}},
    "options": {"menuOptions": {"settings": {"assistiveMml": False}}},
}

# --- bibliography ---------------------------------------------------------------------
bibtex_bibfiles = ["references.bib"]
bibtex_reference_style = "author_year"
bibtex_default_style = "plain"

# --- HTML -----------------------------------------------------------------------------
html_theme = "sphinx_book_theme"
html_title = "vslbook"
# book/_static, then the MathJax copy that build.py stages (VSLBOOK_BOOK_STATIC)
html_static_path = ["_static"] + [p for p in [os.environ.get("VSLBOOK_BOOK_STATIC")] if p]
html_css_files = ["vslbook.css"]
html_theme_options = {
    "show_toc_level": 2,
    "use_download_button": True,
    "use_fullscreen_button": False,
    "home_page_in_toc": True,
    "navigation_with_keys": False,
}
html_last_updated_fmt = None
html_show_sourcelink = False
# A fixed colour mode: with none stored (a fresh browser profile) the theme would log an
# error and fall back to "auto".
html_context = {"default_mode": "light"}
