"""``book/build.py``: which site a ``make book`` call builds, where its runs come from, and
when its cache of executed notebooks is emptied."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def build():
    spec = importlib.util.spec_from_file_location("book_build", ROOT / "book" / "build.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_labels_and_site_folders(build):
    assert build.build_label(None) == "default" and build.site_dir(None) == ROOT / "build" / "site"
    assert build.site_dir("smoke") == ROOT / "build" / "site-smoke"
    assert build.build_label("reduced") == "reduced"
    assert build.build_label(None, retrain=True) == "reduced-retrain"
    assert build.site_dir("full", retrain=True) == ROOT / "build" / "site-full-retrain"


def test_the_cache_is_emptied_when_recorded_results_change(build, tmp_path, monkeypatch):
    from vslbook.data import register_file

    monkeypatch.setenv("VSLBOOK_DATA", str(tmp_path / "data"))
    before = build.cache_stamp(retrain=False)
    assert build.cache_stamp(retrain=True) == build.CACHE_FORMAT  # retraining reads none
    table = tmp_path / "data" / "results" / "fig4-4a" / "full" / "runs.csv"
    table.parent.mkdir(parents=True)
    table.write_text("run\n")
    register_file(table, "a recorded set")
    after = build.cache_stamp(retrain=False)
    assert after != before
    cache = tmp_path / "cache"
    build.prepare_cache(cache, before)
    (cache / "executed.db").write_text("outputs")
    build.prepare_cache(cache, before)  # same results: kept
    assert (cache / "executed.db").exists()
    build.prepare_cache(cache, after)  # newly recorded results: executed again
    assert not (cache / "executed.db").exists()


def test_retrain_prints_the_plan_of_every_figure(build, tmp_path):
    from vslbook.experiments.run_plan import FIGURE_MODULES

    text = build.retrain_estimate("smoke", tmp_path / "runs")
    lines = text.splitlines()
    assert [line.split(":")[0].strip() for line in lines[:-1]] == list(FIGURE_MODULES)
    assert all("runs to train" in line for line in lines[:-1])
    assert lines[-1].startswith("retraining at smoke: ")
