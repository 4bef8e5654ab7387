"""The thesis's claims checked on a figure's final scores (vslbook.experiments.reproduction)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from vslbook.experiments.figure_sources import FigureSet
from vslbook.experiments.reproduction import (
    CLAIMS,
    final_scores,
    reproduction_text,
    verdicts,
)


def _run(root: Path, name: str, env: str, finals: list[float | None]) -> Path:
    """A run directory whose rows log ``test_success`` = each of ``finals`` in turn."""
    path = root / name
    path.mkdir(parents=True)
    (path / "config.json").write_text(json.dumps({"env": env, "seed": 0}))
    rows = [{"step": i, "test_success": v, "grid_success": v} for i, v in enumerate(finals)]
    (path / "metrics.jsonl").write_text("".join(json.dumps(r) + "\n" for r in rows))
    return path


BP, TT = "vslbook/BeerPong-v0", "vslbook/TableTennisCh3-v0"


@pytest.fixture
def beer_pong(tmp_path):
    svsl = [_run(tmp_path, f"svsl-{i}", BP, [0.1, v]) for i, v in enumerate((0.7, 0.9, 0.85, 1.0))]
    hireps = [_run(tmp_path, f"hireps-{i}", BP, [v, None]) for i, v in enumerate((0.7, 0.8))]
    return FigureSet("fig3-2", "full", {"SVSL": svsl, "HiREPS": hireps})


def test_final_scores_take_each_runs_last_value_and_the_iqm(beer_pong):
    scores = final_scores(beer_pong.runs, "test_success", reps=200).set_index("method")
    # IQM of four values: the mean of the middle two (0.85, 0.9); of two: their mean
    assert scores.loc["SVSL", "iqm"] == pytest.approx(0.875)
    assert scores.loc["HiREPS", "iqm"] == pytest.approx(0.75)
    assert scores.loc["SVSL", "ci_low"] <= 0.875 <= scores.loc["SVSL", "ci_high"]
    assert list(scores["runs"]) == [4, 2]


def test_claims_met_not_met_pending_and_smoke(beer_pong, tmp_path):
    v = verdicts("fig3-2", beer_pong, "test_success", reps=200)
    assert list(v["status"]) == ["met", "met"] and v["seeds"][1] == {"SVSL": 4, "HiREPS": 2}
    low = FigureSet("fig3-2", "full", {"SVSL": beer_pong.runs["SVSL"][:1]})
    assert list(verdicts("fig3-2", low, "test_success", reps=200)["status"]) == [
        "not met", "pending"]  # fmt: skip
    smoke = FigureSet("fig3-2", "smoke", beer_pong.runs)
    assert set(verdicts("fig3-2", smoke, "test_success", reps=200)["status"]) == {"smoke"}
    # another task's runs and probes are not scored
    tt = _run(tmp_path, "svsl-tt", TT, [0.0])
    probe = _run(tmp_path, "svsl-probe", BP, [0.0])
    mixed = FigureSet("fig3-2", "full", {"SVSL": [*beer_pong.runs["SVSL"], tt, probe],
                                         "HiREPS": beer_pong.runs["HiREPS"]},
                      probes={"svsl-probe": "10/52600 iterations"})  # fmt: skip
    assert verdicts("fig3-2", mixed, "test_success", reps=200)["seeds"][0] == {"SVSL": 4}


def test_above_needs_the_iqm_above_the_others_ci(beer_pong, tmp_path):
    # HiREPS 0.7 and 0.95: IQM (two runs: their mean) 0.825; bootstrap means of two draws
    # are 0.7, 0.825 or 0.95 (a quarter, half, quarter), so the CI's upper end is 0.95.
    # SVSL's IQM 0.875 is above HiREPS's IQM but inside its CI: not "above"
    spread = [_run(tmp_path, f"hireps-wide-{i}", BP, [v]) for i, v in enumerate((0.7, 0.95))]
    fs = FigureSet("fig3-2", "full", {"SVSL": beer_pong.runs["SVSL"], "HiREPS": spread})
    scores = final_scores(fs.runs, "test_success", reps=200).set_index("method")
    assert scores.loc["HiREPS", "iqm"] < scores.loc["SVSL", "iqm"] < 0.95
    assert scores.loc["HiREPS", "ci_high"] == pytest.approx(0.95)
    assert list(verdicts("fig3-2", fs, "test_success", reps=200)["status"]) == ["met", "not met"]


def test_ranked_needs_an_iqm_outside_the_others_ci():
    import pandas as pd

    from vslbook.experiments.reproduction import ranked

    scores = pd.DataFrame({"method": ["A", "B", "C"], "iqm": [1.0, 0.8, 1.2],
                           "ci_low": [0.5, 0.7, 0.6], "ci_high": [1.5, 0.9, 1.6]})  # fmt: skip
    assert ranked(scores, "A", "B") is True  # 1.0 above B's 0.9
    assert ranked(scores, "B", "A") is False  # A's 1.0 above B's upper end 0.9
    assert ranked(scores, "A", "C") is None  # 1.0 < 1.6 and 1.2 < 1.5: inside each other's CI
    assert ranked(scores, "C", "B") is True
    with pytest.raises(ValueError, match=r"no final scores for \['D'\]"):
        ranked(scores, "A", "D")


def test_text_puts_the_thesis_numbers_beside_ours(beer_pong):
    text = reproduction_text("fig3-2", beer_pong, "test_success", reps=200)
    assert "SVSL: 0.875 [" in text and "4 seed(s); the thesis's: 0.92" in text
    assert "met: beer pong: SVSL above HiREPS" in text


def test_every_claim_names_a_kind_it_can_check():
    kinds = {c.kind for claims in CLAIMS.values() for c in claims}
    assert kinds <= {"at_least", "above", "within_or_above", "within_or_above_published"}


def test_a_claim_of_an_unknown_kind_or_a_stray_curve_is_refused():
    from vslbook.experiments.reproduction import Claim

    with pytest.raises(ValueError, match=r"claim kind 'below'; expected one of"):
        Claim("x", "below", "DIME")
    with pytest.raises(ValueError, match="published curve"):
        Claim("x", "above", "DIME", "CrossQ", published="dmc_cheetah_run")
    with pytest.raises(ValueError, match="published curve"):
        Claim("x", "within_or_above_published", "DIME")


def _dime(root: Path, name: str, steps: list[int], returns: list[float]) -> Path:
    path = root / name
    path.mkdir(parents=True)
    (path / "config.json").write_text(json.dumps({"env": "dm_control/cheetah-run-v0"}))
    rows = [{"step": s, "eval_return": v} for s, v in zip(steps, returns, strict=True)]
    (path / "metrics.jsonl").write_text("".join(json.dumps(r) + "\n" for r in rows))
    return path


def test_cheetah_is_held_against_the_published_curve_where_our_runs_end(tmp_path):
    import pandas as pd
    from scipy.stats import trim_mean

    from vslbook.experiments.reproduction import published_at

    # independent: the authors' returns at 48k steps from the csv, their 25 %-trimmed mean
    csv = pd.read_csv(Path(__file__).resolve().parents[1] / "data/paper/dime_learning_curves.csv")
    at = csv[(csv.env == "dmc_cheetah_run") & (csv.env_steps == 48_000)].mean_return
    pub = published_at("dmc_cheetah_run", 49_000, reps=200)  # nearest published step: 48k
    assert pub["step"] == 48_000 and pub["seeds"] == len(at) == 10
    assert pub["iqm"] == pytest.approx(trim_mean(at, 0.25))
    assert pub["ci_low"] <= pub["iqm"] <= pub["ci_high"]

    def status(final: float) -> str:
        runs = [_dime(tmp_path / f"{final}", f"d{i}", [24_000, end], [1.0, final])
                for i, end in enumerate((48_000, 50_000))]  # the shorter run sets the step
        fs = FigureSet("fig5-3-cheetah", "reduced", {"DIME": runs})
        return verdicts("fig5-3-cheetah", fs, "eval_return", reps=200)["status"].iloc[0]

    assert status(pub["ci_low"] + 1.0) == "met"
    assert status(pub["ci_low"] - 1.0) == "not met"


def test_a_run_without_the_metric_is_named(tmp_path):
    path = _run(tmp_path, "r", BP, [None])
    with pytest.raises(ValueError, match=r"r: no 'test_success' in its metrics"):
        final_scores({"SVSL": [path]}, "test_success")


def test_a_run_without_the_claims_metric_is_not_logged(tmp_path):
    path = _run(tmp_path, "old", BP, [0.5])
    rows = [{"step": 0, "test_success": 0.5}]  # written before grid_success was logged
    (path / "metrics.jsonl").write_text("".join(json.dumps(r) + "\n" for r in rows))
    fs = FigureSet("fig3-2", "full", {"SVSL": [path]})
    assert set(verdicts("fig3-2", fs, "test_success", reps=50)["status"]) == {"not logged"}


def test_overview_reads_each_figures_runs(monkeypatch, tmp_path):
    import vslbook.experiments.figure_sources as FS
    from vslbook.experiments.reproduction import claims_overview

    svsl = [_run(tmp_path, f"s{i}", BP, [v]) for i, v in enumerate((0.9, 0.95))]
    fake = FigureSet("fig3-2", "full", {"SVSL": svsl}, recorded={"s0": {}, "s1": {}})
    monkeypatch.setattr(FS, "figure_set", lambda figure, budget, root: fake)
    table = claims_overview(["fig3-2"], reps=50)
    assert list(table["status"]) == ["met", "pending"]
    assert list(table["runs"]) == ["recorded, full", "recorded, full"]
    assert table["seeds"].iloc[0] == "SVSL 2"


def test_the_claims_table_shows_every_claim_in_full():
    import pandas as pd

    from vslbook.experiments.reproduction import STATUS_COLOURS, show_claims

    claim = "beer pong: " + "a long claim " * 10
    table = pd.DataFrame([{"figure": "fig3-2", "claim": claim, "status": "not met",
                           "seeds": "SVSL 3", "runs": "recorded, full"}])  # fmt: skip
    html = show_claims(table).to_html()
    assert claim in html and STATUS_COLOURS["not met"] in html
    with pytest.raises(ValueError, match=r"not a claims table \(missing columns \['figure'"):
        show_claims(pd.DataFrame({"a": [1]}))
