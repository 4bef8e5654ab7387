"""RNG state for checkpoints: python's ``random``, numpy (global and a Generator), torch.

A run stores :func:`rng_state` in its checkpoint and calls :func:`restore_rng_state` when it
resumes, so the resumed run draws the same numbers as an uninterrupted one would.
"""

from __future__ import annotations

import random
from collections.abc import Mapping
from typing import Any

import numpy as np

__all__ = ["restore_rng_state", "rng_state"]


def rng_state(generator: np.random.Generator | None = None) -> dict[str, Any]:
    """Capture python's ``random``, numpy's global RNG, ``generator`` and torch's RNGs.

    The result is picklable and meant to be stored in a checkpoint; pass it and the same
    generator to :func:`restore_rng_state` to continue the exact same random stream.
    """
    import torch

    if generator is not None and not isinstance(generator, np.random.Generator):
        raise TypeError(
            f"generator must be a numpy.random.Generator or None, got {type(generator).__name__}"
        )
    return {
        "python": random.getstate(),
        "numpy_global": np.random.get_state(),  # noqa: NPY002 - the legacy global state itself
        "generator": None if generator is None else generator.bit_generator.state,
        "torch": torch.get_rng_state(),
        "torch_cuda": torch.cuda.get_rng_state_all() if torch.cuda.is_available() else None,
    }


def restore_rng_state(
    state: Mapping[str, Any], generator: np.random.Generator | None = None
) -> None:
    """Restore the RNG states captured by :func:`rng_state` (into ``generator`` as well).

    Raises:
        ValueError: ``state`` is not from :func:`rng_state`, or a generator state is
            present but no generator given (or the other way round).
    """
    import torch

    missing = {"python", "numpy_global", "generator", "torch"} - set(state)
    if missing:
        raise ValueError(
            f"not an rng_state() dict: missing keys {sorted(missing)}; got {sorted(state)}"
        )
    if (state["generator"] is None) != (generator is None):
        raise ValueError(
            "the captured state and the call disagree on the numpy Generator: captured "
            f"{'none' if state['generator'] is None else 'one'}, given "
            f"{'none' if generator is None else type(generator).__name__}"
        )
    random.setstate(state["python"])
    np.random.set_state(state["numpy_global"])  # noqa: NPY002 - restoring the global state
    if generator is not None:
        generator.bit_generator.state = state["generator"]
    torch.set_rng_state(state["torch"])
    if state.get("torch_cuda") is not None and torch.cuda.is_available():
        torch.cuda.set_rng_state_all(state["torch_cuda"])
