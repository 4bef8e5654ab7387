"""A one-step diffusion policy on a tabular MDP: Propositions 5.4.1–5.4.3 by enumeration.

The action a = a^0 is drawn through one noise value z = a^1: z ~ pi~_1(z) (the fixed
prior, the role of N(0, sigma0²)), then a ~ pi~_{0|1}(a | z, s) (the kernel, learned). The
noising process pi->_{1|0}(z | a) is fixed. With N = 1 the lower bound of Eq. 5.15 is

    l(s) = sum_{z,a} pi~_1(z) pi~_{0|1}(a|z,s)
           * [log pi->_{1|0}(z|a) − log pi~_1(z) − log pi~_{0|1}(a|z,s)],

and everything of Section 5.4 is a finite sum. Arrays: ``P[s, a, s']``, ``R[s, a]``,
``prior[z]``, ``noising[a, z]``, ``kernel[s, z, a]``, ``q[s, a]``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class OneStepDiffusionMDP:
    """The MDP (``P``, ``R``, ``gamma``), the temperature ``alpha`` and the fixed parts of the
    one-step diffusion policy (``prior``, ``noising``)."""

    P: np.ndarray
    R: np.ndarray
    prior: np.ndarray
    noising: np.ndarray
    gamma: float
    alpha: float

    def marginal(self, kernel: np.ndarray) -> np.ndarray:
        """pi~_0(a | s) = sum_z pi~_1(z) pi~_{0|1}(a | z, s)."""
        return np.einsum("z,sza->sa", self.prior, kernel)

    def bound(self, kernel: np.ndarray) -> np.ndarray:
        """l(s), Eq. 5.15 with N = 1, by enumeration over (z, a)."""
        log_ratio = (
            np.log(self.noising.T)[None] - np.log(self.prior)[None, :, None] - np.log(kernel)
        )
        return np.einsum("z,sza,sza->s", self.prior, kernel, log_ratio)

    def evaluate(self, kernel: np.ndarray) -> np.ndarray:
        """Q of the policy, Eq. 5.17 by one linear solve: Q = R + γ P W with
        W = E_pi~0[Q] + α l, i.e. (I − γ P^pi) W = r^pi + α l."""
        pi = self.marginal(kernel)
        p_pi = np.einsum("sa,sat->st", pi, self.P)
        n_s = self.P.shape[0]
        rhs = (pi * self.R).sum(1) + self.alpha * self.bound(kernel)
        w = np.linalg.solve(np.eye(n_s) - self.gamma * p_pi, rhs)
        return self.R + self.gamma * self.P @ w

    def soft_value(self, kernel: np.ndarray, q: np.ndarray) -> np.ndarray:
        """E_pi~0[Q(s, a)] + α l(s): both sides of Eq. C.20."""
        return (self.marginal(kernel) * q).sum(1) + self.alpha * self.bound(kernel)

    def improve(self, q: np.ndarray) -> np.ndarray:
        """Eq. 5.22 in closed form: pi~(a | z, s) ∝ exp(Q(s, a) / α) pi->(z | a)."""
        logits = q[:, None, :] / self.alpha + np.log(self.noising.T)[None]
        weights = np.exp(logits - logits.max(-1, keepdims=True))
        return weights / weights.sum(-1, keepdims=True)

    def random_kernel(self, rng: np.random.Generator) -> np.ndarray:
        """A kernel pi~_{0|1}(a | z, s) with Dirichlet(1) rows."""
        n_s, n_a = self.R.shape
        return rng.dirichlet(np.ones(n_a), size=(n_s, self.prior.size))
