"""Test order: the site's browser test after every other test of ``tests/``.

``make test`` builds the smoke site in the background beside pytest (``site_build.py``);
the browser test waits for that build, so it runs once the rest of ``tests/`` has given the
build time to finish. The notebooks run in that background lane after the build (a second
pytest, with the test files of ``LANE2_TESTS``; see the Makefile), so a notebook that
trains a smoke run finds the run the build finished, and never trains it at the same time
as the build.
"""

from __future__ import annotations

from pathlib import Path

import pytest

TESTS = Path(__file__).resolve().parent
SITE_TEST = TESTS / "test_book_site.py"


def _is_site_test(item: pytest.Item) -> bool:
    return Path(item.path) == SITE_TEST


def _in_tests(item: pytest.Item) -> bool:
    return Path(item.path).is_relative_to(TESTS)


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    site = [i for i in items if _is_site_test(i)]
    if not site:
        return
    rest = [i for i in items if not _is_site_test(i)]
    last = max((k for k, i in enumerate(rest) if _in_tests(i)), default=-1)
    items[:] = rest[:last + 1] + site + rest[last + 1:]
