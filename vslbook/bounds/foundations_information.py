"""Section 2.8 of the thesis: mutual information and its variational lower bound
(Eqs. 2.72-2.74).

Part of :mod:`vslbook.bounds.foundations` (Chapter 2's checks).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from scipy.special import xlogy

from vslbook.bounds import Check, CheckReport, relative_tol
from vslbook.bounds.toy_numerics import check_count, check_distribution, seeded_rng, worst_check


def _entropy(p: np.ndarray, axis: int = -1) -> np.ndarray:
    return -xlogy(p, p).sum(axis)


def check_mutual_information(
    seed: int = 0,
    n_z: int = 4,
    n_s: int = 6,
    n_random: int = 50,
    posterior: Callable[[np.ndarray], np.ndarray] | None = None,
) -> CheckReport:
    """Mutual information identities and the variational lower bound (Eqs. 2.72-2.74).

    On a random joint ``p(z, s)`` (shape ``(n_z, n_s)``) checks Eq. 2.72 = 2.73 = 2.74,
    ``I >= 0``, ``I >= H(z) + E_p(z,s)[log q(z|s)]`` for ``n_random`` random ``q(z|s)``, that the
    gap is ``E_p(s)[KL(p(z|s) || q(z|s))]``, and that the bound is tight for ``posterior``.

    Args:
        posterior: candidate ``p_zs -> q(z|s)`` of shape ``(n_z, n_s)`` (columns sum to 1);
            defaults to the true posterior ``p(z|s)``.

    Returns:
        Report with data ``p_zs``, ``mi`` and ``bounds`` (one per random ``q``).
    """
    nz, ns = check_count("n_z", n_z), check_count("n_s", n_s)
    rng = seeded_rng(seed)
    p_zs = rng.dirichlet(np.ones(nz * ns)).reshape(nz, ns)
    p_z, p_s = p_zs.sum(1), p_zs.sum(0)
    p_z_given_s = p_zs / p_s[None, :]
    p_s_given_z = p_zs / p_z[:, None]
    mi_72 = float(np.sum(p_zs * np.log(p_zs / np.outer(p_z, p_s))))
    mi_73 = float(_entropy(p_z) - p_s @ _entropy(p_z_given_s, axis=0))
    mi_74 = float(_entropy(p_s) - p_z @ _entropy(p_s_given_z, axis=1))

    def bound(q_z_given_s: np.ndarray) -> float:
        with np.errstate(divide="ignore"):
            return float(_entropy(p_z) + np.sum(p_zs * np.log(q_z_given_s)))

    def gap(q_z_given_s: np.ndarray) -> float:
        kl = np.sum(xlogy(p_z_given_s, p_z_given_s) - p_z_given_s * np.log(q_z_given_s), 0)
        return float(p_s @ kl)

    randoms = [
        rng.dirichlet(np.ones(nz), size=ns).T for _ in range(check_count("n_random", n_random))
    ]
    bounds = np.array([bound(q) for q in randoms])
    cand = (
        p_z_given_s
        if posterior is None
        else check_distribution("posterior(p_zs)", posterior(p_zs), (nz, ns), axis=0)
    )
    tol = relative_tol(mi_72)
    checks = (
        Check("Eq. 2.72 = Eq. 2.73 (H(z) - E_p(s)[H(z|s)])", "Eqs. 2.72-2.73", mi_72, mi_73, tol),
        Check("Eq. 2.72 = Eq. 2.74 (H(s) - E_p(z)[H(s|z)])", "Eqs. 2.72, 2.74", mi_72, mi_74, tol),
        Check("I(z, s) >= 0", "Eq. 2.72", 0.0, mi_72, tol, "<="),
        Check(
            f"H(z) + E[log q(z|s)] <= I(z, s) for {n_random} random q",
            "Eq. 2.73",
            bounds.max(),
            mi_72,
            tol,
            "<=",
        ),
        worst_check(
            "I - bound = E_p(s)[KL(p(z|s)||q(z|s))]",
            "Eq. 2.73",
            mi_72 - bounds,
            [gap(q) for q in randoms],
            tol,
        ),
        Check("bound is tight for q(z|s) = p(z|s)", "Eq. 2.73", bound(cand), mi_72, tol),
    )
    return CheckReport(
        "Mutual information and its variational bound (Section 2.8)",
        checks,
        {"p_zs": p_zs, "mi": np.array(mi_72), "bounds": bounds},
    )
