"""Divergence of a training run, watched on the device (Algorithm 4's update loops).

A GPU runs the updates asynchronously; reading a loss on the host after every update would
make the host wait for each one. :class:`FiniteWatch` records the first non-finite update
with tensor operations only, and the loops read it (one host sync) where they sync anyway
or must know: at evaluations, episode ends and before checkpoints.
"""

from __future__ import annotations

import numpy as np
import torch
from torch import Tensor

from vslbook.results import DivergenceError

__all__ = ["WATCHED", "FiniteWatch"]


class FiniteWatch:
    """The update losses' finiteness, watched on the device without a host sync per update.

    :meth:`add` records, with tensor operations only, the environment step and the values of
    the first update that produced a non-finite one (per seed, with ``seeds``: values then
    have a leading seed axis); :meth:`failures` reads them (one host sync) as
    :class:`DivergenceError` s naming that step and quantity, and :meth:`check` raises the
    first. The training loops check at every evaluation and episode end, before a checkpoint
    is written, so a diverged agent is never saved and a GPU's queue of updates is never
    drained just to look at a loss.
    """

    def __init__(
        self, names: tuple[str, ...], device: torch.device, seeds: int | None = None
    ) -> None:
        self.names = tuple(names)
        self.device = device
        self.shape: tuple[int, ...] = () if seeds is None else (int(seeds),)
        self.reset()

    def reset(self) -> None:
        kw = dict(device=self.device)
        self.first_step = torch.full(self.shape, -1, dtype=torch.int64, **kw)
        self.first_values = {n: torch.zeros(self.shape, dtype=torch.float64, **kw)
                             for n in self.names}  # fmt: skip

    def add(self, step: int, **values: Tensor) -> None:
        """Watch ``values`` (a subset of ``names``; 0-d, or (S,) with seeds) at ``step``."""
        v = {n: x.detach().reshape(self.shape).to(torch.float64) for n, x in values.items()}
        bad = ~torch.stack([torch.isfinite(x) for x in v.values()]).all(0)
        first = bad & (self.first_step < 0)
        self.first_step = torch.where(first, step, self.first_step)
        for name, x in v.items():
            self.first_values[name] = torch.where(first, x, self.first_values[name])

    def failures(self) -> dict[int, DivergenceError]:
        """Seed position (0 without seeds) → the error of its first non-finite update."""
        steps = self.first_step.reshape(-1).tolist()  # the one host sync
        if max(steps) < 0:
            return {}
        values = {n: t.reshape(-1).tolist() for n, t in self.first_values.items()}
        out = {}
        for pos, step in enumerate(steps):
            if step >= 0:
                name = next(n for n in self.names if not np.isfinite(values[n][pos]))
                out[pos] = DivergenceError(step, name, values[name][pos])
        return out

    def check(self) -> None:
        """Raise :class:`DivergenceError` for the first non-finite update seen."""
        failures = self.failures()
        if failures:
            raise failures[min(failures)]

    def keep(self, positions: list[int]) -> None:
        """Keep the seeds at ``positions`` (in this order): the others left the stack."""
        rows = torch.as_tensor(positions, dtype=torch.long).to(self.device)
        self.shape = (len(positions),)
        self.first_step = self.first_step.index_select(0, rows)
        self.first_values = {n: t.index_select(0, rows) for n, t in self.first_values.items()}


#: The update quantities Algorithm 4's loops watch (critic l. 7; actor and α l. 8-10).
WATCHED = ("critic_loss", "q_mean", "actor_loss", "entropy_bound", "alpha_loss")
