"""Section 2.6.2 of the thesis: gating of a mixture of experts (Eqs. 2.47-2.49), the
Bayes gating of per-expert context distributions against numerical integrals.

Part of :mod:`vslbook.bounds.foundations` (Chapter 2's checks).
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
import torch
from scipy.stats import multivariate_normal

from vslbook.bounds import Check, CheckReport
from vslbook.bounds.toy_numerics import check_count, seeded_rng, to_numpy, to_tensor, worst_check
from vslbook.dists import LinearGaussianMoE


def _trapezoid_grid(lo: np.ndarray, hi: np.ndarray, n: int) -> tuple[np.ndarray, float]:
    """Tensor grid of shape ``(n, ..., n, d)`` on the box ``[lo, hi]`` and its cell volume."""
    axes = [np.linspace(a, b, n) for a, b in zip(lo, hi, strict=True)]
    volume = float(np.prod([(b - a) / (n - 1) for a, b in zip(lo, hi, strict=True)]))
    return np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1), volume


def _trapezoid_sum(values: np.ndarray, n_axes: int, volume: float) -> float:
    w = values
    for _ in range(n_axes):
        w = np.trapezoid(w, axis=0, dx=1.0)
    return float(w * volume)


def check_moe_gating(
    seed: int = 0,
    n_components: int = 3,
    gating: Callable[[LinearGaussianMoE, torch.Tensor], torch.Tensor] | None = None,
) -> CheckReport:
    """Bayes-rule gating and normalisation of the linear-Gaussian MoE (Eqs. 2.47-2.49).

    Checks that ``gating(model, c)`` equals ``p(o, c) / sum_o' p(o', c)`` computed directly
    from scipy densities, that it sums to 1, that ``log pi(theta | c) = log p(theta, c) -
    log p(c)``, that ``pi(theta | c)`` integrates to 1 over 1-D and 2-D parameter grids, that
    the joint ``p(theta, c)`` integrates to 1 over a 2-D grid, and that samples from
    ``LinearGaussianMoE.sample`` have the mixture mean.

    Args:
        gating: candidate ``(model, contexts) -> probabilities (..., K)``; defaults to
            ``model.gating``.

    Returns:
        Report with data ``contexts`` (n_c,), ``gating`` (n_c, K), ``theta`` (n_t,) and
        ``density`` (n_t, n_c) = ``pi(theta | c)`` of a model with 1-D context and parameter.
    """
    n_components = check_count("n_components", n_components)
    gating = gating or (lambda model, c: model.gating(c))
    gen = torch.Generator().manual_seed(int(seeded_rng(seed).integers(2**31)))
    model = LinearGaussianMoE.random(n_components, 2, 2, seed=seed)
    c, _ = model.sample_contexts(40, gen)
    cand = to_numpy(gating(model, c))
    joint = np.stack(
        [
            to_numpy(model.weights[o])
            * multivariate_normal(
                to_numpy(model.context_means[o]), to_numpy(model.context_covs[o])
            ).pdf(to_numpy(c))
            for o in range(n_components)
        ],
        axis=-1,
    )
    direct = joint / joint.sum(-1, keepdims=True)

    theta, _ = model.sample(c, gen)
    lhs_cond = to_numpy(model.log_prob(theta, c))
    rhs_cond = to_numpy(model.joint_log_prob(theta, c) - model.context_log_prob(c))

    # pi(theta | c) over a 2-D parameter grid, for a few contexts.
    masses_2d = []
    for ci in c[:3]:
        means = to_numpy(model.expert_means(ci))
        std = np.sqrt(np.max(np.linalg.eigvalsh(to_numpy(model.covs))))
        grid, vol = _trapezoid_grid(means.min(0) - 9 * std, means.max(0) + 9 * std, 141)
        dens = np.exp(to_numpy(model.log_prob(to_tensor(grid), ci)))
        masses_2d.append(_trapezoid_sum(dens, 2, vol))

    # 1-D context and parameter: conditional and joint normalisation.
    m1 = LinearGaussianMoE.random(n_components, 1, 1, seed=seed + 1)
    c_std = float(np.sqrt(to_numpy(m1.context_covs).max()))
    c_lo = float(to_numpy(m1.context_means).min()) - 9 * c_std
    c_hi = float(to_numpy(m1.context_means).max()) + 9 * c_std
    t_std = float(np.sqrt(to_numpy(m1.covs).max()))
    ends = to_numpy(m1.expert_means(to_tensor([[c_lo], [c_hi]])))
    t_lo, t_hi = float(ends.min()) - 9 * t_std, float(ends.max()) + 9 * t_std
    contexts = np.linspace(c_lo, c_hi, 161)
    thetas = np.linspace(t_lo, t_hi, 401)
    tt, cc = np.meshgrid(thetas, contexts, indexing="ij")
    cond = np.exp(to_numpy(m1.log_prob(to_tensor(tt[..., None]), to_tensor(cc[..., None]))))
    joint_2d = np.exp(
        to_numpy(m1.joint_log_prob(to_tensor(tt[..., None]), to_tensor(cc[..., None])))
    )
    dt, dc = thetas[1] - thetas[0], contexts[1] - contexts[0]
    masses_1d = np.trapezoid(cond, dx=dt, axis=0)
    joint_mass = np.trapezoid(np.trapezoid(joint_2d, dx=dt, axis=0), dx=dc)
    context_mass = np.trapezoid(
        np.exp(to_numpy(m1.context_log_prob(to_tensor(contexts[:, None])))), dx=dc
    )

    # Sampling: mean of theta | c against sum_o pi(o | c) mu_o(c).
    c0 = c[:1].expand(20000, 2)
    samples, _ = model.sample(c0, gen)
    mix_mean = to_numpy(model.gating(c[0]) @ model.expert_means(c[0]))
    se = to_numpy(samples.std(0)) / math.sqrt(samples.shape[0])

    checks = (
        worst_check(
            "gating pi(o|c) = p(o, c) / sum_o' p(o', c) (scipy densities)",
            "Eqs. 2.48, 2.64",
            cand,
            direct,
            1e-10,
        ),
        worst_check("gating sums to 1 over experts", "Eq. 2.48", cand.sum(-1), 1.0, 1e-12),
        worst_check(
            "log pi(theta|c) = log p(theta, c) - log p(c)", "Eq. 2.48", lhs_cond, rhs_cond, 1e-10
        ),
        worst_check(
            "integral of pi(theta|c) d theta = 1 (1-D grid)", "Eq. 2.48", masses_1d, 1.0, 1e-6
        ),
        worst_check(
            "integral of pi(theta|c) d theta = 1 (2-D grid)",
            "Eq. 2.48",
            np.array(masses_2d),
            1.0,
            1e-6,
        ),
        Check("integral of p(c) dc = 1 (1-D grid)", "Eq. 2.47", context_mass, 1.0, 1e-6),
        Check(
            "integral of p(theta, c) d theta dc = 1 (2-D grid)", "Eq. 2.47", joint_mass, 1.0, 1e-6
        ),
        worst_check(
            "sample mean of theta|c = sum_o pi(o|c) mu_o(c) (4 standard errors)",
            "Eq. 2.48",
            to_numpy(samples.mean(0)),
            mix_mean,
            4 * se,
        ),
    )
    data = {
        "contexts": contexts,
        "gating": to_numpy(m1.gating(to_tensor(contexts[:, None]))),
        "theta": thetas,
        "density": cond,
    }
    return CheckReport("Mixture-of-experts gating by Bayes' rule (Section 2.6.2)", checks, data)
