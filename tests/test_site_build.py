"""The background build of the smoke site (``site_build.py``) and where its test runs."""

from __future__ import annotations

import threading
import time
from pathlib import Path

import conftest
import pytest
import site_build


def test_waiting_returns_once_the_build_wrote_status_zero(tmp_path: Path):
    status = tmp_path / "site.status"
    writer = threading.Timer(0.3, lambda: status.write_text("0\n"))
    writer.start()
    t0 = time.monotonic()
    site_build.wait_for(status, timeout_s=30, poll_s=0.05)
    assert time.monotonic() - t0 >= 0.25   # it waited for the file
    writer.join()


def test_a_failed_build_shows_its_status_and_the_end_of_its_log(tmp_path: Path):
    status = tmp_path / "site.status"
    status.write_text("2\n")
    site_build.log_path(status).write_text("early lines\n" + "x" * 10_000 + "\nsphinx: ERROR\n")
    with pytest.raises(RuntimeError, match=r"status '2' \(expected 0\)") as err:
        site_build.wait_for(status, timeout_s=1, poll_s=0.05)
    assert "sphinx: ERROR" in str(err.value) and "early lines" not in str(err.value)


def test_a_build_that_never_ends_times_out_naming_its_log(tmp_path: Path):
    status = tmp_path / "site.status"
    with pytest.raises(TimeoutError, match="site.log"):
        site_build.wait_for(status, timeout_s=0.2, poll_s=0.05)


def test_the_script_wants_one_status_file(capsys):
    assert site_build.main([]) == 2
    assert site_build.main(["build/site.txt"]) == 2
    assert "STATUS_FILE.status" in capsys.readouterr().err


class _Item:
    def __init__(self, path: Path):
        self.path = path


def test_the_browser_test_runs_after_the_other_tests_and_before_the_notebooks():
    tests, site = conftest.TESTS, conftest.SITE_TEST
    notebooks = tests.parent / "notebooks"
    order = [site, site, tests / "test_a.py", tests / "test_z.py",
             notebooks / "00_index.ipynb", notebooks / "01_tasks.ipynb"]
    items = [_Item(p) for p in order]
    conftest.pytest_collection_modifyitems(items)
    assert [i.path for i in items] == [tests / "test_a.py", tests / "test_z.py", site, site,
                                       notebooks / "00_index.ipynb",
                                       notebooks / "01_tasks.ipynb"]
