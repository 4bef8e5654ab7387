from types import SimpleNamespace

from vslbook.experiments.diskill_scores import score_line, verdict


def row(**kw):
    base = {"label": "Di-SkilL", "iqm": 0.123456, "ci_low": 0.1, "ci_high": 0.2,
            "s_per_iteration": 1.234}  # fmt: skip
    return SimpleNamespace(**{**base, **kw})


def test_verdict_words():
    assert verdict(True) == "as in the thesis"
    assert verdict(False) == "NOT as in the thesis"
    assert verdict(None) == "no ranking (each IQM inside the other's 95 % CI)"


def test_score_line_with_and_without_time():
    assert score_line(row()) == "Di-SkilL 0.123 [0.1, 0.2] (1.2 s/it.)"
    assert score_line(row(), with_time=False) == "Di-SkilL 0.123 [0.1, 0.2]"
    assert score_line(row(s_per_iteration=float("nan"))) == "Di-SkilL 0.123 [0.1, 0.2]"


def test_score_line_says_where_a_probe_had_got_to():
    probes = {"diskill-v2": "900/4500 iterations"}
    assert score_line(row(method="diskill-v2"), probes=probes) == (
        "Di-SkilL 0.123 [0.1, 0.2] (1.2 s/it.) (probe at 900/4500 iterations)")
    plain = "Di-SkilL 0.123 [0.1, 0.2] (1.2 s/it.)"
    assert score_line(row(method="diskill"), probes=probes) == plain
    assert score_line(row(), probes=probes) == plain  # a row with no method
