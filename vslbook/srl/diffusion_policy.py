"""DIME's diffusion policy: a learned denoising chain with a tractable entropy bound.

For a state s the sampler runs N Euler-Maruyama steps of the denoising process (Eq. 5.12),
written with the prior p_N = N(0, σ0² I) and its score ∇log p_N(x) = -x / σ0²:

    x_N ~ N(0, σ0² I)
    x_{n-1} = x_n + η_n (∇log p_N(x_n) + f_θ(x_n, n, s)) + sqrt(2 η_n) ε_n,   n = N, ..., 1
    a = tanh(x_0)

with per-dimension step sizes η_n = dt_n σ², dt_n = softplus(θ_T) · s(n), a learned scale
softplus(θ_T) (0.1 at init) times the cosine schedule s(n) of :func:`cosine_schedule`, which
is *not* normalised (at N = 16 the steps run from ≈ 0.1 down to ≈ 0.001 and sum to ≈ 0.84),
and learned per-dimension scales σ_d² = 1 / softplus(φ_d) (Fig. C.2). The kernels, with their
exact conditional means, are

    generative  π_{n-1|n}(x_{n-1} | x_n)  = N(x_{n-1}; x_n + η_n (∇log p_N(x_n) + f_θ), 2 η_n I)
    noising     →π_{n|n-1}(x_n | x_{n-1}) = N(x_n; x_{n-1} + η_n ∇log p_N(x_{n-1}), 2 η_n I)

The noising kernel is Eq. 5.11 with β_n δ = η_n / σ0² (the thesis's η is σ0): an OU /
Langevin step whose stationary law is the prior. Matching the generative kernel to Eq. 5.12
shows f_θ stands for 2 (∇log π_n - ∇log p_N), so f_θ ≡ 0 (its initial value) keeps the
prior. One chain gives a single-sample estimate of the entropy lower bound ℓ of Eq. 5.15,

    ℓ(a, s) = E[ Σ_n log →π_{n|n-1} - log p_N(x_N) - Σ_n log π_{n-1|n} + Σ_d log(1 - tanh² x_0d) ],

split into two costs whose sum the actor loss multiplies by α (Eq. 5.27):

    running_cost  = Σ_n [log π_{n-1|n} - log →π_{n|n-1}] - Σ_d log(1 - tanh² x_0d)   (Eq. C.30)
    terminal_cost = log p_N(x_N)     (Eq. 5.27's log π_N(a^N): the prior at the chain's start)
    entropy_bound = -(running_cost + terminal_cost),   E[entropy_bound] = ℓ <= H(π(·|s)).

So E[running_cost + terminal_cost] >= E[log π(a|s)]: the cost is an *upper* bound on the
log-likelihood in expectation, the entropy bound a lower bound on the entropy. The actor
minimises mean(-Q(s, a) + α (running_cost + terminal_cost)); the terminal cost does not
depend on any parameter (x_N comes from the fixed prior) but sets the entropy level seen by
the critic target and by the temperature update.

``general_bridges=True`` (Section 5.6) also learns the noising drift:

    noising     →π_{n|n-1}(x_n | x_{n-1}) = N(x_n; x_{n-1} + η_n (∇log p_N + g_ψ)(x_{n-1}), 2 η_n I)

with g_ψ(x_{n-1}, n-1, s) a second score network whose output layer starts at zero, so training
starts from exactly the denoising policy above. This is Eq. 5.35-5.36 with f ≡ 0, β δ = η_n,
u = ∇log p_N + g_ψ and v = ∇log p_N + f_θ; the thesis leaves f and the parameterisation of u, v
open, and its prior N(0, I) (Eq. 5.30) is kept at N(0, σ0² I) here.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

import torch
import torch.nn.functional as F
from torch import Tensor, nn


class PolicySample(NamedTuple):
    """What a policy's ``sample`` returns (shared by the diffusion and Gaussian policies).

    ``action`` (B, d) in (-1, 1); ``running_cost`` and ``terminal_cost`` (B,), whose sum is a
    single-sample estimate of -ℓ, i.e. of an upper bound on log π(a|s) (exact log π(a|s) for
    the Gaussian policy); ``latent`` (B, d) the pre-tanh action x_0; ``trajectory``
    (N + 1, B, d) the chain x_N, ..., x_0 when requested.
    """

    action: Tensor
    running_cost: Tensor
    terminal_cost: Tensor
    latent: Tensor
    trajectory: Tensor | None = None

    @property
    def cost(self) -> Tensor:
        """running_cost + terminal_cost, the term the actor loss multiplies by α."""
        return self.running_cost + self.terminal_cost

    @property
    def entropy_bound(self) -> Tensor:
        """-(running_cost + terminal_cost): single-sample estimate of ℓ (Eq. 5.15) <= H."""
        return -(self.running_cost + self.terminal_cost)


def tanh_log_det_jacobian(x: Tensor) -> Tensor:
    """Σ_d log(1 - tanh²(x_d)) over the last dimension, stable for large |x|.

    Uses 1 - tanh²(x) = 4 e^{-2x} / (1 + e^{-2x})², i.e. 2 (log 2 - x - softplus(-2x)).
    """
    return (2.0 * (math.log(2.0) - x - F.softplus(-2.0 * x))).sum(dim=-1)


def _gaussian_log_prob(x: Tensor, mean: Tensor, var: Tensor) -> Tensor:
    """log N(x; mean, diag(var)) summed over the last dimension."""
    return -0.5 * ((x - mean) ** 2 / var + torch.log(2.0 * math.pi * var)).sum(dim=-1)


def _softplus_inverse(y: float) -> float:
    return y + math.log(-math.expm1(-y))


def cosine_schedule(n_steps: int, offset: float = 0.008, floor: float = 0.001) -> Tensor:
    """The relative step sizes s(n), n = 0..N-1, in sampling order (n = 0 starts from x_N).

        s(n) = (1 - floor) · cos²(½π (1 + offset - t_n) / (1 + offset)) + floor,  t_n = (N - n)/N

    The schedule is *not* normalised: s(0) ≈ 1 and s(N-1) is small (≈ 0.0105 at N = 16), so with
    the initial scale softplus(θ_T) = 0.1 the first step is ≈ 0.1, the last ≈ 0.001 and the
    total ≈ 0.84 at N = 16 (≈ 0.10, 0.015 and 0.25 at N = 4). This is the cosine schedule of
    the authors' released code (offset 0.008, minimum 0.001, one learned scale for all steps);
    the thesis names it (Appendix C.4, Fig. C.2) without printing it.
    """
    if isinstance(n_steps, bool) or not isinstance(n_steps, int) or n_steps < 1:
        raise ValueError(f"n_steps must be an integer >= 1, got {n_steps!r}")
    t = (n_steps - torch.arange(n_steps, dtype=torch.float64)) / n_steps
    phase = 0.5 * math.pi * (1.0 + offset - t) / (1.0 + offset)
    return ((1.0 - floor) * torch.cos(phase) ** 2 + floor).float()


@dataclass(frozen=True)
class DiffusionPolicyConfig:
    """Sampler and score-network settings; defaults follow Table C.2 / Appendix C.4.

    ``sigma0`` is the prior's standard deviation; ``dt`` the initial value of the step-size
    scale softplus(θ_T) in dt_n = softplus(θ_T) · s(n) (:func:`cosine_schedule`; 0.1, so the
    first step is ≈ 0.1); ``sigma_init`` the initial per-dimension noise scale σ_d;
    ``learn_beta`` learns σ_d (Fig. C.2) and ``learn_dt`` learns the scale. ``squash`` puts a
    tanh on x_0 (switch it off for unbounded actions or closed-form checks).
    """

    n_steps: int = 16
    sigma0: float = 2.5
    dt: float = 0.1
    sigma_init: float = 1.0
    learn_beta: bool = True
    learn_dt: bool = True
    n_frequencies: int = 256
    freq_min: float = 0.1
    freq_max: float = 100.0
    hidden: int = 256
    n_layers: int = 3
    out_init_scale: float = 1e-8
    out_clip: float = 1e4
    squash: bool = True
    general_bridges: bool = False

    def __post_init__(self) -> None:
        for name in ("n_steps", "n_frequencies", "hidden", "n_layers"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int):
                raise ValueError(f"{name} must be an integer, got {value!r}")
            if value < 1:
                raise ValueError(f"{name} must be >= 1, got {value}")
        for name in ("sigma0", "dt", "sigma_init", "out_clip"):
            if not getattr(self, name) > 0:
                raise ValueError(f"{name} must be > 0, got {getattr(self, name)}")
        if self.out_init_scale < 0:
            raise ValueError(f"out_init_scale must be >= 0, got {self.out_init_scale}")
        if not 0 < self.freq_min <= self.freq_max:
            raise ValueError(
                f"need 0 < freq_min <= freq_max, got {self.freq_min}, {self.freq_max}"
            )


class ScoreNetwork(nn.Module):
    """f_θ(x, n, s): the learned part of the denoising drift (Appendix C.4).

    Step index n is embedded as [sin, cos](k n + φ), k = linspace(freq_min, freq_max, K) with
    a learned phase φ (zero at init), then Linear-GELU-Linear to ``hidden``; the trunk is
    ``n_layers`` x [Linear, GELU] on concat(x, s, embedding); the output layer starts near
    zero (weights scaled by ``out_init_scale``) and the output is clipped to ±``out_clip``.
    """

    def __init__(self, obs_dim: int, act_dim: int, config: DiffusionPolicyConfig) -> None:
        super().__init__()
        c = config
        self.out_clip = c.out_clip
        self.register_buffer("frequencies", torch.linspace(c.freq_min, c.freq_max, c.n_frequencies))
        self.phase = nn.Parameter(torch.zeros(c.n_frequencies))
        self.time_mlp = nn.Sequential(
            nn.Linear(2 * c.n_frequencies, c.hidden), nn.GELU(), nn.Linear(c.hidden, c.hidden)
        )
        layers: list[nn.Module] = []
        width = act_dim + obs_dim + c.hidden
        for _ in range(c.n_layers):
            layers += [nn.Linear(width, c.hidden), nn.GELU()]
            width = c.hidden
        self.trunk = nn.Sequential(*layers)
        self.out = nn.Linear(width, act_dim)
        with torch.no_grad():
            self.out.weight.mul_(c.out_init_scale)
            self.out.bias.zero_()

    def embed_steps(self, steps: Tensor) -> Tensor:
        """Embeddings (len(steps), hidden) of the raw step indices ``steps``."""
        angle = steps[:, None] * self.frequencies + self.phase
        return self.time_mlp(torch.cat([torch.sin(angle), torch.cos(angle)], dim=-1))

    def forward(self, x: Tensor, step_embedding: Tensor, obs: Tensor) -> Tensor:
        """f_θ for a batch: x (B, d), step_embedding (hidden,) or (B, hidden), obs (B, obs_dim)."""
        emb = step_embedding.expand(x.shape[0], -1)
        out = self.out(self.trunk(torch.cat([x, obs, emb], dim=-1)))
        return out.clamp(-self.out_clip, self.out_clip)


class DiffusionPolicy(nn.Module):
    """The DIME policy π_θ(a|s); see the module docstring for the chain and the costs."""

    def __init__(
        self, obs_dim: int, act_dim: int, config: DiffusionPolicyConfig | None = None
    ) -> None:
        super().__init__()
        if obs_dim < 1 or act_dim < 1:
            raise ValueError(f"obs_dim and act_dim must be >= 1, got {obs_dim}, {act_dim}")
        self.config = c = config or DiffusionPolicyConfig()
        self.obs_dim, self.act_dim = obs_dim, act_dim
        self.score_net = ScoreNetwork(obs_dim, act_dim, c)
        self.noising_net = ScoreNetwork(obs_dim, act_dim, c) if c.general_bridges else None
        if self.noising_net is not None:
            nn.init.zeros_(self.noising_net.out.weight)
        self.register_buffer("schedule", cosine_schedule(c.n_steps))
        raw_dt = torch.tensor(_softplus_inverse(c.dt))
        raw_noise = torch.full((act_dim,), _softplus_inverse(1.0 / c.sigma_init**2))
        self.raw_dt = nn.Parameter(raw_dt, requires_grad=c.learn_dt)
        self.raw_noise = nn.Parameter(raw_noise, requires_grad=c.learn_beta)

    @property
    def dt_scale(self) -> Tensor:
        """softplus(θ_T), the learned scale of the step sizes dt_n = softplus(θ_T) · s(n)."""
        return F.softplus(self.raw_dt)

    @property
    def noise_var(self) -> Tensor:
        """Per-dimension σ_d² = 1 / softplus(φ_d), shape (act_dim,)."""
        return 1.0 / F.softplus(self.raw_noise)

    @property
    def step_sizes(self) -> Tensor:
        """η (N, act_dim) in sampling order: row k is the step from x_{N-k} to x_{N-k-1}.

        η_k = dt_k σ² with dt_k = softplus(θ_T) · s(k) (:func:`cosine_schedule`)."""
        return (self.dt_scale * self.schedule)[:, None] * self.noise_var

    def prior_score(self, x: Tensor) -> Tensor:
        """∇ log N(x; 0, σ0² I) = -x / σ0²."""
        return -x / self.config.sigma0**2

    def forward(
        self, obs: Tensor, deterministic: bool = False, noise: Tensor | None = None
    ) -> PolicySample:
        return self.sample(obs, deterministic, noise=noise)

    def noise_shape(self, batch: int) -> tuple[int, int, int]:
        """Shape of the ``noise`` :meth:`sample` takes: x_N's draw, then ε_N, ..., ε_1."""
        return (self.config.n_steps + 1, batch, self.act_dim)

    def sample(
        self,
        obs: Tensor,
        deterministic: bool = False,
        generator: torch.Generator | None = None,
        return_trajectory: bool = False,
        noise: Tensor | None = None,
    ) -> PolicySample:
        """Run the chain for a batch of states ``obs`` (B, obs_dim), reparameterised throughout.

        ``deterministic=True`` starts at x_N = 0 and sets every ε_n = 0 (the noise-free path);
        its costs are then not an entropy estimate. ``generator`` seeds the noise; or
        ``noise`` (:meth:`noise_shape`) gives the standard normal draws themselves, in the
        order they would be drawn (a run over many seeds draws each seed's from its own
        stream, :mod:`vslbook.srl.seed_axis`).
        """
        if obs.ndim != 2 or obs.shape[1] != self.obs_dim:  # shapes only: no host sync
            raise ValueError(
                f"obs must have shape (batch, obs_dim) = (batch, {self.obs_dim}), "
                f"got {tuple(obs.shape)}"
            )
        c, batch = self.config, obs.shape[0]
        if noise is not None and tuple(noise.shape) != self.noise_shape(batch):
            raise ValueError(
                f"noise must have shape {self.noise_shape(batch)}, got {tuple(noise.shape)}"
            )
        draws = iter(() if noise is None else noise.unbind(0))

        def noise_draw() -> Tensor:
            if deterministic:
                return obs.new_zeros(batch, self.act_dim)
            if noise is not None:
                return next(draws)
            return torch.randn(
                batch, self.act_dim, generator=generator, device=obs.device, dtype=obs.dtype
            )

        n_steps = c.n_steps
        steps = torch.arange(n_steps, 0, -1, device=obs.device, dtype=obs.dtype)  # n = N..1
        score_emb = self.score_net.embed_steps(steps)
        noising_emb = None if self.noising_net is None else self.noising_net.embed_steps(steps - 1)
        etas = self.step_sizes

        x = c.sigma0 * noise_draw()  # x_N ~ N(0, σ0² I)
        var0 = c.sigma0**2
        terminal_cost = -0.5 * (x**2 / var0 + math.log(2.0 * math.pi * var0)).sum(dim=-1)
        log_ratio = obs.new_zeros(batch)
        path = [x]
        for k in range(n_steps):
            eta = etas[k]
            drift = self.prior_score(x) + self.score_net(x, score_emb[k], obs)
            eps = noise_draw()
            x_next = x + eta * drift + torch.sqrt(2.0 * eta) * eps  # Eq. 5.12
            # log π_{n-1|n}(x_{n-1}|x_n), written through ε so it is exact under reparam.
            log_generative = -0.5 * (eps**2 + torch.log(4.0 * math.pi * eta)).sum(dim=-1)
            back_drift = self.prior_score(x_next)
            if self.noising_net is not None:  # General Bridges: learned noising drift
                back_drift = back_drift + self.noising_net(x_next, noising_emb[k], obs)
            # log →π_{n|n-1}(x_n|x_{n-1}), the noising step (Eq. 5.11 / 5.35)
            log_noising = _gaussian_log_prob(x, x_next + eta * back_drift, 2.0 * eta)
            log_ratio = log_ratio + log_noising - log_generative
            x = x_next
            path.append(x)

        running_cost = -log_ratio
        action = x
        if c.squash:  # a = tanh(x_0), Eq. C.29-C.30
            action = torch.tanh(x)
            running_cost = running_cost - tanh_log_det_jacobian(x)
        trajectory = torch.stack(path) if return_trajectory else None
        return PolicySample(action, running_cost, terminal_cost, x, trajectory)
