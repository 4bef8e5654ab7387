"""The audit tables: ours is read from the objects, sources are given, flags are computed."""

from __future__ import annotations

import dataclasses

import pandas as pd
import pytest

from vslbook.envs.robot import make_task
from vslbook.erl.diskill_config import diskill_config
from vslbook.experiments import audit
from vslbook.experiments.audit import NOT_FOUND, NOT_STATED, Setting


@pytest.fixture(scope="module")
def tables() -> dict[str, pd.DataFrame]:
    return {
        "tasks": audit.task_audit(),
        "ch3": audit.algorithm_audit(3),
        "ch4": audit.algorithm_audit(4),
    }


def _row(frame: pd.DataFrame, subject: str, field: str) -> pd.Series:
    hit = frame[(frame["subject"] == subject) & (frame["field"] == field)]
    assert len(hit) == 1, (subject, field)
    return hit.iloc[0]


def test_ours_follows_the_task_options() -> None:
    field = "reward variant (touched, not passed)"
    default = _row(audit.task_audit(), "mini-golf", field)
    changed = _row(audit.task_audit({"mini-golf": {"reward": "thesis"}}), "mini-golf", field)
    assert (default["ours"], default["ours = code"]) == ("code", True)
    assert (changed["ours"], changed["ours = code"], changed["ours = thesis"]) == (
        "thesis", False, True,
    )  # fmt: skip
    bpo = audit.task_audit({"box-pushing-obstacle": {"goal": "learned"}})
    assert _row(bpo, "box-pushing-obstacle", "parameters θ")["ours = code"] is True


def test_box_pushing_follows_the_code_and_the_thesis_settings_the_text() -> None:
    """Every box-pushing row agrees with the authors' code by default; settings="thesis"
    agrees with B.4.2.1 on every row where the thesis states a value."""
    rows = audit.task_audit()
    bpo = rows[rows["subject"] == "box-pushing-obstacle"]
    assert bpo["ours = code"].tolist() == [True] * len(bpo), bpo[["field", "ours"]]
    fields = set(bpo["field"])
    for field in ("obstacle–goal distance rule", "goal mode", "parameters θ",
                  "reward: weight of box–rod distance, of ‖q̇_T‖",
                  "reward: rod tilt cost per step below π/4",
                  "θ outside joint limits rejected unsimulated"):  # fmt: skip
        assert field in fields
        assert _row(rows, "box-pushing-obstacle", field)["choice and why"].startswith("code")
    thesis = audit.task_audit({"box-pushing-obstacle": {"settings": "thesis"}})
    tb = thesis[thesis["subject"] == "box-pushing-obstacle"]
    stated = tb[tb["ours = thesis"].notna()]
    assert stated["ours = thesis"].tolist() == [True] * len(stated), stated[["field", "ours"]]
    assert _row(thesis, "box-pushing-obstacle", "parameters θ")["ours"] == "28"
    assert _row(thesis, "box-pushing-obstacle", "obstacle–goal distance rule")["ours"] == (
        "Euclidean distance >= 0.15"
    )
    limits = _row(thesis, "box-pushing-obstacle", "θ outside joint limits rejected unsimulated")
    assert (limits["ours"], limits["ours = code"]) == ("True", False)


def test_table_tennis_ch3_punishments_follow_the_code_and_the_thesis_settings_a33() -> None:
    """The three punishments of the Chapter 3 table tennis are read from the task: the
    authors' SVSL code's by default, A.3.3's with settings="thesis"."""
    fields = ("context out-of-range punishment",
              "duration punishment (l outside [0.1, 5] s, b the bound)",
              "joint-limit punishment (planned q_d outside the joint box)")  # fmt: skip
    code = audit.task_audit()
    thesis = audit.task_audit({"table-tennis-ch3": {"settings": "thesis"}})
    for field in fields:
        row = _row(code, "table-tennis-ch3", field)
        assert (row["ours = code"], row["ours = thesis"]) == (True, False), field
        assert row["choice and why"].startswith("code") and "settings=" in row["choice and why"]
        assert row["ours read from"].startswith("task.")
        other = _row(thesis, "table-tennis-ch3", field)
        assert (other["ours = code"], other["ours = thesis"]) == (False, True), field
    assert _row(code, "table-tennis-ch3", fields[1])["ours"] == "-3|l - b| - 1"
    assert _row(thesis, "table-tennis-ch3", fields[1])["ours"] == "-3|l - b|"


def test_ours_follows_the_configs() -> None:
    field = "samples per expert"
    before = _row(audit.algorithm_audit(4), "diskill/hopper-jump", field)  # the code's preset
    cfg = diskill_config("hopper-jump", settings="thesis")  # Table B.5
    after = _row(
        audit.algorithm_audit(4, {"diskill/hopper-jump": cfg}), "diskill/hopper-jump", field
    )
    assert (before["ours"], before["ours = code"], before["ours = thesis"]) == (
        "100", True, False)  # fmt: skip
    assert (after["ours"], after["ours = code"], after["ours = thesis"]) == ("80", False, True)
    with pytest.raises(ValueError, match="no subject"):
        audit.algorithm_audit(4, {"diskill/nowhere": cfg})
    with pytest.raises(ValueError, match="chapter"):
        audit.algorithm_audit(5)


def test_every_row_has_sources(tables: dict[str, pd.DataFrame]) -> None:
    for frame in tables.values():
        assert list(frame.columns) == list(audit.COLUMNS)
        for _, row in frame.iterrows():
            assert row["thesis source"].strip(), row["field"]
            assert row["code source"].strip(), row["field"]
            if row["authors' code"] == NOT_FOUND:
                assert row["code source"] == NOT_FOUND
                assert row["ours = code"] is None
            if row["thesis"] == NOT_STATED:
                assert row["ours = thesis"] is None
            assert row["ours"] != "" and row["ours read from"]


def test_flags_on_a_hand_made_example() -> None:
    rows = [
        Setting("s", "a", 1.0, "T1", 2.0, "c.py l.1", "x", "Fig", "why"),
        Setting("s", "b", NOT_STATED, "none", (1, 2), "c.py l.2", "y", "Fig", "why"),
        Setting("s", "c", "thesis", "T2", NOT_FOUND, NOT_FOUND, lambda o: o.z, "Fig", "why"),
    ]
    obj = type("Obj", (), {"x": 1.0, "y": [1.0, 2.0 + 1e-13], "z": "thesis"})()
    frame = audit.audit_frame(rows, {"s": obj})
    assert frame["ours = code"].tolist() == [False, True, None]
    assert frame["ours = thesis"].tolist() == [True, None, True]
    view = audit.show_audit(frame)
    assert view["≠"].tolist() == ["≠ code", "", ""]
    assert len(audit.show_audit(frame, only_differences=True)) == 1
    assert audit.same_value(True, 1) is False and audit.same_value(None, None) is True


def test_every_field_exists(tables: dict[str, pd.DataFrame]) -> None:
    # audit_frame reads every row's attribute; a missing one raises a clear error
    broken = [Setting("s", "f", 1, "T", 1, "c", "no_such.attr", "Fig", "why")]
    with pytest.raises(AttributeError, match="no_such"):
        audit.audit_frame(broken, {"s": make_task("planar-reacher")})
    from vslbook.experiments.audit_algorithms_ch3 import ch3_settings
    from vslbook.experiments.audit_algorithms_ch4 import ch4_settings

    settings = ch4_settings() + ch3_settings()
    names = {
        f.name for cls in (type(diskill_config("mini-golf")),) for f in dataclasses.fields(cls)
    }
    for s in settings:
        if s.subject.startswith(("diskill", "bbrl", "lindiskill")):
            assert s.ours in names, s.ours
    assert sum(len(f) for f in tables.values()) > 300
