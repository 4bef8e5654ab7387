import pytest

import vslbook
from vslbook.cli import main
from vslbook.data import paper_curves
from vslbook.stats import iqm_curve


def test_show_source_renders_library_code():
    md = vslbook.show_source(iqm_curve)
    text = getattr(md, "data", md)
    assert "def iqm_curve" in text and "vslbook/stats.py" in text


def test_show_source_rejects_objects_without_source():
    with pytest.raises(TypeError, match="show_source expects a module, class"):
        vslbook.show_source(42)


def test_figure_command_draws_files(tmp_path, capsys):
    assert main(["figure", "movement-primitives", "--out", str(tmp_path)]) == 0
    printed = capsys.readouterr().out.split()
    assert {p.rsplit(".", 1)[-1] for p in printed} == {"png", "pdf"}
    assert (tmp_path / "movement-primitives.png").stat().st_size > 10_000


def test_paper_iqm_curve_has_ci_around_point():
    curve = iqm_curve(paper_curves("dmc_cheetah_run"), reps=200)
    assert (curve.n_runs == 10).all()
    assert ((curve.lo <= curve.iqm + 1e-9) & (curve.iqm <= curve.hi + 1e-9)).all()
    assert curve.iqm.iloc[-1] > 800  # the published final IQM is about 900
