"""Di-SkilL's networks, K independent copies in one batched module (Chapter 4, Appendix B.3.1).

The mixture of Eq. 4.2 has, for each of its K experts o,

* a Gaussian expert π(θ | c, o) = N(μ_o(c), L_o L_oᵀ) whose mean is a tanh network and whose
  Cholesky factor L_o does not depend on the context (Appendix B.3.1 reports no gain from a
  contextual covariance): :class:`GaussianExperts`;
* an energy-based context distribution π(c | o) = exp φ_o(c) / Z (Eq. 4.6), Z approximated by
  a sum over contexts drawn from p(c): :class:`EnergyNets`;
* a value critic V_o(c), the baseline of the expert's advantage: :class:`ValueCritics`.

The gating follows from Bayes' rule with the fixed uniform prior π(o) = 1/K,
π(o | c) = π(c | o) / Σ_o' π(c | o') (:func:`log_gating`), and the responsibilities of the
experts' objective 4.4/4.7 are π(o | c, θ) ∝ π(θ | c, o) π(o | c)
(:func:`log_responsibilities`).

Every parameter carries a leading axis of length K and every forward pass is one batched
matrix product (``torch.baddbmm``) over that axis, so the K experts are updated together
by a single backward pass on the sum of their losses; the copies share no parameter, so
the gradient of expert k's loss is zero on every other copy. The parameterisation and
initialisation are those of the deep Gaussian policies of the trust-region layers (Otto et
al. 2021, "Differentiable trust region layers for deep reinforcement learning", ICLR), as
used by Di-SkilL: tanh hidden layers initialised orthogonally with gain √2 and zero bias,
an orthogonal output layer with a small gain (0.01 for the expert means and the energies,
1 for the critics), and a Cholesky diagonal diag = softplus(z + s) + 1e-5 with
s = softplus⁻¹(init_std − 1e-5), so that z = 0 gives L = init_std · I. Everything is
float64 unless another ``dtype`` is asked for (:class:`vslbook.erl.diskill.DiSkill` asks for
the configuration's, float32 by default).
"""

from __future__ import annotations

import math
import operator
from collections.abc import Sequence
from typing import Any

import torch
from torch import nn

__all__ = [
    "BatchedMLP",
    "EnergyNets",
    "GaussianExperts",
    "ValueCritics",
    "log_gating",
    "log_responsibilities",
]

MIN_STD = 1e-5  # the Cholesky diagonal is softplus(·) + MIN_STD


# -------------------------------------------------------------------------------- validation


def _positive_int(name: str, value: Any) -> int:
    try:
        n = operator.index(value)  # Python and numpy integers, not floats or bools
    except TypeError:
        n = 0
    if isinstance(value, bool) or n < 1:
        raise ValueError(f"{name} must be a positive integer, got {value!r}")
    return n


def _hidden_sizes(value: Any) -> tuple[int, ...]:
    if not isinstance(value, Sequence) or isinstance(value, str):
        raise ValueError(f"hidden must be a sequence of positive integers, got {value!r}")
    return tuple(_positive_int("each hidden size", h) for h in value)


def _positive_float(name: str, value: Any, above: float = 0.0) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a finite number > {above:g}, got {value!r}") from None
    if not math.isfinite(v) or v <= above:
        raise ValueError(f"{name} must be a finite number > {above:g}, got {value!r}")
    return v


def _tensor(
    name: str, value: Any, shape: tuple[int | None, ...], dtype: torch.dtype
) -> torch.Tensor:
    """``value`` as a finite tensor of ``dtype`` and ``shape`` (None: any size on that axis)."""
    x = torch.as_tensor(value)
    expected = "(" + ", ".join("·" if s is None else str(s) for s in shape) + ")"
    if x.dim() != len(shape) or any(
        s is not None and s != n for s, n in zip(shape, x.shape, strict=True)
    ):
        raise ValueError(f"{name} must have shape {expected}, got {tuple(x.shape)}")
    if x.dtype != dtype:
        raise ValueError(f"{name} must have dtype {dtype} (the networks' dtype), got {x.dtype}")
    if not torch.isfinite(x).all():
        raise ValueError(f"{name} must be finite, got non-finite entries")
    return x


# ----------------------------------------------------------------------------- the networks


class BatchedMLP(nn.Module):
    """K independent tanh MLPs evaluated in one batched pass.

    Layer l holds a weight of shape (K, n_in, n_out) and a bias of shape (K, 1, n_out); the
    forward pass is ``h ← tanh(baddbmm(b, h, W))`` for the hidden layers and the same
    without the tanh for the output layer (``hidden=()``: one affine map).

    Args:
        n_models: K, the number of independent copies.
        in_dim, out_dim: input and output sizes.
        hidden: the hidden layer sizes.
        head_gain: the gain of the output layer's orthogonal initialisation.
        dtype: the parameters' dtype.

    Initialisation: every copy independently from torch's global random stream (so
    ``torch.manual_seed`` fixes it): hidden weights orthogonal with gain √2, the output
    weight orthogonal with gain ``head_gain``, all biases zero.
    """

    def __init__(
        self,
        n_models: int,
        in_dim: int,
        hidden: Sequence[int],
        out_dim: int,
        *,
        head_gain: float,
        dtype: torch.dtype = torch.float64,
    ) -> None:
        super().__init__()
        self.n_models = _positive_int("n_models", n_models)
        self.in_dim = _positive_int("in_dim", in_dim)
        self.out_dim = _positive_int("out_dim", out_dim)
        self.hidden = _hidden_sizes(hidden)
        head_gain = _positive_float("head_gain", head_gain)
        self.dtype = dtype
        sizes = (self.in_dim, *self.hidden, self.out_dim)
        self.weights = nn.ParameterList()
        self.biases = nn.ParameterList()
        for layer, (n_in, n_out) in enumerate(zip(sizes[:-1], sizes[1:], strict=True)):
            gain = head_gain if layer == len(sizes) - 2 else math.sqrt(2.0)
            w = torch.empty(self.n_models, n_in, n_out, dtype=dtype)
            for k in range(self.n_models):
                block = torch.empty(n_out, n_in, dtype=dtype)  # torch.nn.Linear's layout
                nn.init.orthogonal_(block, gain=gain)
                w[k] = block.T
            self.weights.append(nn.Parameter(w))
            self.biases.append(nn.Parameter(torch.zeros(self.n_models, 1, n_out, dtype=dtype)))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """(K, B, in_dim) → (K, B, out_dim); copy k sees only x[k]."""
        return self.layers(_tensor("x", x, (self.n_models, None, self.in_dim), self.dtype))

    def layers(self, x: torch.Tensor) -> torch.Tensor:
        """:meth:`forward` without the input checks (for callers that checked ``x``)."""
        last = len(self.weights) - 1
        for layer, (w, b) in enumerate(zip(self.weights, self.biases, strict=True)):
            x = torch.baddbmm(b, x, w)
            if layer < last:
                x = torch.tanh(x)
        return x


def _softplus(x: torch.Tensor) -> torch.Tensor:
    return torch.logaddexp(x, torch.zeros_like(x))


def _softplus_inv(y: torch.Tensor) -> torch.Tensor:
    """The inverse of log(1 + eˣ) for y > 0, stable for small and large y."""
    return y + torch.log(-torch.expm1(-y))


class GaussianExperts(nn.Module):
    """K Gaussian experts π(θ | c, o) = N(μ_o(c), L_o L_oᵀ) (Appendix B.3.1).

    Args:
        n_experts: K.
        context_dim: dim c.
        theta_dim: d = dim θ.
        hidden: hidden sizes of the mean network; ``()`` gives linear experts μ_o(c) = A_o c + a_o
            (LinDi-SkilL).
        init_std: the standard deviation at initialisation, L = init_std · I (+ the small
            off-diagonals); must exceed 1e-5.
        dtype: the parameters' dtype.

    The mean is a :class:`BatchedMLP` with output gain 0.01, so μ_o(c) ≈ 0 at the start. The
    Cholesky factor is one flat parameter per expert of length d(d+1)/2 holding the lower
    triangle row by row; a diagonal entry z maps to softplus(z + s) + 1e-5 with
    s = softplus⁻¹(init_std − 1e-5) and starts at z = 0; the off-diagonal entries are used as
    they are and start as N(0, 0.01²) draws (the authors' choice: a slightly correlated
    rather than an exactly diagonal start).
    """

    def __init__(
        self,
        n_experts: int,
        context_dim: int,
        theta_dim: int,
        hidden: Sequence[int],
        *,
        init_std: float = 1.0,
        dtype: torch.dtype = torch.float64,
    ) -> None:
        super().__init__()
        self.n_experts = _positive_int("n_experts", n_experts)
        self.context_dim = _positive_int("context_dim", context_dim)
        self.theta_dim = d = _positive_int("theta_dim", theta_dim)
        init_std = _positive_float("init_std", init_std, above=MIN_STD)
        self.dtype = dtype
        self.mean_net = BatchedMLP(
            self.n_experts, self.context_dim, hidden, d, head_gain=0.01, dtype=dtype
        )
        rows, cols = torch.tril_indices(d, d)
        self.register_buffer("_rows", rows, persistent=False)
        self.register_buffer("_cols", cols, persistent=False)
        self.register_buffer("_is_diag", rows == cols, persistent=False)
        shift = _softplus_inv(torch.tensor(init_std - MIN_STD, dtype=dtype))
        self.register_buffer("chol_shift", shift)  # s; saved so a checkpoint keeps its init_std
        flat = torch.zeros(self.n_experts, len(rows), dtype=dtype)
        n_off = int((~self._is_diag).sum())
        if n_off:
            flat[:, ~self._is_diag] = 0.01 * torch.randn(self.n_experts, n_off, dtype=dtype)
        self.chol_flat = nn.Parameter(flat)

    # -- the parameters' maps -------------------------------------------------------------
    def mean(self, contexts: torch.Tensor) -> torch.Tensor:
        """μ_o(c): contexts (K, B, dc) → means (K, B, d)."""
        contexts = _tensor(
            "contexts", contexts, (self.n_experts, None, self.context_dim), self.dtype
        )
        return self.mean_net.layers(contexts)

    def chol(self) -> torch.Tensor:
        """The Cholesky factors L_o, (K, d, d), lower triangular with diagonal > 1e-5."""
        z = self.chol_flat
        entries = torch.where(self._is_diag, _softplus(z + self.chol_shift) + MIN_STD, z)
        k, d = self.n_experts, self.theta_dim
        out = z.new_zeros(k, d, d)
        out[:, self._rows, self._cols] = entries
        return out

    @torch.no_grad()
    def set_chol(self, chol: torch.Tensor) -> None:
        """Write the parameter so that :meth:`chol` returns ``chol`` (K, d, d).

        ``chol`` must be lower triangular with every diagonal entry > 1e-5 (the smallest
        value the parameterisation reaches).
        """
        k, d = self.n_experts, self.theta_dim
        chol = _tensor("chol", chol, (k, d, d), self.dtype)
        upper = torch.triu(chol, diagonal=1).abs().max() if d > 1 else chol.new_zeros(())
        scale = chol.abs().max()
        if upper > 1e-12 * max(float(scale), 1.0):
            raise ValueError(
                "chol must be lower triangular, got upper-triangle entries up to "
                f"{float(upper):.3g}"
            )
        diag = torch.diagonal(chol, dim1=-2, dim2=-1)
        if (diag <= MIN_STD).any():
            raise ValueError(
                f"chol's diagonal entries must be > {MIN_STD:g}, got a minimum of "
                f"{float(diag.min()):.3g}"
            )
        entries = chol[:, self._rows, self._cols]
        z = _softplus_inv(entries - MIN_STD) - self.chol_shift
        self.chol_flat.copy_(torch.where(self._is_diag, z, entries))

    # -- the Gaussian ---------------------------------------------------------------------
    def _check_chol(self, chol: torch.Tensor) -> torch.Tensor:
        chol = _tensor("chol", chol, (self.n_experts, self.theta_dim, self.theta_dim), self.dtype)
        if (torch.diagonal(chol, dim1=-2, dim2=-1) <= 0).any():
            raise ValueError("chol's diagonal entries must be > 0")
        return chol

    def log_prob(
        self, theta: torch.Tensor, mean: torch.Tensor, chol: torch.Tensor, *, check: bool = True
    ) -> torch.Tensor:
        """log N(θ | μ, LLᵀ): theta and mean (K, B, d), chol (K, d, d) → (K, B).

        ``check=False`` skips the input checks (for callers that checked their inputs).
        """
        k, d = self.n_experts, self.theta_dim
        if check:
            theta = _tensor("theta", theta, (k, None, d), self.dtype)
            mean = _tensor("mean", mean, (k, theta.shape[1], d), self.dtype)
            chol = self._check_chol(chol)
        # z = L⁻¹(θ − μ) per sample; ‖z‖² is the Mahalanobis distance
        z = torch.linalg.solve_triangular(chol, (theta - mean).transpose(1, 2), upper=False)
        half_log_det = torch.log(torch.diagonal(chol, dim1=-2, dim2=-1)).sum(-1)  # ½ log|Σ|
        return -0.5 * z.pow(2).sum(1) - half_log_det[:, None] - 0.5 * d * math.log(2 * math.pi)

    def entropy(self, chol: torch.Tensor, *, check: bool = True) -> torch.Tensor:
        """H[N(·, LLᵀ)] = ½ d (1 + log 2π) + Σ_i log L_ii: chol (K, d, d) → (K,)."""
        if check:
            chol = self._check_chol(chol)
        half_log_det = torch.log(torch.diagonal(chol, dim1=-2, dim2=-1)).sum(-1)
        return 0.5 * self.theta_dim * (1.0 + math.log(2 * math.pi)) + half_log_det

    def sample(
        self, contexts: torch.Tensor, generator: torch.Generator
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """One θ ~ π(θ | c, o) per context: contexts (K, B, dc) → (θ, μ), both (K, B, d).

        θ = μ_o(c) + L_o ε with ε ~ N(0, I) from ``generator`` (reparameterised: gradients
        flow unless the caller runs it under ``torch.no_grad``).
        """
        mean = self.mean(contexts)
        eps = torch.randn(mean.shape, generator=generator, dtype=self.dtype)
        return mean + eps @ self.chol().transpose(1, 2), mean


class EnergyNets(nn.Module):
    """K energy functions φ_o(c) of the context distributions π(c | o) ∝ exp φ_o(c) (Eq. 4.6).

    Args:
        n_experts: K.
        context_dim: dim c.
        hidden: hidden sizes (tanh), (16, 16) in the thesis' experiments.
        dtype: the parameters' dtype.

    The output layer is initialised with gain 0.01, so every π(c | o) starts close to
    uniform over any batch of contexts.
    """

    def __init__(
        self,
        n_experts: int,
        context_dim: int,
        hidden: Sequence[int] = (16, 16),
        *,
        dtype: torch.dtype = torch.float64,
    ) -> None:
        super().__init__()
        self.n_experts = _positive_int("n_experts", n_experts)
        self.context_dim = _positive_int("context_dim", context_dim)
        self.dtype = dtype
        self.net = BatchedMLP(
            self.n_experts, self.context_dim, hidden, 1, head_gain=0.01, dtype=dtype
        )

    def energies(self, contexts: torch.Tensor) -> torch.Tensor:
        """φ_o(c_i): contexts (N, dc) shared by all experts, or (K, N, dc) per expert → (K, N)."""
        x = torch.as_tensor(contexts)
        if x.dim() == 2:
            x = _tensor("contexts", x, (None, self.context_dim), self.dtype)
            x = x.expand(self.n_experts, -1, -1)
        elif x.dim() == 3:
            x = _tensor("contexts", x, (self.n_experts, None, self.context_dim), self.dtype)
        else:
            raise ValueError(
                f"contexts must have shape (N, {self.context_dim}) or "
                f"({self.n_experts}, N, {self.context_dim}), got {tuple(x.shape)}"
            )
        return self.net.layers(x)[..., 0]

    def log_probs(self, contexts: torch.Tensor) -> torch.Tensor:
        """log π(c_i | o) = φ_o(c_i) − log Σ_j exp φ_o(c_j), normalised over the N given contexts.

        This is Eq. 4.6 with Z approximated by the batch itself: (N, dc) or (K, N, dc) → (K, N).
        """
        return torch.log_softmax(self.energies(contexts), dim=-1)


class ValueCritics(nn.Module):
    """K value functions V_o(c), the baselines of the experts' advantages (Appendix B.3).

    Args:
        n_experts: K.
        context_dim: dim c.
        hidden: hidden sizes (tanh).
        dtype: the parameters' dtype.

    The output layer is initialised orthogonally with gain 1.
    """

    def __init__(
        self,
        n_experts: int,
        context_dim: int,
        hidden: Sequence[int],
        *,
        dtype: torch.dtype = torch.float64,
    ) -> None:
        super().__init__()
        self.n_experts = _positive_int("n_experts", n_experts)
        self.context_dim = _positive_int("context_dim", context_dim)
        self.dtype = dtype
        self.net = BatchedMLP(
            self.n_experts, self.context_dim, hidden, 1, head_gain=1.0, dtype=dtype
        )

    def values(self, contexts: torch.Tensor) -> torch.Tensor:
        """V_o(c): contexts (K, B, dc) → (K, B)."""
        x = _tensor("contexts", contexts, (self.n_experts, None, self.context_dim), self.dtype)
        return self.net.layers(x)[..., 0]


# ------------------------------------------------------------------------ Bayes' rule


def log_gating(log_pc: torch.Tensor) -> torch.Tensor:
    """log π(o | c) from log π(c | o) with the uniform prior π(o) = 1/K (Appendix B.3.1).

    Args:
        log_pc: (K, N), row o = log π(c_i | o) for the same N contexts (each row normalised
            in the same way, e.g. over one batch from p(c)).

    Returns:
        (K, N): log π(c_i | o) − log Σ_o' π(c_i | o'); the prior 1/K cancels.
    """
    log_pc = torch.as_tensor(log_pc)
    if log_pc.dim() != 2:
        raise ValueError(f"log_pc must have shape (K, N), got {tuple(log_pc.shape)}")
    if not torch.isfinite(log_pc).all():
        raise ValueError("log_pc must be finite, got non-finite entries")
    return log_pc - torch.logsumexp(log_pc, dim=0, keepdim=True)


def log_responsibilities(
    theta: torch.Tensor,
    contexts: torch.Tensor,
    experts: GaussianExperts,
    log_pc: torch.Tensor,
) -> torch.Tensor:
    """log π(o | c, θ) of each expert's own samples (the responsibilities of Eq. 4.4).

    Args:
        theta: (K, B, d), θ_kb drawn by expert k at context c_kb.
        contexts: (K, B, dc), the c_kb.
        experts: the experts; all K are evaluated on all K·B samples in one batched call.
        log_pc: (K, K, B) with ``log_pc[o', k, b]`` = log π(c_kb | o') (normalised as the
            caller chooses, the same way for every o').

    Returns:
        (K, B), entry [k, b] = log π(θ_kb | c_kb, k) + log π(k | c_kb)
        − log Σ_o' π(θ_kb | c_kb, o') π(o' | c_kb), with π(o | c) from :func:`log_gating`.
    """
    k, d, dc = experts.n_experts, experts.theta_dim, experts.context_dim
    theta = _tensor("theta", theta, (k, None, d), experts.dtype)
    b = theta.shape[1]
    contexts = _tensor("contexts", contexts, (k, b, dc), experts.dtype)
    log_pc = _tensor("log_pc", log_pc, (k, k, b), experts.dtype)
    # every expert o' on all K·B samples: rows o', columns (k, b)
    all_ctx = contexts.reshape(1, k * b, dc).expand(k, -1, -1)
    all_theta = theta.reshape(1, k * b, d).expand(k, -1, -1)
    log_p_theta = experts.log_prob(all_theta, experts.mean(all_ctx), experts.chol())
    log_gate = log_gating(log_pc.reshape(k, k * b))
    joint = (log_p_theta + log_gate).reshape(k, k, b)  # [o', k, b]
    own = torch.arange(k)
    return joint[own, own] - torch.logsumexp(joint, dim=0)
