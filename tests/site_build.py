"""The smoke site that the browser test (``test_book_site.py``) checks, built beside pytest.

Building the site executes every notebook at the smoke budget and trains the smoke runs
that no recorded result stands for: about a third of the suite's time on one core. So
``make test`` starts this script in the background, on the machine's second core, and runs
pytest beside it::

    python tests/site_build.py build/site-smoke.status   # writes the build's exit status

The same background lane then runs the notebooks and a few slow test files (a second
pytest over ``LANE2_TESTS`` of the Makefile), so that no notebook trains the same smoke
runs as the build at the same time.
``tests/conftest.py`` runs the browser test after every other test of ``tests/``, and its
fixture :func:`site` waits for the status that ``$VSLBOOK_SITE_BUILD`` names. Run on its
own (``pytest tests/test_book_site.py``), the fixture builds the site itself.

The build saves its figures to :data:`FIGURES`, a folder of its own: the layout checks read
the figures of the site's build, not those that tests and notebooks save meanwhile.
"""

from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SITE = ROOT / "build" / "site-smoke"
#: where the site's build saves its figures (and their ``*.layout.json``)
FIGURES = ROOT / "build" / "figures-site-smoke"
#: the environment variable naming the status file of a build started in the background
STATUS_ENV = "VSLBOOK_SITE_BUILD"
#: how long the fixture waits for a background build before it gives up
WAIT_S = 3600
#: how much of the build's log a failure shows
LOG_TAIL = 6000


def build_env() -> dict[str, str]:
    """The environment of the site's build: the smoke budget, figures in :data:`FIGURES`,
    one thread per process unless ``$OMP_NUM_THREADS`` says otherwise (pytest uses the
    other core)."""
    return {"OMP_NUM_THREADS": "1", **os.environ, "VSLBOOK_BUDGET": "smoke",
            "VSLBOOK_FIGURES": str(FIGURES)}


def build_command() -> list[str]:
    return [sys.executable, str(ROOT / "book" / "build.py"), "--budget", "smoke", "-q"]


def log_path(status: Path) -> Path:
    """The log of a background build: beside its status file, ``.log`` for ``.status``."""
    return status.with_suffix(".log")


def build_now() -> None:
    """Build the site in this process's foreground (output to the terminal)."""
    subprocess.run(build_command(), check=True, cwd=ROOT, env=build_env())


def wait_for(status: Path, timeout_s: float = WAIT_S, poll_s: float = 2.0) -> None:
    """Wait until the background build has written ``status``; raise if it failed.

    Raises ``TimeoutError`` after ``timeout_s`` and ``RuntimeError`` with the end of the
    build's log where the build exited with another status than 0.
    """
    t0 = time.monotonic()
    while not status.is_file():
        if time.monotonic() - t0 > timeout_s:
            raise TimeoutError(f"the site's build has not written {status} in {timeout_s:.0f} s"
                               f"; its log: {log_path(status)}")
        time.sleep(poll_s)
    text = status.read_text().strip()
    if text != "0":
        log = log_path(status)
        tail = log.read_text(errors="replace")[-LOG_TAIL:] if log.is_file() else "(no log)"
        raise RuntimeError(f"the site's build exited with status {text!r} (expected 0); "
                           f"the end of {log}:\n{tail}")


def main(argv: list[str]) -> int:
    """Build the site, its output to the status file's ``.log``; then write the status."""
    if len(argv) != 1 or not argv[0].endswith(".status"):
        print(f"usage: python tests/site_build.py STATUS_FILE.status (got {argv})",
              file=sys.stderr)
        return 2
    status = Path(argv[0]).resolve()
    status.parent.mkdir(parents=True, exist_ok=True)
    status.unlink(missing_ok=True)
    with open(log_path(status), "w") as log:
        rc = subprocess.run(build_command(), cwd=ROOT, env=build_env(),
                            stdout=log, stderr=subprocess.STDOUT).returncode
    partial = status.with_suffix(".status.tmp")
    partial.write_text(f"{rc}\n")
    partial.replace(status)   # the waiting fixture never reads a half-written status
    return rc


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
