"""Di-SkilL's updates, lines 7 and 8 of Algorithm 2 (Chapter 4), all K experts at once.

* :func:`update_experts`: Eq. 4.7, the experts' trust-region policy gradient
  (:mod:`vslbook.erl.trpl` projects every proposal into the trust region);
* :func:`update_critics`: the value critics V_o(c) regress the returns;
* :func:`update_contexts`: Eq. 4.8, PPO on the energy networks φ_o of π(c | o) (Eq. 4.6).

Each is a loop of full-batch Adam steps on the sum of the K experts' losses (the experts
share no parameter, so this is K independent updates; see :mod:`vslbook.erl.diskill`).

The context update evaluates every energy network on all the iteration's contexts from
p(c) (5000 at the thesis's sizes) in every one of its 100 epochs: with the small networks
everywhere else, this is most of the networks' arithmetic. :func:`energy_pass` does that
forward pass and its backward pass written out rather than through autograd: the K
networks run feature-major, (K, width, N), so every matrix product runs along the long
context axis and the first layer, whose input the K networks share, is one matrix product
for all of them; tanh is evaluated as 2σ(2z) − 1 (the same function, to rounding; PyTorch's
CPU sigmoid is several times faster than its tanh); and no intermediate is kept that the
backward pass does not need. ``tests/test_erl_diskill_updates.py`` checks it against
:meth:`~vslbook.erl.diskill_nets.EnergyNets.energies` and autograd.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import torch
from torch import Tensor

from vslbook.erl import trpl
from vslbook.erl.diskill_config import DiSkillConfig
from vslbook.erl.diskill_nets import EnergyNets, GaussianExperts, ValueCritics

__all__ = [
    "clip_per_expert", "energy_pass", "standardise", "update_contexts", "update_critics",
    "update_experts",
]  # fmt: skip


def standardise(x: Tensor) -> Tensor:
    """Per expert (rows): zero mean, unit standard deviation (+1e-8), as the authors."""
    return (x - x.mean(1, keepdim=True)) / (x.std(1, keepdim=True) + 1e-8)


def clip_per_expert(params: list[Tensor], max_norm: float) -> Tensor:
    """Scale each expert's gradient (leading axis) to norm ≤ ``max_norm``; returns the norms."""
    sq = sum(p.grad.reshape(p.shape[0], -1).pow(2).sum(1) for p in params if p.grad is not None)
    norms = torch.as_tensor(sq).sqrt()
    scale = (max_norm / (norms + 1e-6)).clamp(max=1.0)
    for p in params:
        if p.grad is not None:
            p.grad.mul_(scale.reshape(-1, *([1] * (p.dim() - 1))))
    return norms


# ---------------------------------------------------------------- the energy networks' pass


def _tanh_(z: Tensor) -> Tensor:
    """tanh(z/2) in place, as 2σ(z) − 1 (the caller has doubled z)."""
    return torch.sigmoid(z, out=z).mul_(2.0).sub_(1.0)


def energy_pass(
    energies: EnergyNets, contexts: Tensor, *, backward: bool = True
) -> tuple[Tensor, Callable[[Tensor], None] | None]:
    """φ_o(c_i) of every energy network on shared contexts, and its backward pass.

    Args:
        energies: the K energy networks (Eq. 4.6).
        contexts: (N, dc), evaluated by every network, in the networks' dtype.
        backward: also keep what the backward pass needs.

    Returns:
        ``(phi, accumulate)``: ``phi`` (K, N), the values of
        :meth:`~vslbook.erl.diskill_nets.EnergyNets.energies` (to rounding), not tracked by
        autograd; ``accumulate(g)`` adds the gradient of Σ_{o,i} g_oi φ_o(c_i) to each
        parameter's ``.grad`` (``None`` when ``backward`` is False).

    Layer l maps a_l (K, n_l, N) to a_{l+1} = tanh(W_lᵀ a_l + b_l) (the last layer without
    the tanh). Backward, with δ_L = g: ∂W_l = a_l δ_lᵀ, ∂b_l = Σ_i δ_l, and
    δ_{l−1} = (W_l δ_l) ⊙ (1 − a_l²).
    """
    net = energies.net
    k = net.n_models
    x = contexts.detach()
    if x.dim() != 2 or x.shape[1] != net.in_dim or x.dtype != net.dtype:
        raise ValueError(
            f"contexts must have shape (N, {net.in_dim}) and dtype {net.dtype}, got "
            f"{tuple(x.shape)} and {x.dtype}"
        )
    n = x.shape[0]
    weights = [w.detach() for w in net.weights]
    biases = [b.detach() for b in net.biases]
    last = len(weights) - 1
    acts: list[Tensor] = []  # the hidden layers' outputs a_1 … a_L (K, n_l, N)
    with torch.no_grad():
        xt = x.T.contiguous()  # (dc, N), shared
        h = xt
        for layer, (w, b) in enumerate(zip(weights, biases, strict=True)):
            width = w.shape[2]
            scale = 1.0 if layer == last else 2.0  # 2z: tanh(z) = 2σ(2z) − 1
            if layer == 0:  # one product for all K networks: (K·n_1, dc) @ (dc, N)
                w0 = w.transpose(1, 2).reshape(k * width, -1)
                z = torch.addmm(b.reshape(k * width, 1), w0, h, beta=scale, alpha=scale)
                z = z.view(k, width, n)
            else:
                z = torch.baddbmm(b.transpose(1, 2), w.transpose(1, 2), h, beta=scale, alpha=scale)
            if layer < last:
                h = _tanh_(z)
                if backward:
                    acts.append(h)
            else:
                h = z
    phi = h[:, 0, :]
    if not backward:
        return phi, None

    def accumulate(g: Tensor) -> None:
        with torch.no_grad():
            delta = g.detach().reshape(k, 1, n)  # ∂/∂z of the output layer
            for layer in range(last, -1, -1):
                w, b = net.weights[layer], net.biases[layer]
                width = w.shape[2]
                if layer == 0:  # (dc, N) @ (N, K·n_1)
                    gw = torch.mm(xt, delta.reshape(k * width, n).T)
                    gw = gw.reshape(-1, k, width).transpose(0, 1)
                else:
                    gw = torch.bmm(acts[layer - 1], delta.transpose(1, 2))
                gb = delta.sum(2).reshape(k, 1, width)
                for p, grad in ((w, gw), (b, gb)):
                    if p.grad is None:
                        p.grad = grad.contiguous()
                    else:
                        p.grad.add_(grad)
                if layer > 0:  # W_l δ_l: an outer product where δ_l has one row
                    w = w.detach()
                    back = w * delta if width == 1 else torch.bmm(w, delta)
                    delta = torch.ops.aten.tanh_backward(back, acts[layer - 1])

    return phi, accumulate


# ---------------------------------------------------------------- line 7: experts and critics


def update_experts(
    experts: GaussianExperts, opt: torch.optim.Optimizer, batch: dict[str, Any], adv: Tensor,
    config: DiSkillConfig,
) -> dict[str, float]:  # fmt: skip
    """Eq. 4.7: ``config.epochs`` Adam steps on −E[r A] − α H[π̃] + α_TR m(π ‖ sg(π̃)).

    r = π̃(θ | c) / π_old(θ | c) with π̃ the projection of the network's Gaussian onto the
    trust region around the sampling policy (:func:`vslbook.erl.trpl.project`), ``adv`` the
    standardised advantages A (K, n); afterwards each expert's covariance is set to its
    projected value. Returns the last loss (per expert) and the KL parts to the old policy.
    """
    cfg = config
    ctx, theta = batch["ctx"], batch["theta"]
    mean_old, chol_old = batch["mean_old"], batch["chol_old"]
    with torch.no_grad():
        logp_old = experts.log_prob(theta, mean_old, chol_old)
    for epoch in range(cfg.epochs):
        check = epoch == 0  # later epochs' inputs come from the same networks
        mean = experts.mean(ctx) if check else experts.mean_net.layers(ctx)
        chol = experts.chol()
        p_mean, p_chol = trpl.project(
            mean, chol, mean_old, chol_old, cfg.mean_bound, cfg.cov_bound, check=check
        )
        ratio = torch.exp(experts.log_prob(theta, p_mean, p_chol, check=check) - logp_old)
        loss = (
            -(ratio * adv).mean(1)
            - cfg.alpha * experts.entropy(p_chol, check=check)
            + cfg.trust_region_coeff * trpl.trust_region_loss(mean, p_mean, p_chol, check=check)
        ).sum()
        opt.zero_grad()
        loss.backward()
        opt.step()
    with torch.no_grad():  # the covariance becomes its projection
        mean = experts.mean(ctx)
        p_chol = trpl.project_cov(experts.chol(), chol_old, cfg.cov_bound)
        experts.set_chol(p_chol)
        kl_mean, kl_cov = trpl.kl_parts(mean, experts.chol(), mean_old, chol_old)
        entropy = experts.entropy(experts.chol())
    return {
        "expert_loss": loss.item() / cfg.n_experts,
        "kl_mean": float(kl_mean.mean()),
        "kl_cov": float(kl_cov.mean()),
        "expert_entropy": entropy.mean().item(),
    }


def update_critics(
    critics: ValueCritics, opt: torch.optim.Optimizer, contexts: Tensor, returns: Tensor,
    epochs: int,
) -> dict[str, float]:  # fmt: skip
    """Line 7: ``epochs`` Adam steps of V_o(c) on the squared error to the returns (K, n)."""
    critics.values(contexts)  # checks the contexts once
    for _ in range(epochs):
        v_loss = (critics.net.layers(contexts)[..., 0] - returns).pow(2).mean(1).sum()
        opt.zero_grad()
        v_loss.backward()
        opt.step()
    return {"critic_loss": v_loss.item() / critics.n_experts}


# ---------------------------------------------------------------- line 8: context distributions


def update_contexts(
    energies: EnergyNets, opt: torch.optim.Optimizer, batch: dict[str, Any], adv: Tensor,
    config: DiSkillConfig,
) -> dict[str, float]:  # fmt: skip
    """Eq. 4.8 by PPO: ``config.context_epochs`` Adam steps on

        −E[min(r L_c, clip(r) L_c)] − β H[π(·|o)] − (β − α) Σ_i π(c_i | o) log π̃(o | c_i),

    r = π(c | o) / π_old(c | o) on the sampled contexts (``batch["idx"]`` into the
    iteration's contexts from p(c), ``batch["c_env"]``), π(c_i | o) the softmax of φ_o over
    those contexts, ``adv`` the sample estimate of L_c(o, c) (K, n), log π̃(o | c_i) the
    gating before the update (``batch["log_gate_env"]``, None: the term is left out, as in
    Di-SkilLV2/V3). Each expert's gradient is clipped to norm ``config.context_grad_clip``.
    The loss is differentiated by autograd down to the energies φ (K, N) and by
    :func:`energy_pass` from there to the parameters.
    """
    cfg = config
    c_env, idx, gate = batch["c_env"], batch["idx"], batch["log_gate_env"]
    params = list(energies.parameters())
    with torch.no_grad():
        phi, _ = energy_pass(energies, c_env, backward=False)
        logp_old = torch.log_softmax(phi, -1).gather(1, idx)
    for _ in range(cfg.context_epochs):
        phi, accumulate = energy_pass(energies, c_env)
        phi.requires_grad_(True)
        logp = torch.log_softmax(phi, -1)  # (K, N)
        ratio = torch.exp(logp.gather(1, idx) - logp_old)
        clipped = ratio.clamp(1 - cfg.context_clip, 1 + cfg.context_clip)
        surrogate = torch.minimum(ratio * adv, clipped * adv).mean(1)
        p = logp.exp()
        entropy = -(p * logp).sum(1)  # H[π(·|o)] over the drawn contexts
        resp = (p * gate).sum(1) if gate is not None else torch.zeros_like(entropy)
        loss = (-surrogate - cfg.beta * entropy - (cfg.beta - cfg.alpha) * resp).sum()
        (g,) = torch.autograd.grad(loss, phi)
        opt.zero_grad()
        accumulate(g)
        clip_per_expert(params, cfg.context_grad_clip)
        opt.step()
    return {
        "context_loss": loss.item() / cfg.n_experts,
        "context_entropy": entropy.mean().item(),
    }
