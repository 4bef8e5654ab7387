"""vslbook.progress: live bars where someone watches, one line per run set on the site."""

from __future__ import annotations

import io
import re

import pytest

from vslbook import progress as P


@pytest.fixture
def mode(monkeypatch):
    def set_mode(value: str | None) -> None:
        if value is None:
            monkeypatch.delenv(P.MODE_ENV, raising=False)
        else:
            monkeypatch.setenv(P.MODE_ENV, value)

    return set_mode


def test_live_is_the_default_and_gives_tqdm(mode):
    from tqdm.auto import tqdm

    for value in (None, "", "live", "LIVE"):
        mode(value)
        assert P.progress_mode() == "live"
        screen = io.StringIO()
        bar = P.progress_bar(total=5, initial=2, desc="svsl beer-pong s0", file=screen)
        assert isinstance(bar, tqdm)
        assert (bar.total, bar.n, bar.desc) == (5, 2, "svsl beer-pong s0")
        bar.update(3)
        bar.close()
        assert P.find_bar_text(screen.getvalue().replace("\r", "\n"))  # tqdm drew it


def test_a_bad_mode_names_the_value_and_the_choices(mode):
    mode("sumary")
    with pytest.raises(ValueError, match=r"VSLBOOK_PROGRESS='sumary'.*live, summary, off"):
        P.progress_mode()
    with pytest.raises(ValueError, match="sumary"):
        P.progress_bar(total=3)
    with pytest.raises(ValueError, match="sumary"), P.run_set_progress("set"):
        pass


def test_summary_prints_nothing_while_running_and_one_line_on_close(mode, capsys):
    mode("summary")
    with P.progress_bar(total=150, desc="SVSL beer-pong s0") as bar:
        for _ in range(150):
            bar.update(1)
        bar.set_postfix(ret="3.2")
        assert capsys.readouterr().out == ""
    out = capsys.readouterr().out
    assert out.count("\n") == 1
    assert re.fullmatch(r"SVSL beer-pong s0: 150/150 iterations in \d+\.\d s, ret=3\.2\n", out)
    bar.close()  # a second close prints nothing
    assert capsys.readouterr().out == ""


def test_summary_counts_a_resumed_bar_and_its_unit(mode, capsys):
    mode("summary")
    bar = P.progress_bar(total=10_000, initial=4_000, desc="dime Pendulum-v1 s0", unit="steps")
    bar.update(6_000)
    bar.close()
    assert re.fullmatch(r"dime Pendulum-v1 s0: 10000/10000 steps \(resumed at 4000\) in "
                        r"\d+\.\d s\n", capsys.readouterr().out)  # fmt: skip


def test_summary_iterable_form_closes_at_the_end(mode, capsys):
    mode("summary")
    seen = list(P.progress_bar(["a", "b", "c"], desc="verify fig3-1 smoke", unit="runs"))
    assert seen == ["a", "b", "c"]
    assert re.fullmatch(r"verify fig3-1 smoke: 3/3 runs in \d+\.\d s\n", capsys.readouterr().out)


@pytest.mark.parametrize("value", ["summary", "off", "live"])
def test_disable_prints_nothing(mode, capsys, value):
    mode(value)
    with P.run_set_progress("set"), P.progress_bar(total=3, desc="x", disable=True) as bar:
        bar.update(3)
    assert capsys.readouterr() == ("", "")


def test_off_prints_nothing(mode, capsys):
    mode("off")
    with P.run_set_progress("set"), P.progress_bar(total=3, desc="x") as bar:
        bar.update(3)
    assert capsys.readouterr() == ("", "")


def test_a_run_set_prints_one_line_for_all_its_bars(mode, capsys):
    mode("summary")
    with P.run_set_progress("Fig. 4.4a runs"):
        with P.run_set_progress("inner"):  # a set inside a set adds to the outer one
            for method in ("diskill", "bbrl"):
                with P.progress_bar(total=2, desc=f"{method} hopper-jump s0") as bar:
                    bar.update(2)
        with P.progress_prefix("2 steps"):
            left_open = P.progress_bar(total=5, desc="dime Pendulum-v1 seeds 0,1", unit="steps")
            left_open.update(5)  # never closed: the set closes it
        assert capsys.readouterr().out == ""
    out = capsys.readouterr().out
    assert out.count("\n") == 1, out
    assert re.fullmatch(
        r"Fig\. 4\.4a runs: trained in \d+\.\d s: diskill hopper-jump s0 2/2 iterations; "
        r"bbrl hopper-jump s0 2/2 iterations; 2 steps: dime Pendulum-v1 seeds 0,1 5/5 steps\n",
        out,
    )
    assert P.find_bar_text(out) == []  # the summary is not mistaken for a bar


def test_a_run_set_of_reused_runs_prints_nothing(mode, capsys):
    mode("summary")
    with P.run_set_progress("beer pong runs"):
        pass
    assert capsys.readouterr().out == ""


def test_a_run_set_stopped_by_an_error_says_so(mode, capsys):
    mode("summary")
    with pytest.raises(RuntimeError), P.run_set_progress("fig3-1 runs"):
        P.progress_bar(total=4, desc="svsl planar-reacher s0").update(1)
        raise RuntimeError("diverged")
    out = capsys.readouterr().out
    assert "fig3-1 runs: trained in" in out and "(stopped by an error)" in out
    assert "svsl planar-reacher s0 1/4 iterations" in out


def test_live_mode_keeps_sets_and_prefixes_transparent(mode, capsys):
    mode("live")
    with P.run_set_progress("set"), P.progress_prefix("GB"):
        bar = P.progress_bar(total=1, desc="dime Pendulum-v1 s0", file=io.StringIO())
        bar.close()
    assert bar.desc == "GB: dime Pendulum-v1 s0"
    assert capsys.readouterr().out == ""


# -- what the site's browser test looks for ------------------------------------------------
FROZEN_PAGE = """<div class="cell_output docutils container">
<div class="output stderr highlight-myst-ansi notranslate"><div class="highlight"><pre>
<span></span>svsl beer-pong s0:   0%|          | 0/150 [00:00&lt;?, ?it/s]
</pre></div></div>
<script type="application/vnd.jupyter.widget-view+json">{"model_id": "a1b2", "version_major": 2}
</script></div>"""


def _text(html: str) -> str:
    """The page's text as a browser shows it (tags removed, entities decoded)."""
    import html as h

    return h.unescape(re.sub(r"<[^>]+>", "", html))


def test_frozen_bars_are_found_in_a_page():
    found = P.frozen_bars(_text(FROZEN_PAGE), FROZEN_PAGE)
    assert found == ["bar text 'svsl beer-pong s0:   0%|          | 0/150 [00:00<?, ?it/s]'",
                     f"1 widget output(s) ({P.WIDGET_MIME})"]  # fmt: skip
    # also a bar that had moved, with unit scaling and a postfix, and no description
    later = "45%|████▌     | 2.3k/5.05k [00:12<00:14, 190steps/s, ret=-812.3]"
    assert P.find_bar_text(f"before\n{later}\nafter") == [later]
    assert P.find_bar_text("100%|██████████| 2/2 [00:01<00:00,  1.9it/s]")


def test_a_page_of_summary_lines_has_no_frozen_bar(mode, capsys):
    mode("summary")
    with P.run_set_progress("fig3-1 runs"), P.progress_bar(total=2, desc="svsl s0") as bar:
        bar.update(2)
    text = "counts at this budget: {'seeds': 2}\n" + capsys.readouterr().out
    text += "40% of the goals | 3/4 experts\n6 runs ready in 12 s\n"  # prose with % and /
    assert P.frozen_bars(text, "<div>plain output</div>") == []


def test_every_bar_of_the_package_goes_through_this_module():
    from pathlib import Path

    package = Path(P.__file__).resolve().parent
    direct = [str(f.relative_to(package)) for f in sorted(package.rglob("*.py"))
              if f.name != "progress.py" and re.search(r"\btqdm\b", f.read_text())]  # fmt: skip
    assert direct == [], f"use vslbook.progress.progress_bar, not tqdm, in {direct}"


def test_the_book_build_executes_the_notebooks_in_summary_mode(monkeypatch, tmp_path):
    import importlib.util

    spec = importlib.util.spec_from_file_location("book_build", P.__file__.replace(
        "vslbook/progress.py", "book/build.py"))  # fmt: skip
    build = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(build)
    for value, expected in ((None, "summary"), ("live", "summary"), ("off", "off")):
        if value is None:
            monkeypatch.delenv(P.MODE_ENV, raising=False)
        else:
            monkeypatch.setenv(P.MODE_ENV, value)
        assert build.progress_mode_for_site() == expected
    # a cache of outputs made before (live bars frozen in them) is emptied once
    cache = tmp_path / "cache"
    (cache / "executed").mkdir(parents=True)
    (cache / "global.db").write_text("old")
    build.prepare_cache(cache)
    assert sorted(p.name for p in cache.iterdir()) == [build.CACHE_STAMP]
    (cache / "global.db").write_text("new")
    build.prepare_cache(cache)  # stamped: kept
    assert (cache / "global.db").read_text() == "new"


@pytest.mark.slow
def test_a_chapter5_run_set_shows_one_line_then_nothing_when_reused(mode, capsys, tmp_path):
    """Real training in summary mode (the site's): DIME's seed axis, two variants."""
    from vslbook.experiments.dime_runs import run_variants

    tiny = dict(total_steps=100_000, learning_starts=0, critic_hidden=16, actor_hidden=16,
                n_diffusion_steps=2, batch_size=16, eval_every=100_000, eval_episodes=1,
                v_min=-1600.0, v_max=100.0, num_threads=1)  # 200 env steps at smoke
    mode("summary")
    kwargs = dict(seeds=2, budget="smoke", root=tmp_path / "runs", tables=tmp_path / "tables",
                  common=tiny)  # progress=True, as the notebook  # fmt: skip
    variants = {"DIME": ("dime", {}), "GB": ("dime", {"general_bridges": True})}
    run_variants("Pendulum-v1", variants, **kwargs)
    out = capsys.readouterr().out
    assert out.count("\n") == 1, out
    assert re.fullmatch(
        r"Pendulum-v1 runs \(2 variant\(s\) × 2 seed\(s\)\): trained in \d+\.\d s: "
        r"DIME: dime Pendulum-v1 seeds 0,1 200/200 steps; "
        r"GB: dime Pendulum-v1 seeds 0,1 200/200 steps\n", out)  # fmt: skip
    run_variants("Pendulum-v1", variants, **kwargs)  # every run reused: no line
    assert capsys.readouterr().out == ""


@pytest.mark.slow
def test_a_page_built_like_the_book_shows_bars_frozen_in_live_mode_and_one_line_in_summary(
    tmp_path,
):
    """A one-notebook site with the book's conf.py (MyST-NB executing through its
    jupyter-cache store): the kernel inherits the mode from the build's environment."""
    import os
    import shutil
    import subprocess
    import sys
    from pathlib import Path

    import nbformat

    root = Path(__file__).resolve().parents[1]
    cell = ("import os\n"
            "from vslbook.progress import progress_bar, run_set_progress\n"
            "print('mode:', os.environ.get('VSLBOOK_PROGRESS'))\n"
            "with run_set_progress('demo runs'):\n"
            "    for s in range(3):\n"
            "        with progress_bar(total=4, desc=f'svsl demo s{s}') as bar:\n"
            "            bar.update(4)\n")  # fmt: skip
    pages = {}
    for mode in ("live", "summary"):
        src = tmp_path / mode / "src"
        src.mkdir(parents=True)
        shutil.copy(root / "book" / "references.bib", src)
        nb = nbformat.v4.new_notebook(cells=[nbformat.v4.new_markdown_cell("# Demo"),
                                             nbformat.v4.new_code_cell(cell)])  # fmt: skip
        nb.metadata["kernelspec"] = {"name": "python3", "display_name": "Python 3",
                                     "language": "python"}  # fmt: skip
        nbformat.write(nb, src / "index.ipynb")
        env = {**os.environ, "VSLBOOK_PROGRESS": mode, "VSLBOOK_BOOK_TIMEOUT": "300",
               "VSLBOOK_BOOK_CACHE": str(tmp_path / mode / "cache"),
               "MPLBACKEND": "module://matplotlib_inline.backend_inline"}  # fmt: skip
        env.pop("VSLBOOK_BOOK_STATIC", None)
        subprocess.run([sys.executable, "-m", "sphinx", "-b", "html", "-q", "-c",
                        str(root / "book"), str(src), str(tmp_path / mode / "site")],
                       check=True, env=env, capture_output=True)  # fmt: skip
        pages[mode] = (tmp_path / mode / "site" / "index.html").read_text()
    live, summary = pages["live"], pages["summary"]
    assert "mode: live" in _text(live) and "mode: summary" in _text(summary)
    assert len(P.frozen_bars(_text(live), live)) == 3  # what the chapters showed: 0/4 each
    assert "svsl demo s0:   0%|          | 0/4 [00:00&lt;?, ?it/s]" in live
    assert P.frozen_bars(_text(summary), summary) == []
    lines = [ln for ln in _text(summary).splitlines() if ln.startswith("demo runs:")]
    assert len(lines) == 1 and lines[0].endswith(
        "svsl demo s0 4/4 iterations; svsl demo s1 4/4 iterations; svsl demo s2 4/4 iterations")
