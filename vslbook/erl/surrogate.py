"""Quadratic reward surrogates for MORE and contextual MORE (Section 3.3, Appendix A.2).

MORE (Abdolmaleki et al., 2015) and its contextual variant (Tangkaratt et al., 2017) need a
local quadratic model of the (augmented) reward of Eq. 3.5 / Eq. 3.6,

    R(x) ≈ −½ xᵀA x + xᵀa + a0,

fitted by weighted ridge regression on the samples of one expert. Every function here is
batched over a leading expert axis E and works in numpy float64.

The fit follows the recipe used with SVSL:

1. whiten the inputs, x̂ = L⁻¹(x − m), with a Gaussian (m, L L ᵀ) that matches the samples
   (``whitening_gaussian`` for the per-expert context distributions of Eq. 3.6,
   ``joint_whitening`` for the joint (c, θ) input of the experts of Eq. 3.5);
2. features: all monomials x̂_i x̂_j (i ≤ j), x̂, 1; standardise the feature columns (not the
   bias) and the targets, y → (y − ȳ)/σ_R;
3. weighted ridge (λ = 1e-10, bias unregularised);
4. undo the feature standardisation and the whitening, but keep the target standardisation:
   the returned model is in units of σ_R with ȳ removed, so the entropy temperatures of
   Eq. 3.5 / 3.6 must be divided by σ_R (``Quadratic.scale``) by the caller of the dual.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["Quadratic", "fit_quadratic", "joint_whitening", "whitening_gaussian"]


@dataclass(frozen=True)
class Quadratic:
    """R(x) ≈ −½ xᵀA x + xᵀa + a0, batched over E experts, in units of ``scale`` (σ_R).

    ``offset`` is the removed target mean ȳ (None when unknown); ``predict`` returns the
    model in the original reward units, scale · (−½ xᵀA x + xᵀa + a0) + offset.
    """

    A: np.ndarray  # (E, d, d) symmetric
    a: np.ndarray  # (E, d)
    a0: np.ndarray  # (E,)
    scale: np.ndarray  # (E,) σ_R
    offset: np.ndarray | None = None  # (E,) ȳ

    def __post_init__(self) -> None:
        A = np.asarray(self.A, dtype=np.float64)
        if A.ndim != 3 or A.shape[1] != A.shape[2]:
            raise ValueError(f"Quadratic.A must have shape (E, d, d), got {A.shape}")
        n_exp, d = A.shape[0], A.shape[1]
        shapes = {"a": (n_exp, d), "a0": (n_exp,), "scale": (n_exp,)}
        if self.offset is not None:
            shapes["offset"] = (n_exp,)
        for name, shape in shapes.items():
            value = np.asarray(getattr(self, name), dtype=np.float64)
            if value.shape != shape:
                raise ValueError(f"Quadratic.{name} must have shape {shape}, got {value.shape}")
        scale = np.asarray(self.scale, dtype=np.float64)
        if not np.all(scale > 0):
            raise ValueError(f"Quadratic.scale must be > 0, got {scale}")
        if not np.allclose(A, np.swapaxes(A, 1, 2), rtol=1e-8, atol=1e-10):
            raise ValueError("Quadratic.A must be symmetric")

    @property
    def dim(self) -> int:
        return int(np.shape(self.A)[-1])

    def __call__(self, x: np.ndarray) -> np.ndarray:
        """Model value in units of σ_R (ȳ removed); x (E, n, d) → (E, n)."""
        x = np.asarray(x, dtype=np.float64)
        quad = np.einsum("eni,eij,enj->en", x, self.A, x)
        return -0.5 * quad + np.einsum("eni,ei->en", x, self.a) + self.a0[:, None]

    def predict(self, x: np.ndarray) -> np.ndarray:
        """Model value in the original reward units; x (E, n, d) → (E, n)."""
        offset = np.zeros_like(self.scale) if self.offset is None else self.offset
        return self.scale[:, None] * self(x) + offset[:, None]


def _safe_cholesky(cov: np.ndarray, jitter: float = 1e-6) -> np.ndarray:
    """Batched Cholesky; matrices that are not positive definite get ``jitter``·I added."""
    try:
        return np.linalg.cholesky(cov)
    except np.linalg.LinAlgError:
        pass
    cov = cov.copy()
    eye = np.eye(cov.shape[-1])
    for _ in range(12):
        bad = np.linalg.eigvalsh(cov)[..., 0] <= 1e-12 * np.maximum(
            1.0, np.abs(np.trace(cov, axis1=-2, axis2=-1))
        )
        cov[bad] += jitter * eye
        try:
            return np.linalg.cholesky(cov)
        except np.linalg.LinAlgError:
            jitter *= 10.0
    raise ValueError("covariance could not be made positive definite")


def whitening_gaussian(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Sample mean and lower Cholesky factor of the sample covariance of x (E, n, d).

    Used to whiten the context samples of the per-expert context distributions (Eq. 3.6).
    A covariance that is not positive definite gets 1e-6·I added.
    """
    x = np.asarray(x, dtype=np.float64)
    if x.ndim != 3 or x.shape[1] < 2:
        raise ValueError(f"x must have shape (E, n >= 2, d), got {x.shape}")
    mean = x.mean(axis=1)
    centred = x - mean[:, None, :]
    cov = np.swapaxes(centred, 1, 2) @ centred / (x.shape[1] - 1)
    return mean, _safe_cholesky(cov)


def joint_whitening(
    contexts: np.ndarray, K: np.ndarray, k: np.ndarray, cov: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Whitening Gaussian of the joint input x = [c; θ] of an expert update (Eq. 3.5).

    The contexts' sample moments (c̄, Σ_c = L_c L_cᵀ) and the linear-Gaussian expert
    θ | c ~ N(K c + k, Σ = L_θ L_θᵀ) imply the joint Gaussian with mean [c̄; K c̄ + k] and
    covariance [[Σ_c, Σ_c Kᵀ], [K Σ_c, K Σ_c Kᵀ + Σ]], whose Cholesky factor is the block
    matrix [[L_c, 0], [K L_c, L_θ]].

    contexts (E, n, dc), K (E, dθ, dc), k (E, dθ), cov (E, dθ, dθ) → mean (E, dc + dθ),
    chol (E, dc + dθ, dc + dθ).
    """
    contexts = np.asarray(contexts, dtype=np.float64)
    K, k, cov = (np.asarray(v, dtype=np.float64) for v in (K, k, cov))
    if contexts.ndim != 3:
        raise ValueError(f"contexts must have shape (E, n, dc), got {contexts.shape}")
    n_exp, _, dc = contexts.shape
    if K.ndim != 3 or K.shape[0] != n_exp or K.shape[2] != dc:
        raise ValueError(f"K must have shape (E={n_exp}, dθ, dc={dc}), got {K.shape}")
    dt = K.shape[1]
    if k.shape != (n_exp, dt) or cov.shape != (n_exp, dt, dt):
        raise ValueError(
            f"k and cov must have shapes {(n_exp, dt)} and {(n_exp, dt, dt)}, "
            f"got {k.shape} and {cov.shape}"
        )
    c_mean, c_chol = whitening_gaussian(contexts)
    t_chol = _safe_cholesky(cov)
    mean = np.concatenate([c_mean, np.einsum("eij,ej->ei", K, c_mean) + k], axis=1)
    chol = np.zeros((n_exp, dc + dt, dc + dt))
    chol[:, :dc, :dc] = c_chol
    chol[:, dc:, :dc] = K @ c_chol
    chol[:, dc:, dc:] = t_chol
    return mean, chol


def fit_quadratic(
    x: np.ndarray,
    y: np.ndarray,
    *,
    mean: np.ndarray,
    chol: np.ndarray,
    weights: np.ndarray | None = None,
    ridge: float = 1e-10,
) -> Quadratic:
    """Weighted ridge fit of R(x) ≈ −½ xᵀA x + xᵀa + a0 per expert (MORE surrogate).

    x (E, n, d), y (E, n); mean (E, d) and chol (E, d, d) (lower triangular) define the
    whitening x̂ = chol⁻¹(x − mean); weights (E, n) ≥ 0 (default uniform 1/n). The returned
    model is in the original x coordinates, in units of σ_R (the weighted std of y), with the
    weighted target mean removed and stored in ``offset``.
    """
    x = np.asarray(x, dtype=np.float64)
    y = np.asarray(y, dtype=np.float64)
    if x.ndim != 3:
        raise ValueError(f"x must have shape (E, n, d), got {x.shape}")
    n_exp, n, d = x.shape
    mean = np.asarray(mean, dtype=np.float64)
    chol = np.asarray(chol, dtype=np.float64)
    if y.shape != (n_exp, n):
        raise ValueError(f"y must have shape {(n_exp, n)}, got {y.shape}")
    if mean.shape != (n_exp, d) or chol.shape != (n_exp, d, d):
        raise ValueError(
            f"mean and chol must have shapes {(n_exp, d)} and {(n_exp, d, d)}, "
            f"got {mean.shape} and {chol.shape}"
        )
    diag = np.diagonal(chol, axis1=1, axis2=2)
    if not np.all(diag > 0) or not np.allclose(chol, np.tril(chol)):
        raise ValueError("chol must be lower triangular with a positive diagonal")
    if not (np.all(np.isfinite(x)) and np.all(np.isfinite(y))):
        raise ValueError("x and y must be finite")
    if not ridge >= 0:
        raise ValueError(f"ridge must be >= 0, got {ridge}")
    w = normalised_weights(weights, n_exp, n)

    # 1. whiten: x̂ = L⁻¹ (x − m)
    l_inv = np.linalg.inv(chol)
    xw = (x - mean[:, None, :]) @ np.swapaxes(l_inv, 1, 2)
    # 2. features [x̂_i x̂_j (i ≤ j), x̂], standardised per column; targets standardised
    iu, ju = np.triu_indices(d)
    phi = np.concatenate([xw[..., iu] * xw[..., ju], xw], axis=2)  # (E, n, p - 1)
    f_mean = np.einsum("en,enp->ep", w, phi)
    f_std = np.sqrt(np.einsum("en,enp->ep", w, (phi - f_mean[:, None]) ** 2))
    f_std = np.where(f_std > 1e-12, f_std, 1.0)
    phi = (phi - f_mean[:, None]) / f_std[:, None]
    y_mean = np.einsum("en,en->e", w, y)
    y_std = np.sqrt(np.einsum("en,en->e", w, (y - y_mean[:, None]) ** 2))
    y_std = np.where(y_std > 1e-12, y_std, 1.0)
    ys = (y - y_mean[:, None]) / y_std[:, None]
    # 3. weighted ridge on [φ, 1] with an unregularised bias
    design = np.concatenate([phi, np.ones((n_exp, n, 1))], axis=2)
    p = design.shape[2]
    gram = np.swapaxes(design * w[..., None], 1, 2) @ design
    gram[:, np.arange(p - 1), np.arange(p - 1)] += ridge
    rhs = np.einsum("enp,en->ep", design, w * ys)
    beta = np.linalg.solve(gram, rhs[..., None])[..., 0]
    # 4. undo the feature standardisation (in whitened coordinates) ...
    coef = beta[:, :-1] / f_std
    bias = beta[:, -1] - np.einsum("ep,ep->e", coef, f_mean)
    n_quad = len(iu)
    T = np.zeros((n_exp, d, d))
    T[:, iu, ju] = coef[:, :n_quad]
    A_w = -(T + np.swapaxes(T, 1, 2))  # −½ x̂ᵀÂ x̂ = Σ_{i≤j} T_ij x̂_i x̂_j
    a_w = coef[:, n_quad:]
    # ... and the whitening: x̂ = L⁻¹(x − m)
    A = np.swapaxes(l_inv, 1, 2) @ A_w @ l_inv
    A = 0.5 * (A + np.swapaxes(A, 1, 2))
    lt_a = np.einsum("eji,ej->ei", l_inv, a_w)  # L⁻ᵀ â
    a = np.einsum("eij,ej->ei", A, mean) + lt_a
    a0 = bias - 0.5 * np.einsum("ei,eij,ej->e", mean, A, mean) - np.einsum("ei,ei->e", lt_a, mean)
    return Quadratic(A=A, a=a, a0=a0, scale=y_std, offset=y_mean)


def normalised_weights(weights: np.ndarray | None, n_exp: int, n: int) -> np.ndarray:
    """Sample weights (E, n) normalised per expert; uniform 1/n when ``weights`` is None."""
    if weights is None:
        return np.full((n_exp, n), 1.0 / n)
    w = np.asarray(weights, dtype=np.float64)
    if w.shape != (n_exp, n) or np.any(w < 0) or np.any(w.sum(axis=1) <= 0):
        raise ValueError(
            f"weights must be non-negative with shape {(n_exp, n)} and a positive "
            f"sum per expert, got shape {w.shape}"
        )
    return w / w.sum(axis=1, keepdims=True)
