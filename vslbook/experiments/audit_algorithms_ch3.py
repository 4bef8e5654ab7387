"""The audited hyper-parameters of Chapter 3: typed thesis and code values.

Data for :func:`vslbook.experiments.audit.algorithm_audit` (``chapter=3``). Thesis values are
Tables A.1-A.5; code values come from ``Onur4229/SVSL_LMOE@52b5404`` (the run scripts).
HiREPS and LaDiPS have no public code: those code cells say "not found". ``ours`` is a field
of the configuration object of each subject (see :func:`ch3_configs`). Chapter 4's settings
are in :mod:`vslbook.experiments.audit_algorithms_ch4`.
"""

from __future__ import annotations

import math
from typing import Any

from vslbook.experiments.audit import NOT_FOUND, NOT_STATED, Setting

__all__ = ["ch3_configs", "ch3_settings"]

_SV = "Onur4229/SVSL_LMOE@52b5404 "
_CODE = "code (made the figure)"
_NF = (NOT_FOUND, NOT_FOUND)

_CH3_FIG = {
    "planar-reacher": "Fig. 3.1",
    "beer-pong": "Fig. 3.2a, c, e, f",
    "table-tennis-ch3": "Fig. 3.2b, d, 3.3",
}
_RUN = {
    "planar-reacher": "Planar_Reacher_2d_Run.py",
    "beer-pong": "Beer_Pong_Run.py",
    "table-tennis-ch3": "Table_Tennis_Run.py",
}
# field, our attribute: per task (thesis value, code value, code line) in the run script
_SVSL: dict[str, dict[str, tuple[Any, Any, str]]] = {
    "planar-reacher": {
        "alpha": (NOT_STATED, 1e-4, "52"),
        "beta": (1.0, 1.0, "53"),
        "beta_w": (1.0, 1.0, "54"),
        "n_experts": (60, 60, "43"),
        "iterations_per_expert": (350, 350, "34"),
        "fine_tune_every": (50, 50, "44"),
        "weight_iterations": (NOT_STATED, 100, "35"),
        "kl_context": (NOT_STATED, 0.001, "57"),
        "kl_expert": (NOT_STATED, 0.01, "59"),
        "kl_weights": (NOT_STATED, 0.01, "58"),
        "buffer_size": (NOT_STATED, 136, "38"),
        "new_samples_expert": (NOT_STATED, 81, "41"),
        "new_samples_context": (NOT_STATED, 5, "42"),
        "delete_threshold": (NOT_STATED, 1e-6, "37"),
        "context_init_offset_std": (NOT_STATED, (1.5, 3), "73"),
    },
    "beer-pong": {
        "alpha": (1e-3, 1e-3, "52"),
        "beta": (0.5, 0.5, "53"),
        "beta_w": (2.5, 2.5, "54"),
        "n_experts": (70, 70, "42"),
        "iterations_per_expert": (750, 750, "34"),
        "fine_tune_every": (50, 50, "43"),
        "weight_iterations": (NOT_STATED, 100, "35"),
        "kl_context": (NOT_STATED, 0.005, "55"),
        "kl_expert": (NOT_STATED, 0.01, "57"),
        "kl_weights": (NOT_STATED, 0.01, "56"),
        "buffer_size": (NOT_STATED, 256, "38"),
        "new_samples_expert": (NOT_STATED, 24, "40"),
        "new_samples_context": (NOT_STATED, 12, "41"),
        "delete_threshold": (NOT_STATED, 1e-6, "37"),
        "context_init_offset_std": (NOT_STATED, (0.4, 0.8), "71"),
    },
    "table-tennis-ch3": {
        "alpha": (1e-5, 1e-5, "55"),
        "beta": (0.2, 0.2, "56"),
        "beta_w": (0.2, 0.2, "57"),
        "n_experts": (50, 50, "44"),
        "iterations_per_expert": (800, 1000, "33"),
        "fine_tune_every": (50, 50, "45"),
        "weight_iterations": (NOT_STATED, 100, "34"),
        "kl_context": (NOT_STATED, 0.01, "58"),
        "kl_expert": (NOT_STATED, 0.01, "60"),
        "kl_weights": (NOT_STATED, 0.5, "59"),
        "buffer_size": (NOT_STATED, 567, "37"),
        "new_samples_expert": (NOT_STATED, 226, "40-41"),
        "new_samples_context": (NOT_STATED, 8, "42-43"),
        "delete_threshold": (NOT_STATED, 1e-5, "36"),
        "context_init_offset_std": (NOT_STATED, (0.625, 0.75, 0.58, 0.75), "74"),
    },
}
_SVSL_NAMES = {
    "alpha": "α",
    "beta": "β",
    "beta_w": "β_w",
    "n_experts": "N (experts)",
    "iterations_per_expert": "K (iterations per expert)",
    "fine_tune_every": "H (update all every)",
    "weight_iterations": "weight-update iterations",
    "kl_context": "KL bound π(c|o)",
    "kl_expert": "KL bound π(θ|c,o)",
    "kl_weights": "KL bound π(o)",
    "buffer_size": "buffer per expert",
    "new_samples_expert": "new samples per expert update",
    "new_samples_context": "new samples per context update",
    "delete_threshold": "delete experts with π(o) ≤",
    "context_init_offset_std": "new π(c|o) mean offset std",
}


def _svsl_rows() -> list[Setting]:
    rows = []
    for task, table in _SVSL.items():
        for attr, (thesis, code, line) in table.items():
            why = (
                "both agree"
                if thesis == code
                else (
                    "code (table_tennis_counts(settings=\"thesis\") or --set "
                    "iterations_per_expert=800 gives Table A.1's K)"
                    if attr == "iterations_per_expert"
                    else _CODE
                )
            )
            where = "Table A.1" if thesis != NOT_STATED else "Table A.1 gives none"
            rows.append(
                Setting(
                    f"svsl/{task}",
                    _SVSL_NAMES[attr],
                    thesis,
                    where,
                    code,
                    f"{_SV}{_RUN[task]} l.{line}",
                    attr,
                    _CH3_FIG[task],
                    why,
                )
            )
    # Table A.4, the 5-link reacher (no public code)
    for rew, (a, b, bw, k) in {
        "3.8": (1e-6, 15, 15, 250),
        "3.9": (0.01, 1, 2.5, 250),
        "3.10": (1.0, 25, 25, 800),
    }.items():
        for attr, val in (
            ("alpha", a),
            ("beta", b),
            ("beta_w", bw),
            ("n_experts", 40),
            ("iterations_per_expert", k),
            ("fine_tune_every", 50),
        ):
            rows.append(
                Setting(
                    f"svsl/reacher5-ch3 ({rew})",
                    _SVSL_NAMES[attr],
                    val,
                    "Table A.4",
                    *_NF,
                    attr,
                    "Fig. 3.5",
                    "thesis (no public code)",
                )
            )
    return rows


def _baseline_rows() -> list[Setting]:
    rows = []
    hireps = {
        "planar-reacher": (0.5, 0.99, 60),
        "beer-pong": (0.3, 0.9, 70),
        "table-tennis-ch3": (0.3, 0.9, 50),
    }
    for task, (eps, kappa, n) in hireps.items():
        for name, attr, val in (
            ("ε", "eps", eps),
            ("κ", "kappa", kappa),
            ("N (experts)", "n_experts", n),
        ):
            rows.append(
                Setting(
                    f"hireps/{task}",
                    name,
                    val,
                    "Table A.2",
                    *_NF,
                    attr,
                    _CH3_FIG[task],
                    "thesis (no public code)",
                )
            )
    ladips = {"beer-pong": (0.1, 0.05, 70), "table-tennis-ch3": (0.01, 0.02, 50)}
    for task, (eps, eps_g, n) in ladips.items():
        for name, attr, val in (
            ("ε", "eps", eps),
            ("ε_gating", "eps_gating", eps_g),
            ("α (min. gating entropy)", "alpha", math.log(30)),
            ("N (experts)", "n_experts", n),
        ):
            rows.append(
                Setting(
                    f"ladips/{task}",
                    name,
                    val,
                    "Table A.3",
                    *_NF,
                    attr,
                    _CH3_FIG[task],
                    "thesis (no public code)",
                )
            )
    for name, attr, val in (
        ("learning rate", "learning_rate", 1e-4),
        ("N (steps per update)", "n_rollout_steps", 16384),
        ("GAE λ", "gae_lambda", 0.95),
        ("γ", "gamma", 0.99),
        ("minibatch size", "batch_size", 64),
        ("ratio clip", "clip_range", 0.2),
        ("hidden sizes", "net_arch", (64, 64)),
        ("obs./reward normalised", "normalize", True),
        ("epochs", "n_epochs", NOT_STATED),
    ):
        rows.append(
            Setting(
                "ppo/reacher5-ch3",
                name,
                val,
                "Table A.5" if val != NOT_STATED else "Table A.5 gives none",
                *_NF,
                attr,
                "Fig. 3.5",
                "thesis (stable-baselines3; no public code)",
            )
        )
    return rows


def ch3_settings() -> list[Setting]:
    """The Chapter 3 rows: SVSL (Tables A.1, A.4), HiREPS (A.2), LaDiPS (A.3), PPO (A.5)."""
    return _svsl_rows() + _baseline_rows()


def ch3_configs() -> dict[str, Any]:
    """The package's Chapter 3 configuration objects, by subject."""
    from vslbook.erl.hireps import HIREPS_PRESETS
    from vslbook.erl.ladips import LADIPS_PRESETS
    from vslbook.erl.ppo import PPOConfig
    from vslbook.erl.svsl_config import svsl_config

    out: dict[str, Any] = {f"svsl/{t}": svsl_config(t) for t in _SVSL}
    out |= {
        f"svsl/reacher5-ch3 ({r})": svsl_config("reacher5-ch3", reward=r)
        for r in ("3.8", "3.9", "3.10")
    }
    out |= {f"hireps/{t}": HIREPS_PRESETS[t] for t in _CH3_FIG}
    out |= {f"ladips/{t}": LADIPS_PRESETS[t] for t in ("beer-pong", "table-tennis-ch3")}
    out["ppo/reacher5-ch3"] = PPOConfig()
    return out
