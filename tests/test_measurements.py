"""``data/measurements/``: numbers measured outside the book, registered, read by the
notebooks instead of typed into their prose."""

from __future__ import annotations

import shutil

import pytest

from vslbook.data import DataIntegrityError, data_dir, measurements


def test_tables_read_verified_with_their_columns():
    planar = measurements("planar_versatility.csv")
    assert set(planar["code"]) == {"ours", "authors"}
    assert set(planar["reading"]) == {"targets from p(c)", "six figure targets"}
    # every seed range holds its IQM where both are recorded
    key = ["code", "n_experts", "seeds", "reward", "reading", "variant"]
    wide = planar.pivot_table(index=key, columns="measure", values="value")
    ranged = wide.dropna(subset=["ways_per_target", "ways_per_target_seed_min"])
    low, mid = ranged["ways_per_target_seed_min"], ranged["ways_per_target"]
    assert len(ranged) and ((low <= mid) & (mid <= ranged["ways_per_target_seed_max"])).all()
    probe = measurements("table_tennis_probe.csv")
    assert probe["iteration"].is_monotonic_increasing and (probe["test_success"] == 0).all()


def test_a_missing_or_edited_table_is_an_error(tmp_path, monkeypatch):
    shutil.copytree(data_dir() / "measurements", tmp_path / "measurements")
    monkeypatch.setenv("VSLBOOK_DATA", str(tmp_path))
    with pytest.raises(FileNotFoundError, match=r"no measurements table 'x.csv'.*expected one of"):
        measurements("x.csv")
    path = tmp_path / "measurements" / "table_tennis_probe.csv"
    path.write_text(path.read_text().replace("2.1", "2.5"))
    with pytest.raises(DataIntegrityError):
        measurements("table_tennis_probe.csv")
