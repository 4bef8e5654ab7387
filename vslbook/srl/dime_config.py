"""DIME's hyper-parameters (Tables C.2 / C.3), the CrossQ and Gaussian variants, and the
named configurations that a figure may use instead of the thesis's sizes.

A *budget* (:mod:`vslbook.budget`) scales counts only. A smaller network for a CPU is not a
budget's business: it is a *named configuration* (:data:`NAMED_CONFIGS`) that a notebook or a
user picks by name, and :func:`config_differences` / :func:`describe_differences` say, from the
config itself, how a run differs from the thesis's table.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import torch

from vslbook.srl.replay import REPLAY_SAMPLERS

POLICIES = ("diffusion", "gaussian")
CRITICS = ("distributional", "scalar")
Q_REDUCTIONS = ("mean", "min")
CUDA_GRAPH_MODES = ("auto", "on", "off")


@dataclass(frozen=True)
class DIMEConfig:
    """DIME's hyper-parameters; defaults are Table C.2 / C.3 (DIME column) and Appendix C.4.

    Counts marked *scaled* are full-budget values that a :class:`~vslbook.budget.Budget`
    shrinks (``budget.scale``, never below ``min(value, 1000)``); everything else is the
    algorithm and is never changed by a budget.

    Attributes:
        total_steps: environment steps (*scaled*; 1M in the thesis, 3M for two DMC tasks).
        learning_starts: uniform-random exploration steps before updates begin (Table C.2
            "Exploration Steps" 5000). An algorithm setting, *not* scaled by a budget: a
            shorter exploration phase would make a curve start learning earlier than the
            published one it is compared with.
        eval_every: environment steps between evaluations (*scaled*; the published learning
            curves are evaluated every 24k steps).
        eval_episodes: episodes per evaluation with the stochastic policy; 0 takes the
            budget's ``eval_episodes``.
        checkpoint_every: environment steps between checkpoints (*scaled*), each written at
            the first episode end at or after the multiple.
        batch_size, utd, policy_delay, gamma, buffer_size: Table C.2 / C.3 (256, 2, 3,
            0.99, 1e6); ``utd`` critic updates per environment step, one actor and α update
            every ``policy_delay`` critic updates.
        actor_lr, critic_lr, alpha_lr: Adam learning rates (Table C.2: 3e-4, 3e-4, 1e-3).
        adam_beta1: β1 of the actor and critic Adam (0.5, CrossQ's value that DIME adopts);
            the temperature uses Adam's default betas.
        actor_grad_clip: actor gradients are cleared of NaNs and clipped elementwise to
            ±this value (0 disables the clipping).
        init_log_alpha: initial log α (0, i.e. α = 1).
        h_target_per_dim: H_target / |A| of Eq. 5.28, a target for the mean running cost
            (Table C.2: 4·dim(A)); see the module docstring for its entropy meaning.
        fixed_alpha: a constant α instead of the autotuning (the α sweep of Fig. 5.4a-b).
        policy: ``"diffusion"`` (DIME) or ``"gaussian"`` (tanh-Gaussian, Fig. 5.4c-d).
        actor_hidden, actor_layers: score network / Gaussian trunk size (256, 3).
        n_diffusion_steps: N, the denoising steps (Table C.2: 16).
        sigma0: standard deviation of the prior N(0, σ0² I) (Table C.2: 2.5).
        diffusion_dt: initial scale softplus(θ_T) of the step sizes dt_n = softplus(θ_T) s(n)
            (0.1; the cosine schedule s is not normalised, so Σ_n dt_n ≈ 0.84 at N = 16).
        learn_beta: learn the per-dimension diffusion coefficient β (Appendix C.4, Fig. C.2).
        general_bridges: also learn the noising drift (Section 5.6, Fig. 5.8a-b).
        critic: ``"distributional"`` (C51, DIME) or ``"scalar"`` (Bellman residual, Eq. 5.24,
            the ablation of Fig. 5.5c-d / 5.6).
        critic_hidden, critic_layers: critic width and depth (Table C.2: 2048, 2).
        n_atoms: atoms of the categorical return distribution (101 on [v_min, v_max]).
        v_min, v_max: support of the return distribution; None picks the suite's range
            (Table C.3 text: ±200 DMC, ±1600 gymnasium, ±3600 MyoSuite) through
            ``vslbook.envs.step_based.value_range``, else ±1600 with a warning.
        critic_entropy_coef: c in the critic loss CE - c H(p) (Appendix C.4: 0.005).
        q_reduce: how the two critics combine in the target and the actor loss: ``"mean"``
            (DIME, Appendix C.4) or ``"min"`` (clipped double Q; scalar critic only).
        critic_batchrenorm: BatchRenorm layers in the critic (CrossQ).
        renorm_warmup: critic training passes with plain batch norm before renormalising.
        use_target_network: Polyak-averaged target critics for s' (the point-mass study of
            Fig. 5.7) instead of CrossQ's joint batch; ``tau`` is the averaging rate.
        device: ``"auto"`` (cuda if available, else cpu) or a torch device string.
        replay_sampler: where the replay indices are drawn: ``"numpy"`` (the run's numpy
            Generator, copied to the device per batch), ``"device"`` (a torch Generator on
            the device, no host-to-device copy in the update loop) or ``"auto"`` (numpy on
            a CPU, the device elsewhere). The two are different random streams.
        compile: wrap the update functions in ``torch.compile``.
        cuda_graphs: replay the critic step, the actor + α step and the action sampler as
            CUDA graphs (:mod:`vslbook.srl.cuda_graphs`): ``"auto"`` (on a CUDA device,
            unless ``compile`` or ``use_target_network``), ``"on"`` (an error elsewhere) or
            ``"off"``. The numbers are the eager updates' (same random stream).
        num_threads: torch CPU threads (0 leaves torch's default).
    """

    total_steps: int = 1_000_000
    learning_starts: int = 5000
    eval_every: int = 24_000
    eval_episodes: int = 0
    checkpoint_every: int = 100_000
    batch_size: int = 256
    utd: int = 2
    policy_delay: int = 3
    gamma: float = 0.99
    buffer_size: int = 1_000_000
    actor_lr: float = 3e-4
    critic_lr: float = 3e-4
    alpha_lr: float = 1e-3
    adam_beta1: float = 0.5
    actor_grad_clip: float = 1.0
    init_log_alpha: float = 0.0
    h_target_per_dim: float = 4.0
    fixed_alpha: float | None = None
    policy: str = "diffusion"
    actor_hidden: int = 256
    actor_layers: int = 3
    n_diffusion_steps: int = 16
    sigma0: float = 2.5
    diffusion_dt: float = 0.1
    learn_beta: bool = True
    general_bridges: bool = False
    critic: str = "distributional"
    critic_hidden: int = 2048
    critic_layers: int = 2
    n_atoms: int = 101
    v_min: float | None = None
    v_max: float | None = None
    critic_entropy_coef: float = 0.005
    q_reduce: str = "mean"
    critic_batchrenorm: bool = True
    renorm_warmup: int = 100_000
    use_target_network: bool = False
    tau: float = 0.005
    device: str = "auto"
    replay_sampler: str = "auto"
    compile: bool = False
    cuda_graphs: str = "auto"
    num_threads: int = 0

    def __post_init__(self) -> None:
        for name in (
            "total_steps", "eval_every", "checkpoint_every", "batch_size", "utd",
            "policy_delay", "buffer_size", "actor_hidden", "actor_layers",
            "n_diffusion_steps", "critic_hidden", "critic_layers",
        ):  # fmt: skip
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                raise ValueError(f"{name} must be an integer >= 1, got {value!r}")
        for name in ("learning_starts", "eval_episodes", "renorm_warmup", "num_threads"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < 0:
                raise ValueError(f"{name} must be an integer >= 0, got {value!r}")
        for name in ("actor_lr", "critic_lr", "alpha_lr", "sigma0", "diffusion_dt"):
            if not getattr(self, name) > 0:
                raise ValueError(f"{name} must be > 0, got {getattr(self, name)!r}")
        if not 0.0 <= self.gamma <= 1.0:
            raise ValueError(f"gamma must be in [0, 1], got {self.gamma!r}")
        if not 0.0 <= self.adam_beta1 < 1.0:
            raise ValueError(f"adam_beta1 must be in [0, 1), got {self.adam_beta1!r}")
        if self.actor_grad_clip < 0:
            raise ValueError(f"actor_grad_clip must be >= 0 (0: off), got {self.actor_grad_clip!r}")
        if self.fixed_alpha is not None and not self.fixed_alpha > 0:
            raise ValueError(f"fixed_alpha must be > 0 or None, got {self.fixed_alpha!r}")
        if not 0.0 < self.tau <= 1.0:
            raise ValueError(f"tau must be in (0, 1], got {self.tau!r}")
        if isinstance(self.n_atoms, bool) or not isinstance(self.n_atoms, int) or self.n_atoms < 2:
            raise ValueError(f"n_atoms must be an integer >= 2, got {self.n_atoms!r}")
        for name, value, allowed in (
            ("policy", self.policy, POLICIES),
            ("critic", self.critic, CRITICS),
            ("q_reduce", self.q_reduce, Q_REDUCTIONS),
            ("replay_sampler", self.replay_sampler, REPLAY_SAMPLERS),
            ("cuda_graphs", self.cuda_graphs, CUDA_GRAPH_MODES),
        ):
            if value not in allowed:
                raise ValueError(f"unknown {name} {value!r}; expected one of {', '.join(allowed)}")
        if self.cuda_graphs == "on" and self.compile:
            raise ValueError(
                "cuda_graphs='on' and compile=True are two ways to the same end; choose one "
                "(cuda_graphs='auto' leaves the graphs to torch.compile)"
            )
        if self.cuda_graphs == "on" and self.use_target_network:
            raise ValueError(
                "cuda_graphs='on' needs use_target_network=False (the graphs hold CrossQ's "
                "updates); use cuda_graphs='auto' or 'off' for the target-network ablation"
            )
        if (self.v_min is None) != (self.v_max is None):
            raise ValueError(
                f"set both v_min and v_max or neither, got v_min={self.v_min!r}, "
                f"v_max={self.v_max!r}"
            )
        if self.v_min is not None and not self.v_min < self.v_max:
            raise ValueError(f"need v_min < v_max, got v_min={self.v_min!r}, v_max={self.v_max!r}")
        if self.critic == "distributional" and self.q_reduce == "min":
            raise ValueError(
                "q_reduce='min' is defined for the scalar critic only; the distributional "
                "critic averages the two projected distributions (expected q_reduce='mean')"
            )
        if self.general_bridges and self.policy != "diffusion":
            raise ValueError(
                f"general_bridges=True needs policy='diffusion', got policy={self.policy!r}"
            )
        if self.device != "auto":
            try:
                device = torch.device(self.device)
            except (RuntimeError, TypeError) as err:
                raise ValueError(
                    f"unknown device {self.device!r}; expected 'auto', 'cpu', 'cuda', ..."
                ) from err
            if device.type == "cuda":
                _check_cuda(self.device, device.index)


def _check_cuda(name: str, index: int | None) -> None:
    """A clear error for a CUDA device this machine does not have."""
    if not torch.cuda.is_available():
        raise ValueError(
            f"device {name!r} requested but CUDA is not available on this machine "
            "(torch.cuda.is_available() is False); use device='auto' or 'cpu'"
        )
    count = torch.cuda.device_count()
    if index is not None and index >= count:
        raise ValueError(
            f"device {name!r} requested but this machine has {count} CUDA device(s) "
            f"(cuda:0 to cuda:{count - 1}); use device='auto', 'cuda' or 'cpu'"
        )


@dataclass(frozen=True)
class DIMEGaussianConfig(DIMEConfig):
    """DIME with a tanh-Gaussian policy: identical critic and updates (Fig. 5.4c-d).

    Only the policy and its entropy target change; ``h_target_per_dim = 1`` puts the target on
    log π(a|s) at |A|, i.e. SAC's entropy target -|A|.
    """

    policy: str = "gaussian"
    h_target_per_dim: float = 1.0


@dataclass(frozen=True)
class CrossQConfig(DIMEConfig):
    """CrossQ (Bhatt et al., 2024) as the thesis runs it (Table C.3, CrossQ column).

    Tanh-Gaussian actor (3 x 256), scalar critics trained on the Bellman residual (Eq. 5.24)
    with BatchRenorm and no target network, clipped double Q (min), learning rate 7e-4,
    temperature learning rate 3e-4, H_target = dim(A) on log π (entropy -|A|), no actor
    gradient clipping.
    """

    policy: str = "gaussian"
    critic: str = "scalar"
    q_reduce: str = "min"
    actor_lr: float = 7e-4
    critic_lr: float = 7e-4
    alpha_lr: float = 3e-4
    h_target_per_dim: float = 1.0
    actor_grad_clip: float = 0.0


# --------------------------------------------------------------------------- named configurations

#: Named configurations: overrides of a config's defaults (the thesis's values) that a figure
#: may choose *visibly*, by name. ``"thesis"`` is Table C.2 itself. The CPU ones keep every
#: algorithm setting and shrink only the network widths and the number of diffusion steps
#: (Fig. 5.2c-d shows 4 steps performing like 8 and 16 on the thesis's tasks).
NAMED_CONFIGS: dict[str, dict[str, Any]] = {
    "thesis": {},
    "cpu-256": {"critic_hidden": 256, "actor_hidden": 256, "n_diffusion_steps": 4},
    "cpu-64": {"critic_hidden": 64, "actor_hidden": 64, "n_diffusion_steps": 4},
}

#: Fields that set how long or where a run goes, not what the algorithm is: a budget scales
#: the counts, and the runtime fields do not change the numbers' meaning.
COUNT_FIELDS = ("total_steps", "eval_every", "eval_episodes", "checkpoint_every")
RUNTIME_FIELDS = ("device", "compile", "cuda_graphs", "num_threads")

#: Where each config class's defaults come from, for the captions.
THESIS_TABLES = {
    "DIMEConfig": "Table C.2",
    "DIMEGaussianConfig": "Table C.2 (Gaussian policy)",
    "CrossQConfig": "Table C.3, CrossQ column",
}


def named_config(name: str) -> dict[str, Any]:
    """The overrides of the named configuration ``name`` (a copy).

    Raises:
        ValueError: for an unknown name; the message lists the known ones.
    """
    if name not in NAMED_CONFIGS:
        raise ValueError(
            f"unknown named configuration {name!r}; expected one of {', '.join(NAMED_CONFIGS)}"
        )
    return dict(NAMED_CONFIGS[name])


def config_differences(
    config: Any, config_cls: type | None = None, *, include_counts: bool = False
) -> dict[str, tuple[Any, Any]]:
    """``{field: (ours, thesis)}`` for every field where ``config`` differs from the defaults.

    ``config`` is a config instance, or a mapping of overrides / a run's config record
    (unknown keys such as ``algo`` and ``env`` are ignored) together with ``config_cls``.
    The defaults of ``config_cls`` are the thesis's values (see :data:`THESIS_TABLES`).
    Counts (:data:`COUNT_FIELDS`) are left out unless ``include_counts``; runtime fields
    (:data:`RUNTIME_FIELDS`) always are.
    """
    if isinstance(config, Mapping):
        if config_cls is None:
            raise ValueError("config_differences: pass config_cls with a mapping of overrides")
        names = {f.name for f in dataclasses.fields(config_cls)}
        config = config_cls(**{k: v for k, v in config.items() if k in names})
    elif not dataclasses.is_dataclass(config) or isinstance(config, type):
        raise TypeError(
            f"config must be a config instance or a mapping, got {type(config).__name__}"
        )
    config_cls = type(config)
    reference = config_cls()
    skip = set(RUNTIME_FIELDS) | (set() if include_counts else set(COUNT_FIELDS))
    out = {}
    for field in dataclasses.fields(config_cls):
        ours, thesis = getattr(config, field.name), getattr(reference, field.name)
        if field.name not in skip and ours != thesis:
            out[field.name] = (ours, thesis)
    return out


def describe_differences(config: Any, config_cls: type | None = None) -> str:
    """One line for a caption: how ``config`` differs from the thesis's table.

    For example ``"vs Table C.2: critic_hidden 256 (thesis 2048), n_diffusion_steps 4
    (thesis 16)"``, or ``"as Table C.2"`` when nothing but counts differs. Generated from the
    config, never written by hand.
    """
    diffs = config_differences(config, config_cls)
    cls = config_cls if isinstance(config, Mapping) else type(config)
    table = THESIS_TABLES.get(cls.__name__, f"{cls.__name__} defaults")
    if not diffs:
        return f"as {table}"
    parts = [f"{name} {_fmt(ours)} (thesis {_fmt(thesis)})"
             for name, (ours, thesis) in diffs.items()]
    return f"vs {table}: " + ", ".join(parts)


def _fmt(value: Any) -> str:
    if value is None:
        return "none"
    if isinstance(value, float):
        return f"{value:g}"
    return str(value)
