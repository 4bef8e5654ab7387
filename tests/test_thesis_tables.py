"""The thesis's appendix tables beside our configurations (vslbook.experiments.thesis_tables)."""

from __future__ import annotations

import dataclasses
import functools

import pandas as pd
import pytest

from vslbook.experiments import thesis_tables as T
from vslbook.experiments.thesis_tables import (
    COLUMNS,
    NOT_RUN,
    TABLES,
    Fixed,
    Prose,
    Shown,
    Unavailable,
    Via,
    differs,
    fmt,
    show_thesis_table,
    thesis_summary,
    thesis_table,
)


@functools.cache
def table(name: str) -> pd.DataFrame:
    return thesis_table(name)


@functools.cache
def configs(name: str) -> dict:
    return {s.label: s.config() for s in T._spec(name).sources if s.config is not None}


def cell(name: str, row: str, parameter: str) -> pd.Series:
    t = table(name)
    hit = t[(t["row"] == row) & (t["parameter"] == parameter)]
    assert len(hit) == 1, (name, row, parameter)
    return hit.iloc[0]


@pytest.mark.parametrize("name", TABLES)
def test_every_table_builds(name):
    spec = T._spec(name)
    t = table(name)
    assert tuple(t.columns) == COLUMNS
    assert (t["table"] == name).all()
    assert len(t) == len(spec.rows) * len(spec.header)  # one row per cell of the thesis
    assert t.attrs["caption"].startswith(f"Table {name}: ")
    assert set(t.attrs["sources"]) == {s.label for s in spec.sources}
    assert t["thesis"].map(lambda v: isinstance(v, str) and v != "").all()
    # every difference is on purpose: it has a reason
    flagged = t[t["differs"].map(lambda v: v is True)]
    assert not flagged["why"].isin(["", "no reason recorded"]).any(), flagged


@pytest.mark.parametrize("name", TABLES)
def test_typed_table_is_well_formed(name):
    spec = T._spec(name)
    labels = [s.label for s in spec.sources]
    assert len(set(labels)) == len(labels)
    assert len({r[0] for r in spec.rows}) == len(spec.rows)  # unique row labels
    for row in spec.rows:
        assert len(row) == len(spec.header) + 1, row
    if spec.params_are_columns:  # the thesis's rows are the tasks / methods, in order
        assert [r[0] for r in spec.rows] == labels
    else:
        assert list(spec.header) == labels
    for s in spec.sources:  # a source that is run reads every parameter of the table
        if s.config is not None:
            assert set(s.readers) >= set(spec.params), (s.label, set(spec.params) - set(s.readers))


@pytest.mark.parametrize("name", TABLES)
def test_ours_is_read_from_the_config_objects(name):
    """Each ``ours`` is the field the reader names, on the object the run uses."""
    spec = T._spec(name)
    objects = configs(name)
    for src, param, _ in spec.cells():
        got = cell(name, src.label, param)
        if src.config is None:
            assert got["ours"] == NOT_RUN and got["differs"] is None
            continue
        obj = objects[src.label]
        if isinstance(obj, Unavailable):  # e.g. MyoSuite not installed
            assert got["ours"] == "unavailable" and got["differs"] is None
            continue
        reader = src.readers[param]
        if isinstance(reader, str):
            assert reader in {f.name for f in dataclasses.fields(obj)} or hasattr(obj, reader)
            assert got["ours"] == fmt(getattr(obj, reader))
            assert got["ours from"] == f"{type(obj).__name__}.{reader}"
        elif isinstance(reader, Via):
            assert got["ours"] == fmt(reader.fn(obj))
        elif isinstance(reader, Fixed):
            assert got["ours"] == fmt(reader.value)
            assert got["ours from"].startswith("fixed: ")
        else:
            assert reader is None and got["ours"] == "–"


def test_fixed_facts_are_in_the_code():
    """A ``fixed`` cell names a module of ours; that module has what the cell says."""
    import importlib
    import inspect

    marks = {"tanh": "tanh", "orthogonal": "orthogonal_", "adam": "optim.Adam", "full": "chol",
             "KL": "KL", True: "def standardise"}  # fmt: skip
    seen = 0
    for name in TABLES:
        for src in T._spec(name).sources:
            for reader in src.readers.values():
                if not (isinstance(reader, Fixed) and reader.where.startswith("vslbook.")):
                    continue
                module = importlib.import_module(reader.where.split()[0].rstrip(","))
                key = reader.value.lower() if reader.value == "Adam" else reader.value
                assert marks[key] in inspect.getsource(module), (name, reader)
                seen += 1
    assert seen > 0


def test_ours_uses_the_full_budget_runs():
    from vslbook.budget import get_budget
    from vslbook.experiments.ch3_algorithms import svsl_defaults
    from vslbook.experiments.svsl_table_tennis import table_tennis_counts

    full = table_tennis_counts("full")["iterations_per_expert"]
    assert cell("A.1", "Table Tennis Task", "K")["ours"] == str(full)
    run = svsl_defaults("vslbook/TableTennisCh3-v0", get_budget("full"), {})
    assert run.iterations_per_expert == full
    assert T._spec("A.1").sources[2].how.endswith("--budget full")


def test_known_differences_are_flagged():
    """Checked by hand against thesis.txt and the configs: the authors' code trains
    K = 1000 on table tennis (Table A.1: 800), draws 100 hopper-jump samples per expert
    (Table B.5: 80); DIME's critic has 101 atoms (Table C.2: 100 bins); dm_control's
    humanoid has 21 actuators (Table C.1: 24)."""
    for name, row, param, thesis, ours in (
        ("A.1", "Table Tennis Task", "K", "800", "1000"),
        ("B.5", "Di-SkilL", "number samples per expert", "80", "100"),
        ("C.2", "DIME", "Num. Bins/Quantiles", "100", "101"),
        ("C.3", "DIME", "Num. Bins/Quantiles", "100", "101"),
    ):
        c = cell(name, row, param)
        assert (c["thesis"], c["ours"], c["differs"]) == (thesis, ours, True), c.to_dict()
        assert c["why"]
    c = cell("C.1", "humanoid-run", "Action Space Dim.")
    assert c["thesis"] == "24" and (c["ours"] == "unavailable" or c["differs"] is True)


def test_known_agreements_are_not_flagged():
    for name, row, param, value in (
        ("A.1", "Beer Pong Task", "K", "750"),
        ("A.3", "Table Tennis Task", "α", None),  # log 30
        ("A.5", "Reacher Reward (3.10)", "network structure", "[64, 64]"),
        ("B.3", "Di-SkilL", "covariance bound", "0.001"),
        ("B.3", "LinDi-SkilL", "covariance bound", "0.0005"),
        ("B.3", "BBRL", "alpha", "–"),  # "–" beside "–"
        ("B.6", "PPO", "nr. mini batches", "40"),
        ("B.5", "LinDi-SkilL", "number samples per expert", "80"),
        ("C.3", "CrossQ", "Learn. Rate Critic", "0.0007"),
    ):
        c = cell(name, row, param)
        assert c["differs"] is False, c.to_dict()
        assert c["why"] == ""
        if value is not None:
            assert c["thesis"] == c["ours"] == value


def test_prose_and_runs_we_do_not_have_are_not_compared():
    c = cell("A.1", "Planar Reacher (Ablation)", "α")
    assert c["thesis"].startswith("varies") and c["differs"] is None and c["why"]
    assert not table("B.1")["differs"].any()  # SVSL on Chapter 4's table tennis: all as B.1
    qsm = table("C.2")[table("C.2")["row"] == "QSM"]
    assert (qsm["ours"] == NOT_RUN).all() and qsm["why"].str.startswith("not run here").all()


def test_differs_rules():
    assert differs(0.1, 0.1) is False
    assert differs(1e-4, 1e-5) is True
    assert differs(3, 3.0) is False
    assert differs(None, None) is False and differs(None, 3) is True and differs(3, None) is True
    assert differs((32, 32), (32, 32)) is False and differs((64,), (64, 64)) is True
    assert differs("adam", "Adam") is False and differs("Adam", "AdamW") is True
    assert differs(True, True) is False and differs(True, 1) is True
    assert differs(Shown(4.0, "4dim(A)"), Shown(4.0, "4·dim(A)")) is False
    assert differs(Prose("varies"), 1.0) is None
    assert differs(1.0, Unavailable("no suite")) is None and differs(1.0, NOT_RUN) is None
    assert fmt(None) == "–" and fmt((64, 64)) == "[64, 64]" and fmt(1e6) == "1000000"
    assert fmt(3e-4) == "0.0003" and fmt(Shown(2.5, "N(0, 2.5)")) == "N(0, 2.5)"


def test_summary_counts_the_flags():
    s = thesis_summary(["A.1", "B.5"]).set_index("table")
    assert s.loc["A.1", "differ"] == 1 and s.loc["B.5", "differ"] == 2
    assert s.loc["A.1", "compared"] == 17  # the planar reacher's "varies" is not compared
    assert "800 → 1000" in s.loc["A.1", "differences"]


def test_show_highlights_differences():
    html = show_thesis_table("A.1").to_html()
    assert html.count(T._DIFF) == 1  # one CSS rule for the thesis/ours pair of K
    assert "≠ Table Tennis Task, K" in html and "Table A.1" in html
    long = show_thesis_table("A.1", layout="long")
    assert long.data.shape[0] == len(table("A.1"))
    assert T._DIFF in long.to_html()
    assert T._DIFF not in show_thesis_table("A.2").to_html()


@pytest.mark.parametrize("bad", ["A.9", "a.1", "", None, 1])
def test_unknown_table_is_a_clear_error(bad):
    with pytest.raises(ValueError, match=r"unknown thesis table .*A\.1.*C\.3"):
        thesis_table(bad)
    with pytest.raises(ValueError, match="unknown thesis table"):
        show_thesis_table(bad)


def test_unknown_layout_is_a_clear_error():
    with pytest.raises(ValueError, match="unknown layout 'wide'.*'thesis' or 'long'"):
        show_thesis_table("A.1", layout="wide")
