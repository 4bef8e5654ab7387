"""DIME's updates and action sampler replayed as CUDA graphs: the GPU fast path.

At the thesis's sizes an update of Algorithm 4 (l. 7-10) is hundreds of small kernels: the
denoising chain runs N = 16 score-network passes for a' ~ π(·|s'), the critics a joint
forward and backward, then the optimiser. On a GPU their launch cost, not their arithmetic,
sets the update rate. :class:`GraphedUpdates` records each of three steps once as a CUDA
graph and from then on replays it with one launch:

* the critic step (Eq. 5.21 / 5.24, CrossQ joint batch, Adam),
* the actor step with the temperature step after it (Eqs. 5.27 and 5.28, two Adams),
* the action sampler a ~ π(·|s) for the environment (no gradient).

It wraps a single-seed :class:`~vslbook.srl.dime_updates.Agent` or a
:class:`~vslbook.srl.seed_axis.SeedStack` (all seeds in one graph). What a graph may not
contain, it does not: no host synchronisation (the updates read no tensor on the host; the
warm-up of BatchRenorm is a tensor test), no random numbers (the policy noise is an input,
drawn outside the graph by :func:`policy_noise` from the same generator and in the same
chunks as the eager policy draws it, so a graphed run consumes the same random stream), and
Adam with ``capturable=True`` (its step counter and bias correction stay on the device).

Capture. Each graph is captured at its first call: the step runs ``warmup`` times on a side
stream (CUDA's lazy initialisation must happen outside a capture), then every tensor the
step changes (parameters, BatchRenorm statistics, log α, Adam's moments and step counters)
is put back as it was, and the step is captured. So the first replay takes the first real
step: a graphed run follows the eager run's numbers (up to the kernels' own rounding, which
the device tests check) and resumes from the same checkpoints.

Inputs are copied into the graph's static tensors on every call and the outputs cloned
out of its private memory, so a caller may keep them. Shapes are fixed at capture: a batch
of another size (or another number of seeds) is an error that names both shapes.
"""

from __future__ import annotations

import warnings
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import Any

import torch
from torch import Tensor

from vslbook.srl.dime_config import DIMEConfig
from vslbook.srl.dime_updates import (
    Agent,
    UpdateStats,
    actor_update,
    alpha_update,
    critic_update,
    policy_noise,
)
from vslbook.srl.replay import Batch
from vslbook.srl.seed_axis import SeedStack

__all__ = ["GraphedUpdates", "graphs_wanted", "policy_noise", "undone"]

def graphs_wanted(cfg: DIMEConfig, device: torch.device) -> bool:
    """Whether a run of ``cfg`` on ``device`` replays its updates as graphs.

    ``cuda_graphs="auto"``: on a CUDA device, unless the updates are compiled
    (``torch.compile`` makes graphs of its own) or use a target network; ``"on"``: always,
    an error off CUDA; ``"off"``: never.
    """
    cuda = torch.device(device).type == "cuda"
    if cfg.cuda_graphs == "on" and not cuda:
        raise ValueError(
            f"cuda_graphs='on' needs a CUDA device, got device {str(device)!r}; "
            "use cuda_graphs='auto' (graphs where CUDA is) or 'off'"
        )
    if cfg.cuda_graphs == "off" or not cuda:
        return False
    return cfg.cuda_graphs == "on" or not (cfg.compile or cfg.use_target_network)


class _Step:
    """One step (a function of tensors) captured as a CUDA graph at its first call."""

    def __init__(self, name: str, fn: Callable[..., Any], state: Callable[[], list[Tensor]],
                 optimisers: list[torch.optim.Optimizer], warmup: int) -> None:  # fmt: skip
        self.name, self.fn, self.state, self.optimisers = name, fn, state, optimisers
        self.warmup = warmup
        self.graph: torch.cuda.CUDAGraph | None = None
        self.inputs: list[Tensor] = []
        self.outputs: Any = None

    def __call__(self, *inputs: Tensor) -> Any:
        if self.graph is None:
            self._capture(inputs)
        else:
            if len(inputs) != len(self.inputs):
                raise ValueError(
                    f"{self.name}: expected {len(self.inputs)} inputs, got {len(inputs)}"
                )
            for k, (static, new) in enumerate(zip(self.inputs, inputs, strict=True)):
                if static.shape != new.shape:
                    raise ValueError(
                        f"{self.name}: input {k} has shape {tuple(new.shape)}, but the graph "
                        f"was captured for {tuple(static.shape)} (batch size and seeds are fixed "
                        "at capture)"
                    )
                static.copy_(new)
        self.graph.replay()
        return _clone(self.outputs)

    def _capture(self, inputs: tuple[Tensor, ...]) -> None:
        device = inputs[0].device
        if device.type != "cuda":
            raise ValueError(f"{self.name}: CUDA graphs need CUDA tensors, got device {device}")
        for opt in self.optimisers:
            for group in opt.param_groups:
                group["capturable"] = True  # step count and bias correction on the device
        self.inputs = [x.detach().clone() for x in inputs]
        side = torch.cuda.Stream(device)
        side.wait_stream(torch.cuda.current_stream(device))
        with undone(self.state, self.optimisers), warnings.catch_warnings():
            # Adam warns that capturable=True steps outside a capture are slower: these are
            warnings.filterwarnings("ignore", message=".*capturable=True.*")
            with torch.cuda.stream(side):
                for _ in range(self.warmup):  # lazy init (cuBLAS, Adam's state) off-capture
                    self.fn(*self.inputs)
            torch.cuda.current_stream(device).wait_stream(side)
        self.graph = torch.cuda.CUDAGraph()
        with torch.cuda.graph(self.graph):
            self.outputs = self.fn(*self.inputs)


@contextmanager
def undone(
    state: Callable[[], list[Tensor]], optimisers: list[torch.optim.Optimizer]
) -> Iterator[None]:
    """Run the body, then put back every tensor of ``state()`` and every optimiser as it was.

    ``state()`` lists the tensors the body may change (read before and after, so it may
    include Adam's state, which a first step creates). A parameter's Adam state that the
    body created is zeroed in place (a fresh Adam's moments and step count are zeros), so
    its tensors, which a graph captured afterwards refers to, stay where they are.
    """
    saved = [(t, t.detach().clone()) for t in state()]
    fresh = [[p for g in opt.param_groups for p in g["params"] if not opt.state.get(p)]
             for opt in optimisers]  # fmt: skip
    try:
        yield
    finally:
        with torch.no_grad():
            for t, value in saved:
                t.copy_(value)
            for opt, new in zip(optimisers, fresh, strict=True):
                for p in new:
                    for v in opt.state.get(p, {}).values():
                        if torch.is_tensor(v):
                            v.zero_()


def _clone(out: Any) -> Any:
    if torch.is_tensor(out):
        return out.clone()
    if isinstance(out, tuple):
        cloned = [_clone(x) for x in out]
        return type(out)(*cloned) if hasattr(out, "_fields") else tuple(cloned)
    return out


def _optimisers(learner: Agent | SeedStack) -> list[torch.optim.Optimizer]:
    opts = [learner.critic_opt, learner.actor_opt, learner.alpha_opt]
    return [o for o in opts if o is not None]


def _adam_state(opts: list[torch.optim.Optimizer]) -> list[Tensor]:
    return [v for o in opts for st in o.state.values() for v in st.values() if torch.is_tensor(v)]


class GraphedUpdates:
    """The critic step, the actor + α step and the sampler of ``learner`` as CUDA graphs.

    Args:
        learner: an :class:`~vslbook.srl.dime_updates.Agent` (one seed) or a
            :class:`~vslbook.srl.seed_axis.SeedStack` (S seeds, every input with the seed
            axis first), on a CUDA device, without a target network.
        warmup: eager steps on a side stream before each capture (undone afterwards).

    The calls take the policy noise explicitly (:func:`policy_noise`, or
    :meth:`SeedStack.noise`); their numbers are those of
    :func:`~vslbook.srl.dime_updates.critic_update` / ``actor_update`` / ``alpha_update`` (or
    the stack's) given the same noise.
    """

    def __init__(self, learner: Agent | SeedStack, *, warmup: int = 3) -> None:
        if warmup < 1:
            raise ValueError(f"warmup must be >= 1 (lazy CUDA initialisation), got {warmup}")
        self.learner = learner
        stacked = isinstance(learner, SeedStack)
        if not stacked and learner.critic_target is not None:
            raise ValueError(
                "CUDA graphs are for CrossQ critics without a target network "
                "(use_target_network=False); train the target-network ablation eagerly"
            )
        opts = _optimisers(learner)
        if stacked:
            tensors = [*learner.params.values(), *learner.buffers.values(), learner.log_alpha]
        else:
            tensors = [learner.log_alpha]
            for module in (learner.policy, learner.critic):
                tensors += [*module.parameters(), *module.buffers()]

        def state() -> list[Tensor]:
            return tensors + _adam_state(opts)

        def critic(*b: Tensor) -> UpdateStats:
            if stacked:
                return learner.critic_update(Batch(*b[:5]), b[5])
            return critic_update(learner, Batch(*b[:5]), noise=b[5])

        def actor(obs: Tensor, noise: Tensor) -> tuple[UpdateStats, Tensor]:
            if stacked:
                stats = learner.actor_update(obs, noise)
                return stats, learner.alpha_update(stats.running_cost)
            stats = actor_update(learner, obs, noise=noise)
            return stats, alpha_update(learner, stats.running_cost)

        @torch.no_grad()
        def sample(obs: Tensor, noise: Tensor) -> Tensor:
            if stacked:
                return learner.act(obs, noise)
            return learner.policy.sample(obs, noise=noise).action

        self._critic = _Step("critic update", critic, state, opts, warmup)
        self._actor = _Step("actor update", actor, state, opts, warmup)
        self._sample = _Step("action sampler", sample, state, [], warmup)

    def critic_update(self, batch: Batch, noise: Tensor) -> UpdateStats:
        """One critic step (Algorithm 4, l. 7) by graph replay."""
        return self._critic(*batch, noise)

    def actor_alpha_update(self, obs: Tensor, noise: Tensor) -> tuple[UpdateStats, Tensor]:
        """One actor step (l. 9, Eq. 5.27), then one α step (l. 10, Eq. 5.28), by one replay;
        returns the actor's statistics and the temperature loss."""
        return self._actor(obs, noise)

    def act(self, obs: Tensor, noise: Tensor) -> Tensor:
        """Actions a ~ π(·|s): ``obs`` (B, obs_dim) for an agent, (S, obs_dim) for a stack
        (one state per seed, noise of batch 1 per seed)."""
        return self._sample(obs, noise)
