"""DIME: diffusion-based maximum entropy RL (Chapter 5, Algorithm 4), plus CrossQ.

The algorithm is split along the chapter:

``dime_config``   the hyper-parameters (Tables C.2 / C.3), the CrossQ and Gaussian variants
``dime_updates``  the agent and its updates: critic (Eq. 5.21 / 5.24), actor (Eq. 5.27),
                  temperature (Eq. 5.28), as pure functions
``dime_env``      the environments, their seeded resets, acting (l. 3) and evaluation
``dime_state``    what a run holds (θ, ϕ, α, D, streams, counters): created, resumed and
                  checkpointed
``dime_loop``     Algorithm 4 itself (:func:`~vslbook.srl.dime_loop.run_algorithm4`: collect,
                  update, evaluate) and :func:`train`, one seed
``dime_seeds``    the same loop over a seed axis (:func:`~vslbook.srl.dime_seeds.train_seeds`)

This module gathers their public names and registers ``dime``, ``dime-gaussian`` and
``crossq`` with :mod:`vslbook.registry`, so ``vslbook run dime`` trains one seed through
:func:`train` and ``vslbook run dime --seeds 0 1 2`` several through ``train_seeds``.
"""

from __future__ import annotations

from functools import partial

from vslbook.registry import register_algorithm
from vslbook.srl.dime_config import CrossQConfig, DIMEConfig, DIMEGaussianConfig
from vslbook.srl.dime_env import act, default_value_range, evaluate, make_env, validate_env
from vslbook.srl.dime_loop import DimeLoop, run_algorithm4, train
from vslbook.srl.dime_seeds import train_seeds
from vslbook.srl.dime_state import SeedState, eval_row
from vslbook.srl.dime_updates import (
    Agent,
    UpdateStats,
    actor_update,
    alpha_update,
    combine_q,
    critic_update,
    make_agent,
    q_values,
    resolve_device,
)

__all__ = [
    "Agent",
    "CrossQConfig",
    "DIMEConfig",
    "DIMEGaussianConfig",
    "DimeLoop",
    "SeedState",
    "UpdateStats",
    "act",
    "actor_update",
    "alpha_update",
    "combine_q",
    "critic_update",
    "default_value_range",
    "eval_row",
    "evaluate",
    "make_agent",
    "make_env",
    "q_values",
    "resolve_device",
    "run_algorithm4",
    "train",
    "train_seeds",
]

#: Chapter 5's runs never import the episodic (Chapters 2-4) code.
NOT_SRL = ("erl/", "envs/robot/", "experiments/")

register_algorithm(
    "dime",
    train=train,
    config=DIMEConfig,
    doc="DIME (Algorithm 4): diffusion policy, distributional CrossQ critics, autotuned α",
    independent_of=NOT_SRL,
    train_seeds=train_seeds,
    validate_env=validate_env,
)
register_algorithm(
    "dime-gaussian",
    train=partial(train, config_cls=DIMEGaussianConfig),
    config=DIMEGaussianConfig,
    doc="DIME's critic and updates with a tanh-Gaussian policy (Fig. 5.4c-d ablation)",
    independent_of=NOT_SRL,
    train_seeds=partial(train_seeds, config_cls=DIMEGaussianConfig),
    validate_env=validate_env,
)
register_algorithm(
    "crossq",
    train=partial(train, config_cls=CrossQConfig),
    config=CrossQConfig,
    doc="CrossQ: tanh-Gaussian policy, BatchRenorm scalar critics, no target network",
    independent_of=NOT_SRL,
    train_seeds=partial(train_seeds, config_cls=CrossQConfig),
    validate_env=validate_env,
)
