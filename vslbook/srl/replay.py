"""A preallocated ring replay buffer D of transitions (s, a, r, s', terminated) (Algorithm 4, l. 5).

Storage is one torch tensor per field, allocated once with ``capacity`` rows on the training
device, so sampling a batch is a single gather there. When the buffer is full the oldest
transition is overwritten. ``terminated`` is stored, not ``truncated``: a transition cut by
a time limit still bootstraps from s' (Section 2.1's infinite-horizon objective), only a true
terminal state stops the bootstrap.

``state_dict`` holds only the filled rows (plus the write position), so a checkpoint taken
early in training is small, and ``load_state_dict`` restores the buffer bit for bit.

Indices come from a numpy Generator (copied to the device per batch: the CPU default, so CPU
runs keep their random stream) or from a ``torch.Generator`` on the buffer's device
(:func:`replay_generator`), where drawing a batch needs nothing from the host: on a GPU a
copy from pageable host memory would wait for every queued kernel first.
"""

from __future__ import annotations

from typing import Any, NamedTuple

import numpy as np
import torch
from torch import Tensor


class Batch(NamedTuple):
    """A batch of transitions: obs (B, obs_dim), action (B, act_dim), reward (B,),
    next_obs (B, obs_dim), terminated (B,) as 0./1. floats."""

    obs: Tensor
    action: Tensor
    reward: Tensor
    next_obs: Tensor
    terminated: Tensor


class ReplayBuffer:
    """Ring buffer of ``capacity`` transitions stored as float32 tensors on ``device``.

    Args:
        capacity: maximum number of transitions kept (Table C.2: 1e6).
        obs_dim, act_dim: sizes of the flat observation and action vectors.
        device: where the storage lives (and where sampled batches are returned).
    """

    FIELDS = ("obs", "action", "reward", "next_obs", "terminated")

    def __init__(
        self, capacity: int, obs_dim: int, act_dim: int, device: str | torch.device = "cpu"
    ) -> None:
        for name, value in (("capacity", capacity), ("obs_dim", obs_dim), ("act_dim", act_dim)):
            if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 1:
                raise ValueError(f"{name} must be an integer >= 1, got {value!r}")
        self.capacity, self.obs_dim, self.act_dim = int(capacity), int(obs_dim), int(act_dim)
        self.device = torch.device(device)
        kw = dict(dtype=torch.float32, device=self.device)
        self.obs = torch.empty(self.capacity, self.obs_dim, **kw)
        self.action = torch.empty(self.capacity, self.act_dim, **kw)
        self.reward = torch.empty(self.capacity, **kw)
        self.next_obs = torch.empty(self.capacity, self.obs_dim, **kw)
        self.terminated = torch.empty(self.capacity, **kw)
        self.ptr = 0  # next row to write
        self.size = 0  # number of filled rows

    def __len__(self) -> int:
        return self.size

    def add(
        self,
        obs: np.ndarray | Tensor,
        action: np.ndarray | Tensor,
        reward: float,
        next_obs: np.ndarray | Tensor,
        terminated: bool,
    ) -> None:
        """Store one transition, overwriting the oldest one when full."""
        row = self.ptr
        for name, value, dim in (
            ("obs", obs, self.obs_dim),
            ("action", action, self.act_dim),
            ("next_obs", next_obs, self.obs_dim),
        ):
            value = torch.as_tensor(value, dtype=torch.float32)
            if value.shape != (dim,):
                raise ValueError(f"{name} must have shape ({dim},), got {tuple(value.shape)}")
            getattr(self, name)[row] = value
        self.reward[row] = float(reward)
        self.terminated[row] = float(bool(terminated))
        self.ptr = (row + 1) % self.capacity
        self.size = min(self.size + 1, self.capacity)

    def sample(self, batch_size: int, generator: np.random.Generator | torch.Generator) -> Batch:
        """``batch_size`` transitions, uniform with replacement; indices from ``generator``
        (numpy's, on the host, or a ``torch.Generator`` on this buffer's device)."""
        if batch_size < 1:
            raise ValueError(f"batch_size must be >= 1, got {batch_size}")
        if self.size == 0:
            raise ValueError("cannot sample from an empty replay buffer")
        if isinstance(generator, torch.Generator):
            if generator.device.type != self.device.type:
                raise ValueError(
                    f"the index generator is on {generator.device}, the buffer on {self.device}"
                )
            idx = torch.randint(
                0, self.size, (batch_size,), generator=generator, device=self.device
            )
        else:
            idx = torch.from_numpy(generator.integers(0, self.size, size=batch_size))
            idx = idx.to(self.device)
        return Batch(*(getattr(self, name).index_select(0, idx) for name in self.FIELDS))

    def state_dict(self) -> dict[str, Any]:
        """The filled rows (CPU copies) and the write position."""
        state: dict[str, Any] = {
            name: getattr(self, name)[: self.size].cpu() for name in self.FIELDS
        }
        state.update(capacity=self.capacity, ptr=self.ptr, size=self.size)
        return state

    def load_state_dict(self, state: dict[str, Any]) -> None:
        """Restore a buffer saved by :meth:`state_dict` (same capacity and dimensions)."""
        if int(state["capacity"]) != self.capacity:
            raise ValueError(
                f"replay state has capacity {state['capacity']}, this buffer {self.capacity}"
            )
        size = int(state["size"])
        for name in self.FIELDS:
            stored, target = state[name], getattr(self, name)
            if tuple(stored.shape) != (size, *target.shape[1:]):
                raise ValueError(
                    f"replay state field {name!r} has shape {tuple(stored.shape)}, "
                    f"expected {(size, *target.shape[1:])}"
                )
            target[:size] = stored.to(self.device)
        self.size, self.ptr = size, int(state["ptr"])


#: How replay indices are drawn (``DIMEConfig.replay_sampler``): ``"numpy"`` on the host,
#: ``"device"`` by a ``torch.Generator`` on the training device, ``"auto"`` numpy on a CPU and
#: the device elsewhere.
REPLAY_SAMPLERS = ("auto", "numpy", "device")


def replay_generator(sampler: str, device: torch.device, seed: int) -> torch.Generator | None:
    """The device stream for the replay indices, seeded by ``seed``; None where the indices
    come from the run's numpy Generator (``sampler`` ``"numpy"``, or ``"auto"`` on a CPU)."""
    if sampler not in REPLAY_SAMPLERS:
        raise ValueError(f"unknown replay_sampler {sampler!r}; expected one of {REPLAY_SAMPLERS}")
    device = torch.device(device)
    if sampler == "numpy" or (sampler == "auto" and device.type == "cpu"):
        return None
    return torch.Generator(device=device).manual_seed(int(seed))
