"""The book site in a real browser: build it at the smoke budget, open every page in
headless Chromium (Debian's ``chromium``, driven by Playwright without a downloaded
browser) in a 1440x900 window (:data:`site_layout.VIEWPORT`) and check what a reader sees.

Per page: no raw ``$$`` or ``\\begin{`` left in the rendered text (MathJax typeset all
math), every image loaded, no console error or uncaught exception, no request to any host
but the local server (the site works offline), every thesis-numbered equation anchor
(``#eq-N-M``) holds typeset math, and no progress bar is left in the outputs (tqdm's text
``0%| | 0/N [...`` or a widget output: a static page cannot redraw a bar, so it stays
frozen; :func:`vslbook.progress.frozen_bars`). One screenshot per page (plus its first
equation and its first figure, where it has them) goes to ``build/screenshots/``.

Layout (:mod:`site_layout`, measured in the same window): every output image is shown at
``min(natural width, column width)``; every figure saved by the build
(``<id>.layout.json`` beside it) has at most 3 panels per row, each at least 400 px wide
as rendered; every displayed equation fits its column or scrolls horizontally.
"""

from __future__ import annotations

import functools
import http.server
import os
import shutil
import threading
import time
from pathlib import Path

import pytest
import site_build
import site_layout as layout

from vslbook.progress import frozen_bars

ROOT = Path(__file__).resolve().parents[1]
SITE = site_build.SITE
SHOTS = ROOT / "build" / "screenshots"
CHROMIUM = os.environ.get("VSLBOOK_CHROMIUM", "/usr/bin/chromium")
# The flags the site's browser runs with (fresh profile: Playwright makes one per launch).
CHROMIUM_ARGS = ["--headless", "--no-sandbox", "--disable-gpu", "--no-first-run",
                 "--disable-background-networking", "--disable-component-update",
                 "--disable-sync", "--disable-quic"]

pytestmark = pytest.mark.slow

#: how long a page may take to load, typeset and go quiet on the network (and any other
#: browser step): generous, because a busy two-core machine is slow to render; a page that
#: never settles (a request left open) still fails, by name
PAGE_TIMEOUT_MS = 180_000
#: how long a settled page has no request open (:func:`_settle`)
QUIET_S = 0.5

# Text left in the page after MathJax ran, with code, program output and the typeset math
# removed: any raw TeX still in it was not typeset.
_PROSE = """() => {
  const body = document.body.cloneNode(true);
  body.querySelectorAll('pre, code, script, style, mjx-container, .cell_output')
      .forEach(e => e.remove());
  return body.innerText;
}"""
_IMAGES_COMPLETE = "() => Array.from(document.images).every(i => i.complete)"
_IMAGES = """() => Array.from(document.images).map(i => ({src: i.currentSrc || i.src,
  ok: i.complete && i.naturalWidth > 0}))"""
# The text of the notebooks' outputs, as a reader sees it.
_OUTPUTS = """() => Array.from(document.querySelectorAll('.cell_output'))
  .map(e => e.innerText).join('\\n')"""
_ANCHORS = """() => Array.from(document.querySelectorAll('[id^="eq-"]')).map(e => ({
  id: e.id, typeset: e.querySelector('mjx-container') !== null
    || (e.nextElementSibling && e.nextElementSibling.querySelector('mjx-container') !== null)
}))"""


@pytest.fixture(scope="module")
def site() -> Path:
    """The smoke site (notebooks executed, cached by content): the build that ``make test``
    started beside pytest (:mod:`site_build`), or one made now; return its folder."""
    if not Path(CHROMIUM).is_file():
        pytest.fail(f"no Chromium at {CHROMIUM}: `make setup` installs Debian's chromium "
                    "(or set VSLBOOK_CHROMIUM)")
    status = os.environ.get(site_build.STATUS_ENV)
    if status:
        site_build.wait_for(Path(status))
    else:
        site_build.build_now()
    assert (SITE / "index.html").is_file()
    return SITE


@pytest.fixture(scope="module")
def server(site: Path):
    handler = functools.partial(_QuietHandler, directory=str(site))
    httpd = http.server.ThreadingHTTPServer(("127.0.0.1", 0), handler)
    thread = threading.Thread(target=httpd.serve_forever, daemon=True)
    thread.start()
    yield f"http://127.0.0.1:{httpd.server_address[1]}"
    httpd.shutdown()


class _QuietHandler(http.server.SimpleHTTPRequestHandler):
    def log_message(self, *args) -> None:  # keep pytest's output readable
        pass


@pytest.fixture(scope="module")
def browser():
    from playwright.sync_api import sync_playwright

    with sync_playwright() as pw:
        b = pw.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS, headless=True)
        yield b
        b.close()


def _pages(site: Path) -> list[str]:
    return sorted(p.name for p in site.glob("*.html"))


def test_site_has_the_chapters_and_bibliography(site: Path):
    pages = set(_pages(site))
    for name in ("index.html", "02_foundations.html", "03_svsl.html", "04_diskill.html",
                 "05_dime.html", "bibliography.html"):
        assert name in pages, f"{name} missing from the site: {sorted(pages)}"
    # MathJax is served by the site itself
    assert (site / "_static" / "mathjax" / "tex-chtml.js").is_file()
    assert "cdn.jsdelivr" not in (site / "02_foundations.html").read_text()


# Pages whose notebooks draw figures: each must show at least one.
FIGURE_PAGES = ("02_foundations.html", "03_svsl.html", "04_diskill.html", "05_dime.html")
# Chapters that open with their results: the first section is "Results at a glance", with
# a figure and the table of the thesis's claims (claim, status) before any derivation.
RESULTS_PAGES = ("03_svsl.html", "04_diskill.html", "05_dime.html")
_OPENING = """() => {
  const first = document.querySelector('article section section, article h2');
  const sec = first && (first.tagName === 'SECTION' ? first : first.closest('section'));
  if (!sec) return null;
  const h = sec.querySelector('h2');
  const table = Array.from(sec.querySelectorAll('.cell_output table')).find(t =>
      Array.from(t.querySelectorAll('thead th')).some(th => th.innerText.trim() === 'status'));
  let statuses = [];
  if (table) {
    const heads = Array.from(table.querySelectorAll('thead th')).map(t => t.innerText.trim());
    const col = heads.indexOf('status');
    statuses = Array.from(table.querySelectorAll('tbody tr'))
        .map(tr => (tr.children[col] || {innerText: ''}).innerText.trim());
  }
  return {heading: h ? h.innerText : '',
          images: sec.querySelectorAll('.cell_output img').length,
          columns: Array.from(sec.querySelectorAll('.cell_output table th'))
                        .map(t => t.innerText.trim()),
          statuses: statuses};
}"""


@pytest.fixture(scope="module")
def rendered(site: Path, server: str, browser) -> dict[str, dict]:
    """Every page opened once: its problems, output images and displayed equations."""
    if SHOTS.exists():
        shutil.rmtree(SHOTS)
    SHOTS.mkdir(parents=True)
    return {name: _open_page(browser, f"{server}/{name}", name, server)
            for name in _pages(site)}


def test_every_page_renders_offline(rendered: dict[str, dict]):
    problems = [p for page in rendered.values() for p in page["problems"]]
    assert not problems, "\n".join(problems)


def test_output_images_fill_the_column_up_to_their_size(rendered: dict[str, dict]):
    problems = [p for name, page in rendered.items()
                for p in layout.image_problems(name, page["images"])]
    assert not problems, "\n".join(problems)


def test_figures_have_wide_enough_panels(rendered: dict[str, dict]):
    layouts = layout.load_layouts(site_build.FIGURES, "smoke")
    # written while the notebooks execute: a cached build writes none
    assert layouts, (f"no figure layouts (*.layout.json) of the smoke budget in "
                     f"{site_build.FIGURES}: the cached notebooks ran before save_figure "
                     "wrote layouts there; empty build/book-cache/smoke and run again")
    shown = [(name, img) for name, page in rendered.items() for img in page["images"]]
    problems = layout.figure_problems(layouts, shown)
    assert not problems, "\n".join(problems)


def test_displayed_equations_fit_or_scroll(rendered: dict[str, dict]):
    problems = [p for name, page in rendered.items()
                for p in layout.equation_problems(name, page["equations"])]
    assert not problems, "\n".join(problems)


def _open_page(browser, url: str, name: str, server: str) -> dict:
    """:func:`_check_page`, with a page that does not settle in :data:`PAGE_TIMEOUT_MS`
    reported as that page's problem (naming the requests still open) instead of an error
    that hides every other page's checks."""
    from playwright.sync_api import Error as PlaywrightError

    page = browser.new_page(viewport=layout.VIEWPORT)
    page.set_default_timeout(PAGE_TIMEOUT_MS)
    page.set_default_navigation_timeout(PAGE_TIMEOUT_MS)
    open_requests: list = []
    page.on("request", lambda r: open_requests.append(r))
    for done in ("requestfinished", "requestfailed"):
        page.on(done, lambda r: open_requests.remove(r) if r in open_requests else None)
    try:
        return _check_page(page, url, name, server, open_requests)
    except (PlaywrightError, _Unsettled) as e:
        still = [r.url for r in open_requests]
        message = str(e).splitlines()[0].rstrip(".")
        return {"problems": [f"{name}: {message}; requests still open: {still[:10]}"],
                "images": [], "equations": []}
    finally:
        page.close()


class _Unsettled(Exception):
    """A page still busy (typesetting, fonts, images or requests) after its timeout."""


def _settle(page, open_requests: list, timeout_ms: float) -> None:
    """Wait until a loaded page is done: MathJax has typeset (where the page has it), its
    fonts have loaded, every image is complete, and no request has been open for
    :data:`QUIET_S`. The open requests are this test's own account (``open_requests``):
    Playwright's ``networkidle``, re-armed by the fonts MathJax fetches once it typesets,
    once never came back on a slow machine although no request was open."""
    deadline = time.monotonic() + timeout_ms / 1000
    typeset = page.evaluate("""async (ms) => {
      const busy = Promise.all([
        typeof MathJax === 'undefined' ? null : MathJax.startup.promise,
        document.fonts.ready]);
      return await Promise.race([busy.then(() => true),
                                 new Promise(r => setTimeout(() => r(false), ms))]);
    }""", timeout_ms)
    if not typeset:
        raise _Unsettled(f"MathJax or the fonts still busy after {timeout_ms:.0f} ms")
    quiet_since = None
    while True:
        now = time.monotonic()
        done = not open_requests and page.evaluate(_IMAGES_COMPLETE)
        quiet_since = (quiet_since or now) if done else None
        if quiet_since is not None and now - quiet_since >= QUIET_S:
            return
        if now > deadline:
            raise _Unsettled(f"still loading after {timeout_ms:.0f} ms")
        page.wait_for_timeout(50)


def _check_page(page, url: str, name: str, server: str, open_requests: list) -> dict:
    errors: list[str] = []
    outside: list[str] = []
    page.on("console", lambda m: errors.append(m.text) if m.type == "error" else None)
    page.on("pageerror", lambda e: errors.append(str(e)))

    def route(r):
        if r.request.url.startswith(server) or r.request.url.startswith("data:"):
            r.continue_()
        else:
            outside.append(r.request.url)
            r.abort()

    page.route("**/*", route)
    page.goto(url, wait_until="load")
    _settle(page, open_requests, PAGE_TIMEOUT_MS)
    has_mathjax = page.evaluate("() => typeof MathJax !== 'undefined'")
    stem = Path(name).stem
    problems = [f"{name}: console error: {e}" for e in errors]
    problems += [f"{name}: fetched from outside the site: {u}" for u in outside]
    prose = page.evaluate(_PROSE)
    for raw in ("$$", "\\begin{"):
        if raw in prose:
            at = prose.index(raw)
            problems.append(f"{name}: raw {raw!r} in the text: ...{prose[at - 60:at + 60]!r}")
    if name in RESULTS_PAGES:
        problems += _opening_problems(name, page.evaluate(_OPENING))
    images = page.evaluate(_IMAGES)
    if name in FIGURE_PAGES and not images:
        problems.append(f"{name}: no figure on the page")
    for img in images:
        if not img["ok"]:
            problems.append(f"{name}: image not loaded: {img['src'][:120]}")
    for anchor in page.evaluate(_ANCHORS):
        if not anchor["typeset"]:
            problems.append(f"{name}: equation anchor #{anchor['id']} holds no typeset math")
    problems += [f"{name}: progress bar left on the page: {bar}"
                 for bar in frozen_bars(page.evaluate(_OUTPUTS), page.content())]
    measured = {"problems": problems, "images": page.evaluate(layout.OUTPUT_IMAGES),
                "equations": page.evaluate(layout.EQUATIONS) if has_mathjax else []}
    page.screenshot(path=str(SHOTS / f"{stem}.png"))
    equation = page.locator("mjx-container[display='true']")
    if equation.count():
        equation.first.scroll_into_view_if_needed()
        page.screenshot(path=str(SHOTS / f"{stem}-equation.png"))
    figure = page.locator(".cell_output img")
    if figure.count():
        figure.first.scroll_into_view_if_needed()
        page.screenshot(path=str(SHOTS / f"{stem}-figure.png"))
    return measured


def _opening_problems(name: str, opening: dict | None) -> list[str]:
    """What a chapter's first section lacks of its results (:data:`RESULTS_PAGES`)."""
    if opening is None or "Results at a glance" not in opening["heading"]:
        got = None if opening is None else opening["heading"]
        return [f"{name}: the first section is {got!r}, not 'Results at a glance'"]
    problems = []
    if not opening["images"]:
        problems.append(f"{name}: 'Results at a glance' shows no figure")
    if not {"claim", "status"} <= set(opening["columns"]):
        problems.append(f"{name}: 'Results at a glance' has no table of the claims (claim, "
                        f"status); its table columns: {opening['columns']}")
    # the site is built at smoke: no claim may be judged on smoke runs
    judged = [s for s in opening["statuses"] if s in ("met", "not met")]
    if judged or not opening["statuses"]:
        problems.append(f"{name}: the claims of a smoke build must read 'smoke' (code path "
                        f"only), not a verdict; got statuses {opening['statuses']}")
    return problems


class _StallingHandler(http.server.BaseHTTPRequestHandler):
    """A page whose image never arrives within the test's timeout."""

    def do_GET(self) -> None:  # noqa: N802 (the http.server name)
        if self.path.endswith(".png"):
            threading.Event().wait(5.0)
            try:
                self.send_error(404)
            except OSError:  # the browser has closed the page meanwhile
                pass
            return
        body = (b"<html><body><p>text</p><img src='/stalls.png'></body></html>"
                if self.path == "/stalls.html" else  # a request after the page's load:
                b"<html><body><p>text</p><script>addEventListener('load', () =>"
                b" setTimeout(() => fetch('/late.png'), 50))</script></body></html>")
        self.send_response(200)
        self.send_header("Content-Type", "text/html")
        self.send_header("Content-Length", str(len(body)))
        self.end_headers()
        self.wfile.write(body)

    def log_message(self, *args) -> None:
        pass


@pytest.mark.parametrize(("page", "stalled"), [("stalls.html", "stalls.png"),
                                              ("late.html", "late.png")])
def test_a_page_that_never_settles_is_its_own_named_problem(browser, monkeypatch, page,
                                                            stalled):
    """A stalled request, during the page's load or after it, fails that page by name (and
    the request), not the whole run."""
    monkeypatch.setattr(f"{__name__}.PAGE_TIMEOUT_MS", 1000)
    httpd = http.server.ThreadingHTTPServer(("127.0.0.1", 0), _StallingHandler)
    httpd.daemon_threads = True
    threading.Thread(target=httpd.serve_forever, daemon=True).start()
    server = f"http://127.0.0.1:{httpd.server_address[1]}"
    try:
        got = _open_page(browser, f"{server}/{page}", page, server)
    finally:
        httpd.shutdown()
    assert len(got["problems"]) == 1, got["problems"]
    problem = got["problems"][0]
    assert problem.startswith(f"{page}: ") and stalled in problem, problem
    assert got["images"] == [] and got["equations"] == []
