"""Tables B.1-B.7 of the thesis (Chapter 4) for :mod:`vslbook.experiments.thesis_tables`.

The values in ``rows`` are the thesis's (Appendix B.6), typed as printed; the row labels
are the thesis's with its spelling fixed ("ciritc epochs" → "critic epochs") and the
second "initialization" row of each table named "initialization context distr.". ``ours``
is read from the configuration of ``vslbook run diskill|bbrl|lindiskill|ppo-ch4 --budget
full`` (:mod:`vslbook.experiments.ch4_algorithms`: :func:`vslbook.erl.diskill_config.
diskill_config` with the figures' full counts, :func:`vslbook.erl.ppo_ch4.ppo_ch4_config`).
Facts of the code that are no configuration field (tanh layers, orthogonal initialisation,
Adam, full covariances, the KL projection) are read as ``fixed`` with where they are; for
PPO they are stable-baselines3's defaults, read from its signatures.
"""

from __future__ import annotations

import inspect
from typing import Any

from vslbook.experiments.thesis_tables import Fixed, FromAudit, Source, Spec, Via, run_source

__all__ = ["SPECS"]

NA = None  # the thesis's "–"


def _cur(attr: str) -> Via:
    """A field that only a method with a curriculum has (BBRL: "–")."""
    return Via(lambda c: getattr(c, attr) if c.curriculum else None,
               f".{attr} (– without a curriculum)")  # fmt: skip


def _cur_fixed(value: str, where: str) -> Via:
    return Via(lambda c: value if c.curriculum else None,
               f"fixed: {where} (– without a curriculum)")  # fmt: skip


_NETS = "vslbook.erl.diskill_nets"
DISKILL_READERS: dict[str, Any] = {
    "critic activation": Fixed("tanh", f"{_NETS} (tanh MLPs)"),
    "hidden sizes critic": "critic_hidden",
    "initialization": Fixed("orthogonal", f"{_NETS} (orthogonal weights)"),
    "lr critic": "lr_critic",
    "optimizer critic": Fixed("adam", "vslbook.erl.diskill (torch.optim.Adam)"),
    "critic epochs": "critic_epochs",
    "activation context distr.": _cur_fixed("tanh", f"{_NETS}, energy network"),
    "epochs context distr.": _cur("context_epochs"),
    "hidden sizes context distr.": _cur("context_hidden"),
    "initialization context distr.": _cur_fixed("orthogonal", f"{_NETS}, energy network"),
    "lr context distr.": _cur("lr_context"),
    "optimizer context distr.": _cur_fixed("adam", "vslbook.erl.diskill (torch.optim.Adam)"),
    "batch size per expert": Via(lambda c: c.samples_per_expert,
                                 ".samples_per_expert (one full batch per epoch)"),
    "nr. mini batches": NA,
    "nr. samples from env. distr.": _cur("env_contexts"),
    "number samples per expert": "samples_per_expert",
    "normalize advantages": Fixed(True, "vslbook.erl.diskill_updates (standardise)"),
    "expert activation": Via(lambda c: "tanh" if c.expert_hidden else None,
                             f"fixed: {_NETS} (– for linear experts)"),
    "epochs": "epochs",
    "hidden sizes expert": Via(lambda c: c.expert_hidden or None,
                               ".expert_hidden (– for linear experts)"),
    "lr policy": "lr_policy",
    "covariance type": Fixed("full", f"{_NETS} (Cholesky factor)"),
    "alpha": _cur("alpha"),
    "beta": _cur("beta"),
    "number experts": _cur("n_experts"),
    "covariance bound": "cov_bound",
    "mean bound": "mean_bound",
    "projection type": Fixed("KL", "vslbook.erl.trpl (KL projection)"),
    "trust region coefficient": "trust_region_coeff",
    "discount factor": Fixed(1, "Algorithm 2 scores the undiscounted episode return"),
}  # fmt: skip


def _sb3(name: str) -> Any:
    """The default of a stable-baselines3 argument our PPO leaves alone."""
    from stable_baselines3 import PPO
    from stable_baselines3.common.policies import ActorCriticPolicy

    for fn in (ActorCriticPolicy.__init__, PPO.__init__):
        params = inspect.signature(fn).parameters
        if name in params:
            return params[name].default
    raise KeyError(name)


_SB3 = "stable-baselines3's default"
PPO_READERS: dict[str, Any] = {
    "critic activation": Via(lambda c: _sb3("activation_fn").__name__.lower(),
                             f"{_SB3} activation_fn"),
    "hidden sizes critic": "net_arch",
    "initialization": Via(lambda c: "orthogonal" if _sb3("ortho_init") else "default",
                          f"{_SB3} ortho_init"),
    "lr critic": "learning_rate",
    "optimizer critic": Via(lambda c: _sb3("optimizer_class").__name__.lower(),
                            f"{_SB3} optimizer_class"),
    "critic epochs": "n_epochs",
    "batch size per expert": "batch_size",
    "nr. mini batches": "n_minibatches",
    "number samples per expert": "n_rollout_steps",
    "normalize advantages": Via(lambda c: _sb3("normalize_advantage"),
                                f"{_SB3} normalize_advantage"),
    "expert activation": Via(lambda c: _sb3("activation_fn").__name__.lower(),
                             f"{_SB3} activation_fn"),
    "epochs": "n_epochs",
    "hidden sizes expert": "net_arch",
    "lr policy": "learning_rate",
    "covariance type": Fixed("diagonal", "stable-baselines3 DiagGaussianDistribution"),
    "discount factor": "gamma",
}  # fmt: skip
for _p in ("activation context distr.", "epochs context distr.", "hidden sizes context distr.",
           "initialization context distr.", "lr context distr.", "optimizer context distr.",
           "nr. samples from env. distr.", "alpha", "beta", "number experts", "covariance bound",
           "mean bound", "projection type", "trust region coefficient"):  # fmt: skip
    PPO_READERS[_p] = NA

_ENVS = {
    "table-tennis-4d": "vslbook/TableTennis4D-v0",
    "reacher5": "vslbook/Reacher5-v0",
    "table-tennis-hard": "vslbook/TableTennisHard-v0",
    "hopper-jump": "vslbook/HopperJump-v0",
    "box-pushing-obstacle": "vslbook/BoxPushingObstacle-v0",
    "mini-golf": "vslbook/MiniGolf-v0",
}
_PPO_ENVS = {
    "reacher5": "vslbook/Reacher5SparseStep-v0",
    "box-pushing-obstacle": "vslbook/BoxPushingObstacleStep-v0",
}
_ALGOS = {"Di-SkilL": "diskill", "BBRL": "bbrl", "LinDi-SkilL": "lindiskill", "PPO": "ppo-ch4"}
_NOTE = ("ours: vslbook run diskill|bbrl|lindiskill|ppo-ch4 --env ENV --budget full; a "
         "smaller budget runs fewer iterations and seeds (reduced: fewer experts on some "
         "tasks; smoke: also 4 samples per expert), nothing else changes.")  # fmt: skip


def _sources(task: str, methods: tuple[str, ...]) -> tuple[Source, ...]:
    return tuple(
        run_source(m, "ppo-ch4", _PPO_ENVS[task], PPO_READERS) if m == "PPO"
        else run_source(m, _ALGOS[m], _ENVS[task], DISKILL_READERS)
        for m in methods
    )  # fmt: skip


def _table(name: str, caption: str, task: str, methods: tuple[str, ...],
           rows: tuple[tuple[Any, ...], ...], why: dict | None = None) -> Spec:  # fmt: skip
    return Spec(name, caption, header=methods, rows=rows, sources=_sources(task, methods),
                params_are_columns=False, why=why or {}, note=_NOTE)  # fmt: skip


# ---- B.1: SVSL on Chapter 4's table tennis (Fig. 4.3b) -----------------------------------
_ONE_AT_A_TIME = "Algorithm 1 (vslbook.erl.svsl.train): one expert to start, one added at a time"
SVSL_READERS: dict[str, Any] = {
    "add expert every iteration": "iterations_per_expert",
    "fine tune all experts every iteration": "fine_tune_every",
    "number expert adds": Fixed(1, _ONE_AT_A_TIME),
    "number initial experts": Fixed(1, _ONE_AT_A_TIME),
    "number total experts": "n_experts",
    "number traj. samples per expert per iteration": "new_samples_expert",
    "α": "alpha",
    "β": "beta",
    "expert KL-bound": "kl_expert",
    "context KL-bound": "kl_context",
}
B1 = Spec(
    "B.1",
    "Hyperparameters for SVSL on TT.",
    header=("SVSL",),
    rows=(
        ("add expert every iteration", 1000),
        ("fine tune all experts every iteration", 50),
        ("number expert adds", 1),
        ("number initial experts", 1),
        ("number total experts", 20),
        ("number traj. samples per expert per iteration", 200),
        ("α", 0.0001),
        ("β", 0.5),
        ("expert KL-bound", 0.01),
        ("context KL-bound", 0.01),
    ),
    sources=(run_source("SVSL", "svsl", _ENVS["table-tennis-4d"], SVSL_READERS),),
    params_are_columns=False,
    note="ours: vslbook run svsl --env vslbook/TableTennis4D-v0 --budget full (Fig. 4.3b; "
    "what the table leaves open is Chapter 3's table-tennis preset, vslbook.erl.svsl_config); "
    "a smaller budget runs fewer experts, iterations and seeds, nothing else changes.",
)

# ---- B.2-B.7: one block per row of the thesis; columns as in each table -----------------

def _rows(cells: dict[str, tuple[Any, ...]]) -> tuple[tuple[Any, ...], ...]:
    return tuple((k, *v) for k, v in cells.items())


B2 = _table("B.2", "Hyperparameters for Di-SkilL and BBRL on TT.", "table-tennis-4d",
            ("Di-SkilL", "BBRL"), _rows({
    "critic activation": ("tanh", "tanh"),
    "hidden sizes critic": ((8, 8), (32, 32)),
    "initialization": ("orthogonal", "orthogonal"),
    "lr critic": (0.0003, 0.0003),
    "optimizer critic": ("adam", "adam"),
    "critic epochs": (100, 100),
    "activation context distr.": ("tanh", NA),
    "epochs context distr.": (100, NA),
    "hidden sizes context distr.": ((16, 16), NA),
    "initialization context distr.": ("orthogonal", NA),
    "lr context distr.": (0.0001, NA),
    "optimizer context distr.": ("adam", NA),
    "batch size per expert": (50, 209),
    "nr. samples from env. distr.": (5000, NA),
    "number samples per expert": (50, 209),
    "normalize advantages": (True, True),
    "expert activation": ("tanh", "tanh"),
    "epochs": (100, 100),
    "hidden sizes expert": ((64,), (32,)),
    "lr policy": (0.0003, 0.0003),
    "covariance type": ("full", "full"),
    "alpha": (0.001, NA),
    "beta": (4, NA),
    "number experts": (5, NA),
    "covariance bound": (0.005, 0.001),
    "mean bound": (0.05, 0.05),
    "projection type": ("KL", "KL"),
    "trust region coefficient": (100, 25),
}))  # fmt: skip

B3 = _table("B.3", "Hyperparameters for Di-SkilL, BBRL, LinDi-SkilL, and PPO on 5LR (PPO with "
            "all code-level optimisations of Engstrom et al. 2020).", "reacher5",
            ("Di-SkilL", "BBRL", "LinDi-SkilL", "PPO"), _rows({
    "critic activation": ("tanh", "tanh", "tanh", "tanh"),
    "hidden sizes critic": ((32, 32), (32, 32), (32, 32), (32, 32)),
    "initialization": ("orthogonal",) * 4,
    "lr critic": (0.0003, 0.0003, 0.0003, 0.0003),
    "optimizer critic": ("adam",) * 4,
    "critic epochs": (100, 100, 100, 10),
    "activation context distr.": ("tanh", NA, "tanh", NA),
    "epochs context distr.": (100, NA, 100, NA),
    "hidden sizes context distr.": ((16, 16), NA, (16, 16), NA),
    "initialization context distr.": ("orthogonal", NA, "orthogonal", NA),
    "lr context distr.": (0.0001, NA, 0.0001, NA),
    "optimizer context distr.": ("adam", NA, "adam", NA),
    "batch size per expert": (25, 240, 25, 512),
    "nr. mini batches": (NA, NA, NA, 32),
    "nr. samples from env. distr.": (5000, NA, 5000, NA),
    "number samples per expert": (25, 240, 25, 16384),
    "normalize advantages": (True, True, True, True),
    "expert activation": ("tanh", "tanh", NA, "tanh"),
    "epochs": (100, 100, 100, 10),
    "hidden sizes expert": ((32, 32), (64, 64), NA, (32, 32)),
    "lr policy": (0.0003, 0.0003, 0.0003, 0.0003),
    "covariance type": ("full", "full", "full", "diagonal"),
    "alpha": (0.01, NA, 0.01, NA),
    "beta": (8, NA, 8, NA),
    "number experts": (10, NA, 10, NA),
    "covariance bound": (0.001, 0.005, 0.0005, NA),
    "mean bound": (0.05, 0.05, 0.05, NA),
    "projection type": ("KL", "KL", "KL", NA),
    "trust region coefficient": (100, 25, 100, NA),
    "discount factor": (1, 1, 1, 1),
}))  # fmt: skip

B4 = _table("B.4", "Hyperparameters for Di-SkilL, BBRL, and LinDi-SkilL for the Hard Table "
            "Tennis Task (TT-H).", "table-tennis-hard", ("Di-SkilL", "BBRL", "LinDi-SkilL"),
            _rows({
    "critic activation": ("tanh", "tanh", "tanh"),
    "hidden sizes critic": ((8, 8), (32, 32), (8, 8)),
    "initialization": ("orthogonal",) * 3,
    "lr critic": (0.0003, 0.0003, 0.0003),
    "optimizer critic": ("adam",) * 3,
    "critic epochs": (100, 100, 100),
    "activation context distr.": ("tanh", NA, "tanh"),
    "epochs context distr.": (100, NA, 100),
    "hidden sizes context distr.": ((16, 16), NA, (16, 16)),
    "initialization context distr.": ("orthogonal", NA, "orthogonal"),
    "lr context distr.": (0.0001, NA, 0.0001),
    "optimizer context distr.": ("adam", NA, "adam"),
    "batch size per expert": (50, 209, 50),
    "nr. samples from env. distr.": (5000, NA, 5000),
    "number samples per expert": (50, 209, 50),
    "normalize advantages": (True, True, True),
    "expert activation": ("tanh", "tanh", NA),
    "epochs": (100, 100, 100),
    "hidden sizes expert": ((128,), (32, 32), NA),
    "lr policy": (0.0003, 0.0003, 0.0003),
    "covariance type": ("full", "full", "full"),
    "alpha": (0.001, NA, 0.001),
    "beta": (0.5, NA, 0.5),
    "number experts": (10, NA, 10),
    "covariance bound": (0.005, 0.0005, 0.001),
    "mean bound": (0.05, 0.05, 0.05),
    "projection type": ("KL", "KL", "KL"),
    "trust region coefficient": (100, 25, 100),
}))  # fmt: skip

_HJ_SAMPLES = FromAudit(
    4, "diskill/hopper-jump", "samples per expert",
    "the authors' hopper_jump.yml (l.111) draws 100, which made Fig. 4.4a; "
    "diskill_config(..., settings='thesis') gives the table's 80",
)  # fmt: skip
B5 = _table("B.5", "Hyperparameters for Di-Skill, BBRL, and LinDi-Skill for the Hopper Jump "
            "Task (HJ).", "hopper-jump", ("Di-SkilL", "BBRL", "LinDi-SkilL"), _rows({
    "critic activation": ("tanh", "tanh", "tanh"),
    "hidden sizes critic": ((64, 64), (64, 64), (64, 64)),
    "initialization": ("orthogonal",) * 3,
    "lr critic": (0.0001, 0.0001, 0.0001),
    "optimizer critic": ("adam",) * 3,
    "critic epochs": (100, 100, 100),
    "activation context distr.": ("tanh", NA, "tanh"),
    "epochs context distr.": (100, NA, 100),
    "hidden sizes context distr.": ((16, 16), NA, (16, 16)),
    "initialization context distr.": ("orthogonal", NA, "orthogonal"),
    "lr context distr.": (0.0001, NA, 0.0001),
    "optimizer context distr.": ("adam", NA, "adam"),
    "batch size per expert": (80, 200, 80),
    "nr. samples from env. distr.": (1000, NA, 1000),
    "number samples per expert": (80, 200, 80),
    "normalize advantages": (True, True, True),
    "expert activation": ("tanh", "tanh", NA),
    "epochs": (100, 100, 100),
    "hidden sizes expert": ((32, 32), (32, 32), NA),
    "lr policy": (0.0003, 0.0003, 0.0003),
    "covariance type": ("full", "full", "full"),
    "alpha": (0.01, NA, 0.01),
    "beta": (8, NA, 8),
    "number experts": (3, NA, 3),
    "covariance bound": (0.005, 0.05, 0.005),
    "mean bound": (0.05, 0.1, 0.05),
    "projection type": ("KL", "KL", "KL"),
    "trust region coefficient": (100, 25, 100),
}), why={("Di-SkilL", "batch size per expert"): _HJ_SAMPLES,
         ("Di-SkilL", "number samples per expert"): _HJ_SAMPLES})  # fmt: skip

B6 = _table("B.6", "Hyperparameters for Di-SkilL, BBRL, LinDi-SkilL, and PPO for Box Pushing "
            "Obstacle task (BPO) (PPO with all code-level optimisations of Engstrom et al. "
            "2020).", "box-pushing-obstacle", ("Di-SkilL", "BBRL", "LinDi-SkilL", "PPO"), _rows({
    "critic activation": ("tanh", "tanh", "tanh", "tanh"),
    "hidden sizes critic": ((32, 32), (32, 32), (32, 32), (256, 256)),
    "initialization": ("orthogonal",) * 4,
    "lr critic": (0.0003, 0.0003, 0.0003, 0.0001),
    "optimizer critic": ("adam",) * 4,
    "critic epochs": (100, 100, 100, 10),
    "activation context distr.": ("tanh", NA, "tanh", NA),
    "epochs context distr.": (100, NA, 100, NA),
    "hidden sizes context distr.": ((16, 16), NA, (16, 16), NA),
    "initialization context distr.": ("orthogonal", NA, "orthogonal", NA),
    "lr context distr.": (0.0001, NA, 0.0001, NA),
    "optimizer context distr.": ("adam", NA, "adam", NA),
    "batch size per expert": (50, 500, 50, 410),
    "nr. mini batches": (NA, NA, NA, 40),
    "nr. samples from env. distr.": (5000, NA, 5000, NA),
    "number samples per expert": (50, 500, 50, 16384),
    "normalize advantages": (True, True, True, True),
    "expert activation": ("tanh", "tanh", NA, "tanh"),
    "epochs": (100, 100, 100, 10),
    "hidden sizes expert": ((64, 64), (64, 64), NA, (256, 256)),
    "lr policy": (0.0003, 0.0003, 0.0003, 0.0001),
    "covariance type": ("full", "full", "full", "diagonal"),
    "alpha": (0.01, NA, 0.0001, NA),
    "beta": (64, NA, 64, NA),
    "number experts": (10, NA, 10, NA),
    "covariance bound": (0.005, 0.0005, 0.001, NA),
    "mean bound": (0.05, 0.05, 0.05, NA),
    "projection type": ("KL", "KL", "KL", NA),
    "trust region coefficient": (100, 25, 100, NA),
    "discount factor": (1, 1, 1, 1),
}))  # fmt: skip

B7 = _table("B.7", "Hyperparameters for Di-SkilL, BBRL, and LinDi-SkilL for the mini golf task.",
            "mini-golf", ("Di-SkilL", "BBRL", "LinDi-SkilL"), _rows({
    "critic activation": ("tanh", "tanh", "tanh"),
    "hidden sizes critic": ((32, 32), (32, 32), (32, 32)),
    "initialization": ("orthogonal",) * 3,
    "lr critic": (0.0003, 0.0003, 0.0003),
    "optimizer critic": ("adam",) * 3,
    "critic epochs": (100, 100, 100),
    "activation context distr.": ("tanh", NA, "tanh"),
    "epochs context distr.": (100, NA, 100),
    "hidden sizes context distr.": ((16, 16), NA, (16, 16)),
    "initialization context distr.": ("orthogonal", NA, "orthogonal"),
    "lr context distr.": (0.0001, NA, 0.0001),
    "optimizer context distr.": ("adam", NA, "adam"),
    "batch size per expert": (50, 500, 50),
    "nr. samples from env. distr.": (5000, NA, 5000),
    "number samples per expert": (50, 500, 50),
    "normalize advantages": (True, True, True),
    "expert activation": ("tanh", "tanh", NA),
    "epochs": (100, 100, 100),
    "hidden sizes expert": ((64, 64), (128, 128), NA),
    "lr policy": (0.0003, 0.0003, 0.0003),
    "covariance type": ("full", "full", "full"),
    "alpha": (0.0001, NA, 0.0001),
    "beta": (1, NA, 1),
    "number experts": (10, NA, 10),
    "covariance bound": (0.005, 0.001, 0.001),
    "mean bound": (0.05, 0.05, 0.01),
    "projection type": ("KL", "KL", "KL"),
    "trust region coefficient": (100, 25, 100),
}))  # fmt: skip

SPECS = {s.name: s for s in (B1, B2, B3, B4, B5, B6, B7)}
