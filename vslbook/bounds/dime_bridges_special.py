"""Numerical check of Section 5.6 (DIME): DIME is the general bridge with ``u = 0``.

:func:`check_dime_as_bridge` checks that DIME's chains are the special case ``f = -beta a``,
``u = 0``, ``v = 2 grad log pi~`` of the general bridges of Eqs. 5.29-5.38, in the thesis's
notation (:func:`~vslbook.bounds.dime_bridges.dime_bridge`) and as the library's
:class:`~vslbook.srl.DiffusionPolicy`, with and without ``general_bridges``
(:func:`~vslbook.bounds.dime_bridges.policy_bridge`).

Import from :mod:`vslbook.bounds.dime`, which re-exports everything public here.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
import torch
from torch import nn

from vslbook.bounds import Check, CheckReport, relative_tol
from vslbook.bounds.dime_bridges import (
    GeneralBridge,
    dime_bridge,
    entropy_bound_samples,
    policy_bridge,
    sample_backward,
)
from vslbook.bounds.dime_bridges_linear import linear_bridge_closed_form
from vslbook.bounds.dime_entropy import single_thread
from vslbook.bounds.dime_linear_chain import AffineScore, linear_gaussian_chain
from vslbook.bounds.toy_numerics import check_count, seeded_rng, worst_check
from vslbook.srl.diffusion_policy import DiffusionPolicy, DiffusionPolicyConfig, ScoreNetwork

__all__ = ["check_dime_as_bridge"]


def _policy(
    general_bridges: bool, affine: tuple[np.ndarray, ...] | None, seed: int
) -> DiffusionPolicy:
    """A float64 DiffusionPolicy (no tanh) with random nonlinear networks, or affine ones
    ``(slope, offset, noise_slope, noise_offset)``."""
    config = DiffusionPolicyConfig(
        n_steps=4,
        sigma0=1.3,
        dt=0.4,
        sigma_init=0.9,
        learn_beta=False,
        learn_dt=False,
        n_frequencies=8,
        hidden=16,
        n_layers=2,
        out_init_scale=1.0,
        squash=False,
        general_bridges=general_bridges,
    )
    with torch.random.fork_rng(devices=[]):
        torch.manual_seed(seed)
        policy = DiffusionPolicy(obs_dim=3, act_dim=2, config=config).double()
        with torch.no_grad():
            policy.raw_noise.add_(0.3 * torch.randn(2, dtype=torch.float64))
            if policy.noising_net is not None:
                nn.init.normal_(policy.noising_net.out.weight, std=0.3)
                nn.init.normal_(policy.noising_net.out.bias, std=0.3)
    if affine is not None:
        slope, offset, noise_slope, noise_offset = (torch.as_tensor(x) for x in affine)
        for name, s, o in (
            ("score_net", slope, offset),
            ("noising_net", noise_slope, noise_offset),
        ):
            net = ScoreNetwork(3, 2, config).double()
            with torch.no_grad():
                nn.init.zeros_(net.out.weight)
                net.out.bias.copy_(o)
            setattr(policy, name, AffineScore(net, s))
    return policy


def _thesis_dime_kernels(beta, delta, eta, score, a, n):
    """Eqs. 5.11b and 5.12 written out: (noising mean, denoising mean, variance)."""
    noising = a - beta * a * delta
    denoising = a + (beta * a + 2 * eta**2 * beta * score(a, n)) * delta
    return noising, denoising, 2 * eta**2 * beta * delta


def check_dime_as_bridge(
    seed: int = 0,
    n_samples: int = 4000,
    bridge_of: Callable[[torch.nn.Module, np.ndarray], GeneralBridge] | None = None,
) -> CheckReport:
    """DIME is the general bridge ``f = -beta a``, ``u = 0``, ``v = 2 grad log pi~`` (Section 5.6).

    * Thesis notation: the kernels of :func:`dime_bridge` (Eqs. 5.35-5.36) equal Eqs. 5.11b
      and 5.12 written out, for a nonlinear score, ``eta != 1`` and random points.
    * Closed form: for an affine score, ``ℓ``, ``H`` and the gap of :func:`dime_bridge`
      (:func:`~vslbook.bounds.dime_bridges_linear.linear_bridge_closed_form`) equal those of
      DIME's own chain (:func:`~vslbook.bounds.dime_linear_chain.linear_gaussian_chain`).
    * The library: the :class:`~vslbook.srl.DiffusionPolicy`'s single-chain ``entropy_bound``
      equals the bridge estimator :func:`entropy_bound_samples` of :func:`policy_bridge` on
      the policy's own chains (random nonlinear networks, ``general_bridges`` off and on); its
      sampler and :func:`sample_backward` on the bridge give the same ``a^0`` moments (5 SE);
      and with affine networks the bridge's closed form equals ``linear_gaussian_chain`` with
      the learned noising drift (``noise_slope``, ``noise_offset``).

    Args:
        bridge_of: candidate ``(policy, obs) -> GeneralBridge``; defaults to
            :func:`policy_bridge`.

    Returns:
        Report with data ``library_bound`` and ``bridge_bound`` (per chain, ``general_bridges``
        on) and ``closed_form`` (rows: DIME thesis notation, library GB; columns: ``ℓ``,
        ``H``, gap, each bridge then chain).
    """
    n_samples = check_count("n_samples", n_samples, 10)
    to_bridge = bridge_of or policy_bridge
    rng = seeded_rng(seed, 59)
    with single_thread():
        # thesis notation, nonlinear score
        beta, delta, eta, n_steps = 0.8, 0.15, 1.4, 5
        score_c = rng.normal(size=2)

        def score(a: np.ndarray, n: int) -> np.ndarray:
            return -a / (1 + n) + score_c * np.sin(a)

        dime = dime_bridge(beta, delta, n_steps, 2, score, eta)
        a = rng.normal(size=(50, 2)) * 2
        gaps = []
        for n in range(1, n_steps):
            noising, denoising, var = _thesis_dime_kernels(beta, delta, eta, score, a, n)
            gaps += [
                np.abs(dime.forward_mean(a, n) - noising).max(),
                np.abs(dime.backward_mean(a, n) - denoising).max(),
                np.abs(dime.kernel_var(n) - var).max(),
            ]
        gaps.append(np.abs(dime.prior_var - eta**2).max())

        # closed form: affine score s(a) = c a + o  <->  library slope 2/eta^2 + 2c, offset 2o
        c_aff, o_aff = rng.uniform(-0.8, 0.0, 2), rng.normal(size=2)
        affine = dime_bridge(beta, delta, n_steps, 2, lambda a, n: a * c_aff + o_aff, eta)
        cf = linear_bridge_closed_form(affine, np.zeros(2), np.eye(2))
        chain = linear_gaussian_chain(
            np.full((n_steps, 2), eta**2 * beta * delta), eta, 2 / eta**2 + 2 * c_aff, 2 * o_aff
        )
        rows = [
            [
                cf.bound,
                chain.bound.sum(),
                cf.entropy,
                chain.entropy.sum(),
                cf.gap_kl,
                chain.kl.sum(),
            ]
        ]

        # the library's policy, nonlinear networks, without and with general bridges
        obs = rng.normal(size=3)
        obs_batch = torch.as_tensor(np.tile(obs, (n_samples, 1)))
        sample_gaps, sample_scale, moments = [], [], []
        library_bound = bridge_bound = None
        for gb in (False, True):
            policy = _policy(gb, None, seed)
            out = policy.sample(
                obs_batch, generator=torch.Generator().manual_seed(seed), return_trajectory=True
            )
            traj = out.trajectory.detach().numpy()[::-1]  # traj[n] = a^n
            bridge = to_bridge(policy, obs)
            library_bound = out.entropy_bound.detach().numpy()
            bridge_bound = entropy_bound_samples(bridge, traj)
            sample_gaps.append(np.abs(library_bound - bridge_bound).max())
            sample_scale.append(relative_tol(float(np.abs(library_bound).max()), rtol=1e-9))
            if gb:
                ours = sample_backward(bridge, n_samples, seed)[0]
                moments = [
                    traj[0].mean(0),
                    ours.mean(0),
                    traj[0].var(0, ddof=1),
                    ours.var(0, ddof=1),
                ]

        # affine library GB policy: the bridge's closed form vs linear_gaussian_chain
        coef = [
            rng.uniform(-0.6, 0.0, 2),
            rng.normal(size=2),
            rng.uniform(-0.6, 0.0, 2),
            rng.normal(size=2),
        ]
        policy = _policy(True, tuple(coef), seed)
        cf_gb = linear_bridge_closed_form(to_bridge(policy, obs), np.zeros(2), np.eye(2))
        etas = policy.step_sizes.detach().numpy()
        chain = linear_gaussian_chain(etas, policy.config.sigma0, *coef)
        rows.append(
            [
                cf_gb.bound,
                chain.bound.sum(),
                cf_gb.entropy,
                chain.entropy.sum(),
                cf_gb.gap_kl,
                chain.kl.sum(),
            ]
        )
    rows = np.array(rows)
    m_se = np.sqrt((moments[2] + moments[3]) / n_samples)
    v_se = (moments[2] + moments[3]) * math.sqrt(2 / (n_samples - 1))
    checks = (
        Check(
            "dime_bridge kernels = Eqs. 5.11b-5.12 written out (max abs difference)",
            "Eqs. 5.11b-5.12, 5.35-5.36",
            max(gaps),
            0.0,
            1e-12,
        ),
        worst_check(
            "DIME in thesis notation: bridge closed form = DIME chain (ℓ, H, gap)",
            "Eqs. 5.15, 5.35-5.36",
            rows[0, ::2],
            rows[0, 1::2],
            relative_tol(*rows[0], rtol=1e-9),
        ),
        worst_check(
            "DiffusionPolicy entropy_bound = bridge estimator, per chain (GB off, on)",
            "Eqs. 5.15, 5.35-5.36",
            np.array(sample_gaps),
            0.0,
            np.array(sample_scale),
        ),
        worst_check(
            "DiffusionPolicy (GB) a^0 mean = bridge sampler's (5 SE)",
            "Eqs. 5.32, 5.34",
            moments[0],
            moments[1],
            5 * m_se,
        ),
        worst_check(
            "DiffusionPolicy (GB) a^0 variance = bridge sampler's (5 SE)",
            "Eqs. 5.32, 5.34",
            moments[2],
            moments[3],
            5 * v_se,
        ),
        worst_check(
            "affine GB policy: bridge closed form = linear_gaussian_chain (ℓ, H, gap)",
            "Eqs. 5.15, 5.35-5.37",
            rows[1, ::2],
            rows[1, 1::2],
            relative_tol(*rows[1], rtol=1e-9),
        ),
    )
    data = {"library_bound": library_bound, "bridge_bound": bridge_bound, "closed_form": rows}
    return CheckReport("DIME as a general bridge (Sections 5.4 and 5.6)", checks, data)
