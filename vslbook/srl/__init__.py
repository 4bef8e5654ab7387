"""Step-based RL (Chapter 5, DIME): the building blocks the training loop imports.

``batchrenorm``       BatchRenorm1d, the CrossQ normalisation layer
``c51``               CategoricalSupport (atoms, Bellman atoms, projection), categorical_loss
``critic``            DistributionalCritic, ScalarCritic, DoubleCritic (joint batch), polyak_update
``diffusion_policy``  DiffusionPolicy (denoising chain + entropy bound), PolicySample
``gaussian_policy``   GaussianPolicy, the tanh-Gaussian baseline with the same interface
"""

from __future__ import annotations

from vslbook.srl.batchrenorm import BatchRenorm1d
from vslbook.srl.c51 import CategoricalSupport, categorical_loss
from vslbook.srl.critic import (
    DistributionalCritic,
    DoubleCritic,
    ScalarCritic,
    critic_mlp,
    polyak_update,
)
from vslbook.srl.diffusion_policy import (
    DiffusionPolicy,
    DiffusionPolicyConfig,
    PolicySample,
    ScoreNetwork,
    cosine_schedule,
    tanh_log_det_jacobian,
)
from vslbook.srl.gaussian_policy import GaussianPolicy

__all__ = [
    "BatchRenorm1d",
    "CategoricalSupport",
    "DiffusionPolicy",
    "DiffusionPolicyConfig",
    "DistributionalCritic",
    "DoubleCritic",
    "GaussianPolicy",
    "PolicySample",
    "ScalarCritic",
    "ScoreNetwork",
    "categorical_loss",
    "cosine_schedule",
    "critic_mlp",
    "polyak_update",
    "tanh_log_det_jacobian",
]
