"""Tables A.1-A.5 of the thesis (Chapter 3) for :mod:`vslbook.experiments.thesis_tables`.

The values in ``rows`` are the thesis's (Appendix A.3 and A.3.3.2), typed as printed.
``ours`` is read from the configuration of ``vslbook run svsl|hireps|ladips|ppo --budget
full`` (:mod:`vslbook.experiments.ch3_algorithms`: Table A.1's SVSL presets with the
figures' full counts, the HiREPS / LaDiPS task presets, :class:`vslbook.erl.ppo.PPOConfig`).
"""

from __future__ import annotations

import math

from vslbook.experiments.thesis_tables import FromAudit, Prose, Shown, Spec, run_source

__all__ = ["SPECS"]

_TASKS = {  # the thesis's row label → the one-step env of the task
    "Planar Reacher (Ablation)": "vslbook/PlanarReacher-v0",
    "Beer Pong Task": "vslbook/BeerPong-v0",
    "Table Tennis Task": "vslbook/TableTennisCh3-v0",
}
_REWARDS = {f"Reacher Reward ({r})": r for r in ("3.8", "3.9", "3.10")}

_SVSL = {
    "α": "alpha", "β": "beta", "β_w": "beta_w", "N": "n_experts", "K": "iterations_per_expert",
    "H": "fine_tune_every",
}  # fmt: skip
_NOTE = ("ours: vslbook run ... --budget full; a smaller budget runs fewer experts (N) and "
         "iterations (K), nothing else changes.")  # fmt: skip

A1 = Spec(
    "A.1",
    "Hyperparameters of our algorithm (SVSL) for all environments.",
    header=tuple(_SVSL),
    rows=(
        ("Planar Reacher (Ablation)", Prose("varies (see section 3.4.1)"), 1.0, 1.0, 60, 350, 50),
        ("Beer Pong Task", 0.001, 0.5, 2.5, 70, 750, 50),
        ("Table Tennis Task", 0.00001, 0.2, 0.2, 50, 800, 50),
    ),
    sources=tuple(run_source(label, "svsl", env, _SVSL) for label, env in _TASKS.items()),
    params_are_columns=True,
    why={
        ("Planar Reacher (Ablation)", "α"): (
            "the thesis varies α across Fig. 3.1's runs; 1e-4 is the authors' run script's "
            "(Planar_Reacher_2d_Run.py l.52) and svsl_config's default"
        ),
        ("Table Tennis Task", "K"): FromAudit(
            3, "svsl/table-tennis-ch3", "K (iterations per expert)",
            "the authors' Table_Tennis_Run.py trains K = 1000; --set iterations_per_expert=800 "
            "gives the table's",
        ),
    },  # fmt: skip
    note=_NOTE,
)

_HIREPS = {"ϵ": "eps", "κ": "kappa", "N": "n_experts"}
A2 = Spec(
    "A.2",
    "Hyperparameters of HiREPS for all environments.",
    header=tuple(_HIREPS),
    rows=(
        ("Planar Reacher (Ablation)", 0.5, 0.99, 60),
        ("Beer Pong Task", 0.3, 0.9, 70),
        ("Table Tennis Task", 0.3, 0.9, 50),
    ),
    sources=tuple(run_source(label, "hireps", env, _HIREPS) for label, env in _TASKS.items()),
    params_are_columns=True,
    note="ours: vslbook run hireps ... --budget full (the task presets of vslbook.erl.hireps).",
)

_LADIPS = {"ϵ": "eps", "ϵ_gating": "eps_gating", "α": "alpha", "N": "n_experts"}
A3 = Spec(
    "A.3",
    "Hyperparameters of LaDiPS.",
    header=tuple(_LADIPS),
    rows=(
        ("Beer Pong Task", 0.1, 0.05, Shown(math.log(30), "log 30"), 70),
        ("Table Tennis Task", 0.01, 0.02, Shown(math.log(30), "log 30"), 50),
    ),
    sources=tuple(
        run_source(label, "ladips", _TASKS[label], _LADIPS)
        for label in ("Beer Pong Task", "Table Tennis Task")
    ),
    params_are_columns=True,
    note="ours: vslbook run ladips ... --budget full (the task presets of vslbook.erl.ladips); "
    "α is log 30 = 3.40.",
)

A4 = Spec(
    "A.4",
    "Hyperparameters of our algorithm (SVSL) for the reacher environment.",
    header=tuple(_SVSL),
    rows=(
        ("Reacher Reward (3.8)", 1e-6, 15, 15, 40, 250, 50),
        ("Reacher Reward (3.9)", 0.01, 1, 2.5, 40, 250, 50),
        ("Reacher Reward (3.10)", 1, 25, 25, 40, 800, 50),
    ),
    sources=tuple(
        run_source(label, "svsl", "vslbook/Reacher5Ch3-v0", _SVSL, reward=r)
        for label, r in _REWARDS.items()
    ),
    params_are_columns=True,
    note=_NOTE,
)

_PPO = {
    "α": "learning_rate", "N": "n_rollout_steps", "GAE λ": "gae_lambda", "γ": "gamma",
    "K": "batch_size", "ϵ": "clip_range", "network structure": "net_arch",
}  # fmt: skip
A5 = Spec(
    "A.5",
    "Hyperparameters of PPO for the reacher environment (α learning rate, N rollouts per "
    "update, γ discount, K batch size, ϵ ratio clip; the layers of both the policy and the "
    "value network).",
    header=tuple(_PPO),
    rows=tuple(
        (label, 1e-4, 16384, 0.95, 0.99, 64, 0.2, (64, 64)) for label in _REWARDS
    ),
    sources=tuple(
        run_source(label, "ppo", "vslbook/Reacher5Ch3Step-v0", _PPO, reward=r)
        for label, r in _REWARDS.items()
    ),
    params_are_columns=True,
    note="ours: vslbook run ppo --env vslbook/Reacher5Ch3Step-v0 --set reward=R --budget full "
    "(stable-baselines3; N is environment steps per update, from 16 environments).",
)

SPECS = {s.name: s for s in (A1, A2, A3, A4, A5)}
