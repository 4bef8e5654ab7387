"""``vslbook.replay.rows_match``: the comparison that decides whether a run made by other
code is current (equal first rows) or stale, at the stated tolerances."""

from __future__ import annotations

from vslbook.replay import RTOL, SEED_AXIS_RTOL, numeric_row, rows_match


def test_rows_match_at_the_stated_tolerances():
    old = [{"step": 1, "loss": 749.19806, "tag": "a", "iteration_seconds": 1.0}]
    assert rows_match(old, [dict(old[0], iteration_seconds=9.0)]) is None  # wall clock aside
    near = [dict(old[0], loss=749.19806 * (1 + 0.5 * RTOL))]
    assert rows_match(old, near) is None
    seed_axis = [dict(old[0], loss=749.19816)]  # 1.3e-7 relative: the seed axis's rounding
    assert rows_match(old, seed_axis) == "row 1, loss: 749.19806 recorded, 749.19816 now"
    assert rows_match(old, seed_axis, rtol=SEED_AXIS_RTOL) is None
    far = [dict(old[0], loss=749.3)]
    assert rows_match(old, far, rtol=SEED_AXIS_RTOL).startswith("row 1, loss: ")
    assert rows_match(old, [dict(old[0], tag="b")]) == "row 1, tag: 'a' recorded, 'b' now"
    assert rows_match(old + old, old) == "the replay logged 1 rows, the run 2"
    assert rows_match([{"step": 1, "x": None}], [{"step": 1, "x": 0.0}]) is not None


def test_another_cpus_rounding_is_not_a_code_change():
    """Rows 1-2 of HiREPS on beer pong (seed 0, full) as recorded, and as the same code
    replayed them on a machine with another CPU: its dual variables moved by rounding alone
    (3e-10 and 1.2e-9 relative); a change of 1e-6 relative is still a difference."""
    recorded = [{"step": 1, "eta": 15.035175704720041, "xi": 3.729672851888331},
                {"step": 2, "eta": 12.033650576965552, "xi": 1.193878048459641}]
    replayed = [{"step": 1, "eta": 15.035175703111374, "xi": 3.7296728506779737},
                {"step": 2, "eta": 12.03365057668383, "xi": 1.1938780499383954}]
    assert rows_match(recorded, replayed) is None
    changed = [replayed[0], dict(replayed[1], xi=1.193878048459641 * (1 + 1e-6))]
    assert rows_match(recorded, changed) == (
        f"row 2, xi: 1.193878048459641 recorded, {1.193878048459641 * (1 + 1e-6)!r} now")


def test_numeric_row_keeps_what_a_recorded_table_keeps():
    row = {"step": 3, "a": 1, "b": 2.5, "c": None, "d": True, "e": "text", "f": [1, 2]}
    assert numeric_row(row) == {"step": 3, "a": 1, "b": 2.5, "c": None}
