"""Seed every source of randomness from one integer."""

from __future__ import annotations

import random
from typing import Any

import numpy as np
import torch


def seed_everything(
    seed: int, env: Any | None = None, *, deterministic_torch: bool = True
) -> np.random.Generator:
    """Seed python, numpy, torch and (optionally) a gymnasium environment and its spaces.

    Args:
        seed: a non-negative integer.
        env: a gymnasium environment; it is reset with ``seed`` and its action and
            observation spaces are seeded, so ``env.action_space.sample()`` is reproducible.
        deterministic_torch: ask torch for deterministic kernels (CPU results are then
            bit-identical run to run; on CUDA some ops become slower).

    Returns:
        A fresh ``numpy.random.Generator`` seeded with ``seed``; prefer passing it around
        to using numpy's global state.
    """
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise ValueError(f"seed must be a non-negative integer, got {seed!r}")
    seed = int(seed)
    random.seed(seed)
    np.random.seed(seed % 2**32)  # noqa: NPY002 - legacy global state, still used by libraries
    torch.manual_seed(seed)
    if deterministic_torch:
        torch.use_deterministic_algorithms(True, warn_only=True)
    if env is not None:
        env.reset(seed=seed)
        env.action_space.seed(seed)
        env.observation_space.seed(seed)
    return np.random.default_rng(seed)
