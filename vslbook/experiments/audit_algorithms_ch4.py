"""The audited hyper-parameters of Chapter 4: typed thesis and code values.

Data for :func:`vslbook.experiments.audit.algorithm_audit` (``chapter=4``). Thesis values are
Tables B.2-B.7; code values come from ``ALRhub/di-skill@3e5a9e2`` (``diskill/configs/*.yml``:
the last value of a key, i.e. the grid entry where there is one). Di-SkilL's repository
publishes configurations for TT-H, HJ, BPO and MG only (no TT-4D, 5LR, BBRL, LinDi-SkilL, V2/V3
or PPO ones): those code cells say "not found". ``ours`` is a field of the configuration
object of each subject (see :func:`ch4_configs`). Table B.1 (SVSL on TT in Chapter 4) has no
configuration in this package and no row. Chapter 3's settings are in
:mod:`vslbook.experiments.audit_algorithms_ch3`.
"""

from __future__ import annotations

from typing import Any

from vslbook.experiments.audit import NOT_FOUND, NOT_STATED, Setting

__all__ = ["ch4_configs", "ch4_settings"]

_DS = "ALRhub/di-skill@3e5a9e2 diskill/configs/"
_CODE = "code (made the figure)"
_NF = (NOT_FOUND, NOT_FOUND)

_CH4 = {  # task: (table, figure, code yml or None)
    "table-tennis-4d": ("B.2", "Fig. 4.3b", None),
    "reacher5": ("B.3", "Fig. 4.3c", None),
    "table-tennis-hard": ("B.4", "Fig. 4.4c", "table_tennis.yml"),
    "hopper-jump": ("B.5", "Fig. 4.4a", "hopper_jump.yml"),
    "box-pushing-obstacle": ("B.6", "Fig. 4.4b", "box_pushing.yml"),
    "mini-golf": ("B.7", "Fig. 4.4d", "mini_golf.yml"),
}
# task: K, α, β, expert, critic, n, ε_Σ (thesis, Tables B.2-B.7)
_DI_THESIS = {
    "table-tennis-4d": (5, 1e-3, 4.0, (64,), (8, 8), 50, 0.005),
    "reacher5": (10, 0.01, 8.0, (32, 32), (32, 32), 25, 0.001),
    "table-tennis-hard": (10, 1e-3, 0.5, (128,), (8, 8), 50, 0.005),
    "hopper-jump": (3, 0.01, 8.0, (32, 32), (64, 64), 80, 0.005),
    "box-pushing-obstacle": (10, 0.01, 64.0, (64, 64), (32, 32), 50, 0.005),
    "mini-golf": (10, 1e-4, 1.0, (64, 64), (32, 32), 50, 0.005),
}
# yml: attr → (value, line) (the last occurrence of the key in the file)
_DI_CODE: dict[str, dict[str, tuple[Any, int]]] = {
    "table_tennis.yml": {
        "n_experts": (10, 16),
        "alpha": (1e-3, 95),
        "beta": (0.5, 96),
        "expert_hidden": ((128,), 101),
        "critic_hidden": ((8, 8), 73),
        "samples_per_expert": (50, 103),
        "cov_bound": (0.005, 99),
        "mean_bound": (0.05, 98),
        "iterations": (4500, 4),
        "env_contexts": (5000, 37),
        "lr_critic": (3e-4, 77),
        "reward_baseline_batches": (1, 39),
    },
    "hopper_jump.yml": {
        "n_experts": (3, 17),
        "alpha": (0.01, 96),
        "beta": (8.0, 97),
        "expert_hidden": ((32, 32), 109),
        "critic_hidden": ((64, 64), 102),
        "samples_per_expert": (100, 111),
        "cov_bound": (0.005, 99),
        "mean_bound": (0.05, 100),
        "iterations": (1400, 5),
        "env_contexts": (1000, 38),
        "lr_critic": (1e-4, 103),
        "reward_baseline_batches": (10, 40),
    },
    "box_pushing.yml": {
        "n_experts": (10, 17),
        "alpha": (0.01, 99),
        "beta": (64.0, 98),
        "expert_hidden": ((64, 64), 101),
        "critic_hidden": ((32, 32), 74),
        "samples_per_expert": (50, 105),
        "cov_bound": (0.005, 96),
        "mean_bound": (0.05, 56),
        "iterations": (4500, 5),
        "env_contexts": (5000, 38),
        "lr_critic": (3e-4, 78),
        "reward_baseline_batches": (1, 40),
    },
    "mini_golf.yml": {
        "n_experts": (10, 16),
        "alpha": (1e-4, 98),
        "beta": (1.0, 99),
        "expert_hidden": ((64, 64), 101),
        "critic_hidden": ((32, 32), 73),
        "samples_per_expert": (50, 105),
        "cov_bound": (0.005, 95),
        "mean_bound": (0.05, 96),
        "iterations": (4500, 4),
        "env_contexts": (5000, 37),
        "lr_critic": (3e-4, 77),
        "reward_baseline_batches": (1, 39),
    },
}
# attr: (name, thesis value for every task or None (per task), yml line in the 4 files)
_COMMON = {
    "trust_region_coeff": ("trust-region coefficient", 100.0, 100.0, "trust_region_coeff"),
    "context_hidden": ("EBM hidden sizes", (16, 16), (16, 16), "hidden_sizes_ctxt_distr"),
    "lr_policy": ("expert learning rate", 3e-4, 3e-4, "lr_policy"),
    "lr_context": ("EBM learning rate", 1e-4, 1e-4, "lr_ctxt_distr"),
    "epochs": ("expert epochs", 100, 100, "epochs"),
    "critic_epochs": ("critic epochs", 100, 100, "val_epochs"),
    "context_epochs": ("EBM epochs", 100, 100, "epochs_ctxt_distr"),
    "init_std": ("initial std", NOT_STATED, 1.0, "init_std"),
    "test_every": ("test every (iterations)", NOT_STATED, 5, "test_every_it"),
    "test_contexts": ("test contexts", NOT_STATED, 75, "n_test_samples"),
    "context_clip": ("EBM ratio clip", NOT_STATED, 0.2, "importance_ratio_clip_ctxt_distr"),
}
_NAMES = {
    "n_experts": "K (experts)",
    "alpha": "α",
    "beta": "β",
    "expert_hidden": "expert hidden sizes",
    "critic_hidden": "critic hidden sizes",
    "samples_per_expert": "samples per expert",
    "cov_bound": "ε_Σ",
    "mean_bound": "ε_μ",
    "iterations": "iterations",
    "env_contexts": "contexts from p(c) per iteration",
    "lr_critic": "critic learning rate",
    "reward_baseline_batches": "EBM reward baseline (batches)",
}


def _diskill_rows() -> list[Setting]:
    rows = []
    for task, (table, fig, yml) in _CH4.items():
        k, a, b, ex, cr, n, cov = _DI_THESIS[task]
        thesis = {
            "n_experts": k,
            "alpha": a,
            "beta": b,
            "expert_hidden": ex,
            "critic_hidden": cr,
            "samples_per_expert": n,
            "cov_bound": cov,
            "mean_bound": 0.05,
            "iterations": NOT_STATED,
            "env_contexts": 1000 if task == "hopper-jump" else 5000,
            "lr_critic": 1e-4 if task == "hopper-jump" else 3e-4,
            "reward_baseline_batches": NOT_STATED,
        }
        for attr, t in thesis.items():
            c, line = _DI_CODE[yml][attr] if yml else (NOT_FOUND, 0)
            where = f"{_DS}{yml} l.{line}" if yml else NOT_FOUND
            tw = f"Table {table}" if t != NOT_STATED else f"Table {table} gives none"
            why = (
                "code (diskill_config's CODE_SETTINGS; settings='thesis' has no value here, "
                "so 10, HJ's, where nothing is published)"
                if attr == "reward_baseline_batches"
                else "code: its 100 made Fig. 4.4a (settings='thesis' gives Table B.5's 80)"
                if (task, attr) == ("hopper-jump", "samples_per_expert")
                else "both agree"
                if t == c
                else _CODE
                if c != NOT_FOUND
                else "thesis (no published configuration)"
            )
            rows.append(Setting(f"diskill/{task}", _NAMES[attr], t, tw, c, where, attr, fig, why))
        for attr, (name, t, c, key) in _COMMON.items():
            where = f"{_DS}{yml} key {key}" if yml else NOT_FOUND
            rows.append(
                Setting(
                    f"diskill/{task}",
                    name,
                    t,
                    "Tables B.2-B.7 (all tasks)"
                    if t != NOT_STATED
                    else "Tables B.2-B.7 give none",
                    c if yml else NOT_FOUND,
                    where,
                    attr,
                    fig,
                    "both agree" if t == c else _CODE,
                )
            )
    return rows


# method/task: attr → thesis value (no published configuration for these methods)
_OTHER: dict[str, dict[str, Any]] = {
    **{
        f"bbrl/{t}": {
            "samples_per_expert": n,
            "expert_hidden": net,
            "cov_bound": cov,
            "mean_bound": mb,
            "trust_region_coeff": 25.0,
        }
        for t, (n, net, cov, mb) in {
            "table-tennis-4d": (209, (32,), 0.001, 0.05),
            "reacher5": (240, (64, 64), 0.005, 0.05),
            "table-tennis-hard": (209, (32, 32), 0.0005, 0.05),
            "hopper-jump": (200, (32, 32), 0.05, 0.1),
            "box-pushing-obstacle": (500, (64, 64), 0.0005, 0.05),
            "mini-golf": (500, (128, 128), 0.001, 0.05),
        }.items()
    },
    "lindiskill/reacher5": {"cov_bound": 0.0005, "expert_hidden": ()},
    "lindiskill/table-tennis-hard": {"cov_bound": 0.001, "expert_hidden": ()},
    "lindiskill/hopper-jump": {"cov_bound": 0.005, "expert_hidden": ()},
    "lindiskill/box-pushing-obstacle": {"cov_bound": 0.001, "alpha": 1e-4, "expert_hidden": ()},
    "lindiskill/mini-golf": {"cov_bound": 0.001, "mean_bound": 0.01, "expert_hidden": ()},
    "diskill-v2/table-tennis-4d": {
        "n_experts": 5,
        "beta": 2000.0,
        "context_responsibilities": False,
    },
    "diskill-v3/table-tennis-4d": {
        "n_experts": 5,
        "beta": 2000.0,
        "context_responsibilities": False,
        "samples_per_expert": 260,
    },
    "ppo/reacher5": {
        "learning_rate": 3e-4,
        "batch_size": 512,
        "net_arch": (32, 32),
        "n_epochs": 10,
        "n_rollout_steps": 16384,
        "gamma": 1.0,
    },
    "ppo/box-pushing-obstacle": {
        "learning_rate": 1e-4,
        "batch_size": 410,
        "net_arch": (256, 256),
        "n_epochs": 10,
        "n_rollout_steps": 16384,
        "gamma": 1.0,
    },
}
_MORE_NAMES = {
    "trust_region_coeff": "trust-region coefficient",
    "context_responsibilities": "log π̃(o|c) in the context objective",
    "learning_rate": "learning rate",
    "batch_size": "minibatch size",
    "net_arch": "hidden sizes",
    "n_epochs": "epochs",
    "n_rollout_steps": "samples per update",
    "gamma": "γ",
}


def _other_rows() -> list[Setting]:
    rows = []
    for subject, table in _OTHER.items():
        task = subject.split("/")[1]
        tab, fig, _ = _CH4[task]
        where = (
            "Fig. 4.3b caption, Sec. 4.5.3" if subject.startswith("diskill-v") else f"Table {tab}"
        )
        for attr, val in table.items():
            name = _NAMES.get(attr) or _MORE_NAMES[attr]
            rows.append(
                Setting(
                    subject,
                    name,
                    val,
                    where,
                    *_NF,
                    attr,
                    fig,
                    "thesis (no published configuration)",
                )
            )
    return rows


def ch4_settings() -> list[Setting]:
    """The Chapter 4 rows: Di-SkilL (Tables B.2-B.7), BBRL, LinDi-SkilL, V2/V3, PPO (B.3, B.6)."""
    return _diskill_rows() + _other_rows()


def ch4_configs() -> dict[str, Any]:
    """The package's Chapter 4 configuration objects, by subject."""
    from vslbook.erl.diskill_config import diskill_config
    from vslbook.erl.ppo_ch4 import ppo_ch4_config

    out: dict[str, Any] = {f"diskill/{t}": diskill_config(t) for t in _CH4}
    for subject in _OTHER:
        method, task = subject.split("/")
        out[subject] = ppo_ch4_config(task) if method == "ppo" else diskill_config(task, method)
    return out
