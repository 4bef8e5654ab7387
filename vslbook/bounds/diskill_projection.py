"""Independent references for the trust-region projection layers of Di-SkilL's expert update
(Section 4.4, Eq. 4.7; `vslbook.erl.trpl`).

The layer splits KL(N(mu, Sigma) || N(mu_o, Sigma_o)) into a mean part m and a covariance
part C and projects each onto its bound. Chapter 4 checks it against what is written here:
the textbook Gaussian KL in numpy, SLSQP on both primal problems, and the covariance dual

    Sigma~(eta)^{-1} = (eta Sigma_o^{-1} + Sigma^{-1}) / (eta + 1),
    g(eta) = eta eps - eta/2 log|Sigma_o| + (eta + 1)/2 log|Sigma~(eta)|,

whose derivative is eps − C(Sigma~(eta)). None of it calls the layer.
"""

from __future__ import annotations

import numpy as np
import torch
from scipy.optimize import OptimizeResult, minimize, minimize_scalar

F64 = {"dtype": torch.float64}


def random_chol(*batch: int, dim: int, spread: float) -> torch.Tensor:
    """Random lower-triangular factors with positive diagonal, shape ``(*batch, dim, dim)``:
    standard normals times ``spread`` below the diagonal, their exponential on it."""
    a = torch.randn(*batch, dim, dim, **F64) * spread
    return torch.tril(a, -1) + torch.diag_embed(torch.exp(torch.diagonal(a, dim1=-2, dim2=-1)))


def tril_from_free(v: torch.Tensor, dim: int = 2) -> torch.Tensor:
    """The ``dim x dim`` lower-triangular matrix whose free entries, row-major, are ``v``."""
    tri = torch.tril_indices(dim, dim)
    return torch.zeros(dim, dim, dtype=v.dtype).index_put((tri[0], tri[1]), v)


def gauss_kl(mu1: np.ndarray, S1: np.ndarray, mu2: np.ndarray, S2: np.ndarray) -> float:
    """KL(N(mu1, S1) || N(mu2, S2)), the textbook formula in numpy."""
    diff = mu2 - mu1
    return 0.5 * (
        np.trace(np.linalg.solve(S2, S1))
        + diff @ np.linalg.solve(S2, diff)
        - len(mu1)
        + np.linalg.slogdet(S2)[1]
        - np.linalg.slogdet(S1)[1]
    )


def cov_of(x: np.ndarray) -> np.ndarray:
    """A 2x2 covariance from a Cholesky factor with log-diagonal x[0], x[2] and x[1] below."""
    L = np.array([[np.exp(x[0]), 0.0], [x[1], np.exp(x[2])]])
    return L @ L.T


def slsqp_mean_projection(
    mu: np.ndarray, mu_o: np.ndarray, S_o: np.ndarray, eps: float
) -> np.ndarray:
    """argmin over mu~ of (mu~ − mu)ᵀ Sigma_o⁻¹ (mu~ − mu) s.t. m(mu~) <= eps, by SLSQP
    started at mu_o."""
    P_o = np.linalg.inv(S_o)
    return minimize(
        lambda x: (x - mu) @ P_o @ (x - mu),
        mu_o,
        method="SLSQP",
        options={"ftol": 1e-15},
        constraints=[{"type": "ineq", "fun": lambda x: eps - 0.5 * (x - mu_o) @ P_o @ (x - mu_o)}],
    ).x


def slsqp_cov_projection(
    S: np.ndarray, S_o: np.ndarray, eps: float, restarts: int = 5
) -> OptimizeResult:
    """argmin over a 2x2 Sigma~ of KL(N(0, Sigma~) || N(0, Sigma)) s.t. C(Sigma~) <= eps, by SLSQP
    over a Cholesky factor (:func:`cov_of`), started at the feasible Sigma_o and restarted from
    its own answer (at ftol 1e-15 its line search can stop short)."""
    z = np.zeros(2)
    start = np.linalg.cholesky(S_o)  # Σ_o is feasible (C = 0)
    x0 = [np.log(start[0, 0]), start[1, 0], np.log(start[1, 1])]
    for _ in range(restarts):
        result = minimize(
            lambda x: gauss_kl(z, cov_of(x), z, S),
            x0,
            method="SLSQP",
            constraints=[{"type": "ineq", "fun": lambda x: eps - gauss_kl(z, cov_of(x), z, S_o)}],
            options={"ftol": 1e-15, "maxiter": 500},
        )
        x0 = result.x
        if result.success:
            break
    return result


def sigma_tilde(eta: float, S: np.ndarray, S_o: np.ndarray) -> np.ndarray:
    """The stationary point of the covariance Lagrangian, (eta + 1)(eta Sigma_o⁻¹ + Sigma⁻¹)⁻¹."""
    return (eta + 1) * np.linalg.inv(eta * np.linalg.inv(S_o) + np.linalg.inv(S))


def cov_dual(eta: float, S: np.ndarray, S_o: np.ndarray, eps: float) -> float:
    """The dual g(eta) of the covariance projection (to be minimised over eta >= 0)."""
    return (
        eta * eps
        - 0.5 * eta * np.linalg.slogdet(S_o)[1]
        + 0.5 * (eta + 1) * np.linalg.slogdet(sigma_tilde(eta, S, S_o))[1]
    )


def dual_minimiser(S: np.ndarray, S_o: np.ndarray, eps: float) -> float:
    """argmin of g over eta = exp(t), t in [−15, 15] (bounded Brent, xatol 1e-12)."""
    res = minimize_scalar(
        lambda t: cov_dual(np.exp(t), S, S_o, eps),
        bounds=(-15, 15),
        method="bounded",
        options={"xatol": 1e-12},
    )
    return float(np.exp(res.x))


def eta_on_path(S_t: np.ndarray, S: np.ndarray, S_o: np.ndarray) -> tuple[float, float]:
    """Read eta off a covariance assumed on the path,
    Sigma~⁻¹ − Sigma⁻¹ = eta (Sigma_o⁻¹ − Sigma~⁻¹), by least squares; also the relative
    residual (0 when Sigma~ lies on the path)."""
    P_t, P, P_o = np.linalg.inv(S_t), np.linalg.inv(S), np.linalg.inv(S_o)
    a, b = (P_t - P).ravel(), (P_o - P_t).ravel()
    eta = a @ b / (b @ b)
    return float(eta), float(np.linalg.norm(a - eta * b) / np.linalg.norm(a))
