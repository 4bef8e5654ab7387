"""Chapter 4's test curves taken apart: executed return and executed share."""

from __future__ import annotations

import json

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

from vslbook.experiments.diskill_executed import draw_executed  # noqa: E402


def _run(root, name, rows):
    path = root / name
    path.mkdir()
    (path / "config.json").write_text(json.dumps({"seed": 0}))
    (path / "metrics.jsonl").write_text("".join(json.dumps(r) + "\n" for r in rows))
    return path


def test_draws_both_parts_and_says_when_nothing_was_executed(tmp_path):
    rows = [{"step": i, "samples": 10 * i, "test_executed": e, "test_executed_return": r}
            for i, (e, r) in enumerate([(0.0, None), (0.5, -3.0), (1.0, -1.0)])]  # fmt: skip
    runs = {"diskill": [_run(tmp_path, "a", rows)], "bbrl": [_run(tmp_path, "b", rows)]}
    fig, (ax_ret, ax_share) = plt.subplots(1, 2)
    assert draw_executed(ax_ret, ax_share, runs, reps=20)
    ys = ax_share.lines[0].get_ydata()
    assert ys[0] == 0.0 and ys[-1] == 1.0  # the share, from 0 to all executed
    assert max(ax_ret.lines[0].get_ydata()) == -1.0  # no penalty in the executed return
    plt.close(fig)
    never = [{"step": i, "samples": 10 * i, "test_executed": 0.0, "test_executed_return": None}
             for i in range(3)]  # fmt: skip
    fig, (ax_ret, ax_share) = plt.subplots(1, 2)
    assert not draw_executed(ax_ret, ax_share, {"diskill": [_run(tmp_path, "c", never)]}, reps=20)
    assert "every one was rejected" in ax_ret.texts[0].get_text()
    plt.close(fig)
