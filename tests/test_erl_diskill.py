"""Di-SkilL (Chapter 4, Algorithms 2-3): presets, determinism, exact resume, learning on toys."""

from __future__ import annotations

import dataclasses
import io
from dataclasses import replace
from typing import ClassVar

import numpy as np
import pytest
import torch

from vslbook.budget import get_budget
from vslbook.envs.robot.task import Episode, EpisodicTask
from vslbook.erl import trpl
from vslbook.erl.diskill import DiSkill, train
from vslbook.erl.diskill_config import DiSkillConfig, diskill_config


class Bimodal(EpisodicTask):
    """c ∈ [−1, 1]; R(θ, c) = −4 min_± ‖θ − (c, ±1)‖²: two equally good solutions per context."""

    name = "toy-bimodal"
    context_names = ("c",)
    context_low = np.array([-1.0])
    context_high = np.array([1.0])
    n_params = 2
    has_success: ClassVar[bool] = True

    def episodes(self, theta: np.ndarray, contexts: np.ndarray) -> list[Episode]:
        d = [((theta - np.c_[contexts[:, 0], np.full(len(theta), s)]) ** 2).sum(1) for s in (1, -1)]
        r = -4.0 * np.minimum(*d)
        return [Episode(float(x), bool(x > -0.1)) for x in r]


class Slope(EpisodicTask):
    """c ∈ [−1, 1]; R(θ, c) = 3c − ‖θ‖²: high contexts pay more, whatever θ does."""

    name = "toy-slope"
    context_names = ("c",)
    context_low = np.array([-1.0])
    context_high = np.array([1.0])
    n_params = 1
    has_success: ClassVar[bool] = False

    def episodes(self, theta: np.ndarray, contexts: np.ndarray) -> list[Episode]:
        r = 3.0 * contexts[:, 0] - (theta**2).sum(1)
        return [Episode(float(x)) for x in r]


def small(**kw) -> DiSkillConfig:
    base = dict(
        n_experts=2, alpha=1e-3, beta=1.0, expert_hidden=(16,), critic_hidden=(8,),
        samples_per_expert=32, mean_bound=0.05, cov_bound=0.005, iterations=6,
        env_contexts=400, epochs=10, critic_epochs=10, context_epochs=10, test_every=3,
        test_contexts=20, normaliser_contexts=400,
    )  # fmt: skip
    return DiSkillConfig(**(base | kw))


def run_rows(task, config, seed, **kw):
    rows = []
    s = train(task, config, seed, callback=lambda it, m: rows.append((it, m)), workers=0, **kw)
    return s, rows


# ---------------------------------------------------------------- presets (Tables B.2-B.7)
# task: K, α, β, expert, critic, n, ε_μ, ε_Σ, env contexts, critic lr (written from the tables)
TABLES = {
    "table-tennis-4d": (5, 0.001, 4, (64,), (8, 8), 50, 0.05, 0.005, 5000, 0.0003),
    "reacher5": (10, 0.01, 8, (32, 32), (32, 32), 25, 0.05, 0.001, 5000, 0.0003),
    "table-tennis-hard": (10, 0.001, 0.5, (128,), (8, 8), 50, 0.05, 0.005, 5000, 0.0003),
    "hopper-jump": (3, 0.01, 8, (32, 32), (64, 64), 80, 0.05, 0.005, 1000, 0.0001),
    "box-pushing-obstacle": (10, 0.01, 64, (64, 64), (32, 32), 50, 0.05, 0.005, 5000, 0.0003),
    "mini-golf": (10, 0.0001, 1, (64, 64), (32, 32), 50, 0.05, 0.005, 5000, 0.0003),
}
# task: n, expert, critic, ε_μ, ε_Σ
BBRL = {
    "table-tennis-4d": (209, (32,), (32, 32), 0.05, 0.001),
    "reacher5": (240, (64, 64), (32, 32), 0.05, 0.005),
    "table-tennis-hard": (209, (32, 32), (32, 32), 0.05, 0.0005),
    "hopper-jump": (200, (32, 32), (64, 64), 0.1, 0.05),
    "box-pushing-obstacle": (500, (64, 64), (32, 32), 0.05, 0.0005),
    "mini-golf": (500, (128, 128), (32, 32), 0.05, 0.001),
}
# task: α, ε_μ, ε_Σ of LinDi-SkilL
LINDI = {
    "reacher5": (0.01, 0.05, 0.0005),
    "table-tennis-hard": (0.001, 0.05, 0.001),
    "hopper-jump": (0.01, 0.05, 0.005),
    "box-pushing-obstacle": (0.0001, 0.05, 0.001),
    "mini-golf": (0.0001, 0.01, 0.001),
}


@pytest.mark.parametrize("task", sorted(TABLES))
def test_presets_are_the_tables(task):
    k, a, b, ex, cr, n, em, ec, ne, lrc = TABLES[task]
    c = diskill_config(task, settings="thesis")
    got = (c.n_experts, c.alpha, c.beta, c.expert_hidden, c.critic_hidden, c.samples_per_expert,
           c.mean_bound, c.cov_bound, c.env_contexts, c.lr_critic)  # fmt: skip
    assert got == (k, a, b, ex, cr, n, em, ec, ne, lrc)
    assert (c.lr_policy, c.lr_context, c.epochs, c.context_epochs, c.critic_epochs) == (
        3e-4,
        1e-4,
        100,
        100,
        100,
    )
    assert (c.trust_region_coeff, c.context_hidden, c.curriculum) == (100, (16, 16), True)
    n, ex, cr, em, ec = BBRL[task]
    c = diskill_config(task, "bbrl")
    assert (c.n_experts, c.samples_per_expert, c.expert_hidden, c.critic_hidden) == (1, n, ex, cr)
    assert (c.mean_bound, c.cov_bound, c.trust_region_coeff, c.curriculum, c.alpha) == (
        em,
        ec,
        25,
        False,
        0,
    )
    if task in LINDI:
        c = diskill_config(task, "lindiskill")
        assert (c.alpha, c.mean_bound, c.cov_bound, c.expert_hidden) == LINDI[task] + ((),)


@pytest.mark.parametrize("task", sorted(TABLES))
def test_the_code_settings_differ_from_the_tables_only_where_the_authors_configs_do(task):
    """Di-SkilL's default preset is the authors' configuration (diskill/configs/*.yml): on
    hopper jump 100 episodes per expert (Table B.5: 80), and the EBM baseline over one batch
    on table tennis hard, box pushing and mini golf; everything else is the tables'."""
    thesis, code = diskill_config(task, settings="thesis"), diskill_config(task)
    expected = {"hopper-jump": {"samples_per_expert": (80, 100)},
                "table-tennis-hard": {"reward_baseline_batches": (10, 1)},
                "box-pushing-obstacle": {"reward_baseline_batches": (10, 1)},
                "mini-golf": {"reward_baseline_batches": (10, 1)}}.get(task, {})  # fmt: skip
    differ = {f.name: (getattr(thesis, f.name), getattr(code, f.name))
              for f in dataclasses.fields(code)
              if getattr(thesis, f.name) != getattr(code, f.name)}  # fmt: skip
    assert differ == expected | {"settings": ("thesis", "code")}
    # the other methods have no published configuration: the tables' values either way
    bbrl = diskill_config(task, "bbrl")
    assert dataclasses.replace(bbrl, settings="thesis") == diskill_config(
        task, "bbrl", settings="thesis")  # fmt: skip
    with pytest.raises(ValueError, match=r"settings must be one of \('code', 'thesis'\), got 'x'"):
        diskill_config(task, settings="x")


def test_ablation_variants():
    v2, v3 = (
        diskill_config("table-tennis-4d", "diskill-v2"),
        diskill_config("table-tennis-4d", "diskill-v3"),
    )
    assert (v2.beta, v2.context_responsibilities, v2.n_experts, v2.samples_per_expert) == (
        2000,
        False,
        5,
        50,
    )
    assert (v3.beta, v3.context_responsibilities, v3.samples_per_expert) == (2000, False, 260)


def test_budget_changes_only_counts():
    from vslbook.experiments.ch4_algorithms import DISKILL_ENVS, _defaults

    defaults = _defaults("diskill", DISKILL_ENVS)
    full = defaults("vslbook/Reacher5-v0", get_budget("full"), {})
    red = defaults("vslbook/Reacher5-v0", get_budget("reduced"), {})
    # the counts Fig. 4.3c uses (diskill_runs.counts): at reduced 10 % of the 5LR iterations
    assert full.iterations == 3000 and red.iterations == 300
    assert replace(red, iterations=full.iterations) == full


@pytest.mark.parametrize(
    ("call", "match"),
    [
        (lambda: diskill_config("beer-pong"), "no Di-SkilL configuration for task 'beer-pong'"),
        (lambda: diskill_config("reacher5", "svsl"), "unknown method 'svsl'"),
        (lambda: diskill_config("table-tennis-4d", "lindiskill"), "not on 'table-tennis-4d'"),
        (lambda: diskill_config("reacher5", "diskill-v2"), "curriculum ablation"),
        (lambda: small(alpha=-1.0), "alpha must be a finite number >= 0, got -1.0"),
        (lambda: small(cov_bound=0.0), "cov_bound must be a positive number, got 0.0"),
        (lambda: small(samples_per_expert=0), "samples_per_expert must be a positive integer"),
        (lambda: small(expert_hidden=(16, 0)), r"expert_hidden must be a tuple of positive"),
        (lambda: small(curriculum=False), "n_experts=2"),
    ],
)
def test_bad_input(call, match):
    with pytest.raises(ValueError, match=match):
        call()


# ---------------------------------------------------------------- the loop
@pytest.mark.parametrize(("dtype", "rtol"), [("float64", 1e-6), ("float32", 1e-4)])
def test_sampling_counts_and_trust_region(dtype, rtol):
    """The covariance ends on its trust-region bound: to 1e-6 in float64; in float32 the
    stored factor is the float64 projection rounded to float32 (KL measured in float64)."""
    # large steps: the bound binds
    cfg = small(n_experts=3, samples_per_expert=7, lr_policy=0.05, dtype=dtype)
    s = DiSkill(Bimodal(), cfg, seed=0, workers=0)
    b = s.collect()
    assert b["ctx"].shape == (3, 7, 1) and b["theta"].shape == (3, 7, 2)
    assert b["idx"].shape == (3, 7) and int(b["idx"].max()) < cfg.env_contexts
    # each expert's contexts are rows of the iteration's batch from p(c)
    assert torch.equal(b["ctx"], b["c_env"][b["idx"]])
    assert s.samples == s.episodes == 21
    # the responsibilities of each sample are probabilities: log π̃(o|c,θ) ≤ 0
    assert (b["log_resp"] <= 1e-12).all() and (b["log_resp"] < -1e-6).any()
    s.update_experts(b)
    with torch.no_grad():
        parts = (s.experts.mean(b["ctx"]), s.experts.chol(), b["mean_old"], b["chol_old"])
        m, c = trpl.kl_parts(*(x.double() for x in parts))
    assert (c <= cfg.cov_bound * (1 + rtol)).all()  # the covariance is its projection
    assert torch.allclose(c, torch.full_like(c, cfg.cov_bound), rtol=rtol)  # and binds


def test_deterministic_under_seed():
    _, a = run_rows(Bimodal(), small(iterations=3), seed=4)
    _, b = run_rows(Bimodal(), small(iterations=3), seed=4)
    _, c = run_rows(Bimodal(), small(iterations=3), seed=5)
    strip = [
        [(it, {k: v for k, v in m.items() if k != "iteration_seconds"}) for it, m in r]
        for r in (a, b, c)
    ]
    assert strip[0] == strip[1]
    assert strip[0] != strip[2]


def test_resume_is_exact():
    cfg = small(iterations=6)
    whole, rows = run_rows(Bimodal(), cfg, seed=1)
    first, rows1 = run_rows(Bimodal(), cfg, seed=1, until=3)
    buf = io.BytesIO()
    torch.save(first.state_dict(), buf)
    buf.seek(0)
    again = DiSkill(Bimodal(), cfg, seed=1, workers=0)
    again.load_state_dict(torch.load(buf, weights_only=False))
    _, rows2 = run_rows(Bimodal(), cfg, seed=1, state=again)

    def strip(r):
        return [(it, {k: v for k, v in m.items() if k != "iteration_seconds"}) for it, m in r]

    assert strip(rows1 + rows2) == strip(rows)
    for p, q in zip(whole.experts.parameters(), again.experts.parameters(), strict=True):
        assert torch.equal(p, q)
    for p, q in zip(whole.energies.parameters(), again.energies.parameters(), strict=True):
        assert torch.equal(p, q)


def test_two_experts_find_both_solutions():
    """Bimodal: the return rises from the initial policy's, and both modes (θ₂ = ±1) are taken."""
    cfg = small(iterations=50, test_every=50, epochs=20, critic_epochs=20, context_epochs=20,
                lr_policy=3e-3)  # fmt: skip
    s, rows = run_rows(Bimodal(), cfg, seed=0)
    first, last = rows[0][1]["test_return"], rows[-1][1]["test_return"]
    assert first < -5 and last > first + 4, (first, last)
    grid = torch.linspace(-0.9, 0.9, 7, dtype=s.dtype).reshape(1, 7, 1).expand(2, -1, -1)
    with torch.no_grad():
        means = s.experts.mean(grid)  # (K, 7, 2)
    assert (means[..., 0] - grid[..., 0]).abs().max() < 0.3  # θ₁ follows c
    assert means[..., 1].max() > 0.5 and means[..., 1].min() < -0.5, means[..., 1]


def test_context_distribution_moves_to_rewarding_contexts():
    """Eq. 4.8: with a reward that grows with c, π(c|o) shifts its mass to high c."""
    cfg = small(n_experts=1, iterations=25, beta=0.2, alpha=0.0, test_every=25, lr_context=3e-3)
    s, _ = run_rows(Slope(), cfg, seed=0)
    c = torch.linspace(-1, 1, 201, dtype=s.dtype).reshape(-1, 1)
    with torch.no_grad():
        p = torch.softmax(s.energies.energies(c)[0], 0)
    mean_c = float((p * c[:, 0]).sum())
    assert mean_c > 0.3, mean_c  # p(c) itself has mean 0


# ---------------------------------------------------------------- the command line
TINY = {"n_experts": 3, "samples_per_expert": 4, "env_contexts": 200, "epochs": 3,
        "critic_epochs": 3, "context_epochs": 3, "iterations": 4, "test_every": 2,
        "test_contexts": 6, "normaliser_contexts": 200}  # fmt: skip


def test_cli_run_resumes_exactly_on_the_5_link_reacher(tmp_path, monkeypatch):
    """`vslbook run diskill` on the 5LR task: an interrupted run ends as an uninterrupted one."""
    monkeypatch.setenv("VSLBOOK_WORKERS", "1")
    from vslbook.training import run

    whole = run("diskill", "vslbook/Reacher5-v0", seed=3, budget="smoke", root=tmp_path / "a",
                overrides=TINY, progress=False)  # fmt: skip
    assert whole.done
    part = run("diskill", "vslbook/Reacher5-v0", seed=3, budget="smoke", root=tmp_path / "b",
               overrides=TINY, progress=False, stop_after=1)  # fmt: skip
    assert not part.done
    part = run("diskill", "vslbook/Reacher5-v0", seed=3, budget="smoke", root=tmp_path / "b",
               overrides=TINY, progress=False)  # fmt: skip
    assert part.done

    def rows(rd):
        return [{k: v for k, v in r.items() if k != "iteration_seconds"} for r in rd.metrics()]

    assert rows(whole) == rows(part)
    assert [r["step"] for r in whole.metrics()] == [0, 1, 2, 3, 4]
    assert {"test_return", "test_experts_used"} <= set(whole.metrics()[-1])
    assert whole.metrics()[-1]["samples"] == 4 * 3 * 4  # every 5LR θ is executed
    cfg = whole.config
    assert (cfg["n_experts"], cfg["alpha"], cfg["beta"], cfg["cov_bound"]) == (3, 0.01, 8.0, 0.001)


def test_cli_bad_env_names_the_value(tmp_path):
    from vslbook.training import run

    with pytest.raises(ValueError, match="BeerPong"):
        run("diskill", "vslbook/BeerPong-v0", seed=0, budget="smoke", root=tmp_path, progress=False)
    with pytest.raises(ValueError, match="TableTennis4D"):
        run("lindiskill", "vslbook/TableTennis4D-v0", seed=0, budget="smoke", root=tmp_path,
            progress=False)  # fmt: skip


class HalfRejected(EpisodicTask):
    """c ∈ [−1, 1]; θ with θ₀ > c is rejected unsimulated (−100), else R = −θ₀² − 1."""

    name = "toy-half-rejected"
    context_names = ("c",)
    context_low = np.array([-1.0])
    context_high = np.array([1.0])
    n_params = 1
    has_success: ClassVar[bool] = False

    def episodes(self, theta: np.ndarray, contexts: np.ndarray) -> list[Episode]:
        return [Episode(-100.0, executed=False) if t[0] > c[0] else Episode(-t[0] ** 2 - 1.0)
                for t, c in zip(theta, contexts, strict=True)]  # fmt: skip


def test_executed_return_leaves_the_rejected_penalty_out():
    model = DiSkill(HalfRejected(), small(test_contexts=200), seed=3)
    before = model.iteration
    out = model.test()
    gen = torch.Generator().manual_seed(3 * 1_000_003 + before)  # as test() draws o
    experts = model.choose_experts(model.test_contexts, gen)
    theta = model.mean_parameters(model.test_contexts, experts)
    executed = theta[:, 0] <= model.test_contexts[:, 0]
    assert 0 < executed.mean() < 1  # both kinds present: the check means something
    assert out["test_executed"] == pytest.approx(executed.mean())
    assert out["test_executed_return"] == pytest.approx(np.mean(-theta[executed, 0] ** 2 - 1.0))
    assert out["test_return"] == pytest.approx(
        np.where(executed, -theta[:, 0] ** 2 - 1.0, -100.0).mean())
    rows = model.iterate()
    assert rows["executed_return"] is None or rows["executed_return"] > -100.0
