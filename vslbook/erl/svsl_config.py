"""SVSL's hyper-parameters: :class:`SVSLConfig` (Tables A.1, A.4, B.1) and the per-task presets.

:func:`svsl_config` gives the thesis's α, β, β_w, N, K, H for each Chapter 3 task (and
Table B.1's for Chapter 4's table tennis, Fig. 4.3b) and the
sizes the thesis leaves out (KL bounds, buffer sizes, new samples per update, initial
distributions), taken from the authors' set-up (CH3_CH4_FACTS §3.5–3.6) or, where they are
unknown, chosen here and marked as such. A budget changes only counts (N, K, seeds).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

__all__ = ["SVSLConfig", "buffer_size", "svsl_config"]


def buffer_size(dim: int) -> int:
    """Samples per expert buffer: 1.5 × the parameters of a quadratic in ``dim`` variables.

    n = int(1.5 (1 + d + d(d + 1)/2)) (the authors' rule; TT 567, BP 256, planar 136).
    """
    return int(1.5 * (1 + dim + dim * (dim + 1) / 2))


@dataclass(frozen=True)
class SVSLConfig:
    """Hyper-parameters of SVSL (Algorithm 1; Tables A.1 and A.4).

    Table A.1 (our algorithm):

    ==================  =======  ====  ====  ==  ===  ==
    task                α        β     β_w   N   K    H
    ==================  =======  ====  ====  ==  ===  ==
    planar reacher      varies   1.0   1.0   60  350  50
    beer pong           0.001    0.5   2.5   70  750  50
    table tennis        1e-5     0.2   0.2   50  800  50
    ==================  =======  ====  ====  ==  ===  ==

    Table A.4 (5-link reacher, rewards 3.8 / 3.9 / 3.10): α 1e-6 / 0.01 / 1, β 15 / 1 / 25,
    β_w 15 / 2.5 / 25, N 40, K 250 / 250 / 800, H 50.

    Table B.1 (Chapter 4's table tennis, Fig. 4.3b): α 1e-4, β 0.5, N 20, K 1000, H 50,
    200 new episodes per expert update, expert and context KL bounds 0.01 (β_w and the
    rest as Chapter 3's table tennis).

    The KL bounds, buffer sizes, numbers of new samples and initial distributions are not in
    the thesis; they are the authors' (CH3_CH4_FACTS §3.5–3.6) and :func:`svsl_config`
    sets them per task.

    Line 13 of Algorithm 1 (delete the newest expert if it ended in a local optimum) is
    off for beer pong and table tennis, as A.2 says, and so on for the planar and the
    5-link reacher. A.2 leaves the test open ("comparing the entropy, or achieved task
    reward"); ours is the authors': the newest expert goes if the mean return in its buffer
    is below ``local_optimum_factor`` (5) times the mean of the other experts' buffer
    means (:meth:`vslbook.erl.svsl.SVSL.delete_if_local_optimum`).
    """

    alpha: float  #: α, entropy coefficient of the experts (Eq. 3.5)
    beta: float  #: β, entropy coefficient of the context distributions (Eq. 3.6)
    beta_w: float  #: β_w, entropy coefficient of the weights (Eq. A.7)
    n_experts: int  #: N, experts added one by one
    iterations_per_expert: int  #: K
    new_samples_expert: int  #: new episodes per expert update
    new_samples_context: int  #: new episodes per context update
    buffer_size: int  #: samples kept per expert
    context_init_offset_std: tuple[float, ...]  #: a new π(c|o)'s mean: box centre + N(0, diag²)
    context_init_cov: tuple[float, ...]  #: a new π(c|o)'s covariance (diagonal)
    expert_init_cov: tuple[float, ...]  #: a new expert's covariance (diagonal); mean 0
    fine_tune_every: int = 50  #: H
    weight_iterations: int = 100  #: iterations of the π(o) update after the last expert
    kl_context: float = 0.01  #: KL bound of the context update (MORE)
    kl_expert: float = 0.01  #: KL bound of the expert update (contextual MORE)
    kl_weights: float = 0.01  #: KL bound of the weight update (REPS)
    responsibilities: bool = True  #: use log π̃ in the augmented rewards (False: Fig. 3.1d)
    delete_threshold: float = 1e-6  #: experts with π(o) ≤ this are removed at the end
    delete_local_optima: bool = False  #: Algorithm 1, line 13 (on: planar and 5-link reachers)
    local_optimum_factor: float = 5.0  #: line 13 deletes the newest if its return < this × others'
    entropy_gamma: float = 0.99  #: H_min = γ (H_old − H₀) + H₀ for MORE's entropy bound
    entropy_h0: float = -75.0  #: H₀ of that rule
    context_eig_clip: tuple[float, float] = (5e-5**2, 3.0**2)  #: π(c|o) covariance eigenvalues
    value_samples: int = 10_000  #: at most this many samples train V(c) (A.6)
    value_kernel_scale: float = 0.5  #: Nadaraya–Watson kernel scale
    test_every: int = 50  #: iterations between test evaluations
    test_contexts: int = 200  #: fixed contexts from p(c) for the test evaluation

    def __post_init__(self) -> None:
        for name in ("alpha", "beta", "beta_w"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v >= 0):
                raise ValueError(f"{name} must be a finite number >= 0, got {v!r}")
        for name in ("kl_context", "kl_expert", "kl_weights", "value_kernel_scale",
                     "local_optimum_factor"):  # fmt: skip
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
                raise ValueError(f"{name} must be a positive number, got {v!r}")
        for name in (
            "n_experts", "iterations_per_expert", "new_samples_expert", "new_samples_context",
            "buffer_size", "fine_tune_every", "test_every", "test_contexts", "value_samples",
        ):  # fmt: skip
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < 1:
                raise ValueError(f"{name} must be a positive integer, got {v!r}")
        w = self.weight_iterations
        if isinstance(w, bool) or not isinstance(w, (int, np.integer)) or w < 0:
            raise ValueError(f"weight_iterations must be an integer >= 0, got {w!r}")
        if max(self.new_samples_expert, self.new_samples_context) > self.buffer_size:
            raise ValueError(
                f"new samples per update ({self.new_samples_expert}, "
                f"{self.new_samples_context}) cannot exceed buffer_size {self.buffer_size}"
            )

    @property
    def total_iterations(self) -> int:
        """N·K iterations of adding experts plus the weight iterations."""
        return self.n_experts * self.iterations_per_expert + self.weight_iterations


def _popsize(dim: int) -> int:
    """Twice the CMA-ES population rule, 2 (4 + ⌊3 ln d⌋) (the authors' beer-pong choice)."""
    return int(2 * (4 + math.floor(3 * math.log(dim))))


def svsl_config(task: str, *, reward: str | None = None, **overrides: Any) -> SVSLConfig:
    """The thesis's SVSL configuration for a Chapter 3 task (Tables A.1, A.4) or for
    Chapter 4's table tennis, SVSL's curve in Fig. 4.3b (Table B.1).

    Args:
        task: ``"planar-reacher"``, ``"beer-pong"``, ``"table-tennis-ch3"``,
            ``"reacher5-ch3"`` or ``"table-tennis-4d"`` (Table B.1; what the table leaves
            open follows the Chapter 3 table-tennis preset).
        reward: for ``reacher5-ch3``, ``"3.8"``, ``"3.9"`` or ``"3.10"``.
        overrides: any :class:`SVSLConfig` field (e.g. ``alpha`` for the planar reacher,
            whose α "varies" in Table A.1; default 1e-4 as the authors' run script).
    """
    if task == "planar-reacher":
        dc, dt = 2, 10
        n = buffer_size(dc + dt)
        cov = [0.19] * dt
        cov[0] = 5.0
        base = SVSLConfig(
            alpha=1e-4, beta=1.0, beta_w=1.0, n_experts=60, iterations_per_expert=350,
            new_samples_expert=int(0.6 * n), new_samples_context=int(0.6 * buffer_size(dc)),
            buffer_size=n, context_init_offset_std=(1.5, 3.0), context_init_cov=(1.0, 1.0),
            expert_init_cov=tuple(cov), kl_context=0.001, kl_expert=0.01, kl_weights=0.01,
            delete_threshold=1e-6, delete_local_optima=True,
        )  # fmt: skip
    elif task == "beer-pong":
        dc, dt = 2, 15
        # θ = [l, w_1,1, w_1,2, ..., w_7,2]: duration variance 0.25, then per joint 5 × 0.05
        # for the "turning" joints 1, 3, 5, 7 and 5 × 1 for the others (authors' run script).
        per_joint = [0.05, 1.0, 0.05, 1.0, 0.05, 1.0, 0.05]
        cov = [0.25] + [5.0 * v for v in per_joint for _ in range(2)]
        base = SVSLConfig(
            alpha=1e-3, beta=0.5, beta_w=2.5, n_experts=70, iterations_per_expert=750,
            new_samples_expert=_popsize(dc + dt), new_samples_context=_popsize(dc),
            buffer_size=buffer_size(dc + dt), context_init_offset_std=(0.4, 0.8),
            context_init_cov=(0.09, 0.25), expert_init_cov=tuple(cov), kl_context=0.005,
            kl_expert=0.01, kl_weights=0.01, delete_threshold=1e-6,
        )  # fmt: skip
    elif task == "table-tennis-ch3":
        dc, dt = 4, 22
        n = buffer_size(dc + dt)
        # Table A.1, with the authors' K = 1000 (the code drew Fig. 3.2; the thesis says 800,
        # iterations_per_expert=800 gives it); the rest is the
        # authors' set-up: 40 % of the buffer new per update, weights' KL bound 0.5, a new
        # context Gaussian at the box centre ± [0.625, 0.75, 0.58, 0.75] (one std), expert
        # covariance I (θ = [l, w]: the duration starts at 0 ± 1 s, many draws are rejected).
        base = SVSLConfig(
            alpha=1e-5, beta=0.2, beta_w=0.2, n_experts=50, iterations_per_expert=1000,
            new_samples_expert=int(0.4 * n), new_samples_context=int(0.4 * buffer_size(dc)),
            buffer_size=n, context_init_offset_std=(0.625, 0.75, 0.58, 0.75),
            context_init_cov=(0.32, 0.375, 0.29, 0.375), expert_init_cov=(1.0,) * dt,
            kl_context=0.01, kl_expert=0.01, kl_weights=0.5, delete_threshold=1e-5,
        )  # fmt: skip
    elif task == "table-tennis-4d":
        dc, dt = 4, 23
        # Chapter 4's table tennis (Fig. 4.3b), Table B.1: N = 20 experts in total (one to
        # start with, one added at a time), K = 1000 ("add expert every iteration"), H = 50,
        # 200 new episodes per expert update ("traj. samples per expert per iteration"),
        # α = 1e-4, β = 0.5, expert and context KL bounds 0.01. Table B.1 leaves the rest
        # open; it is the Chapter 3 table-tennis preset's (above): β_w = 0.2, weights' KL
        # bound 0.5, the buffer rule (609 for d = 27), 40 % of buffer_size(4) new contexts
        # per context update (8), 100 weight iterations, deletion below 1e-5, expert
        # covariance I (θ = [τ, delay, w]: τ and the delay start at 0 ± 1 and most first
        # draws are rejected, as the Chapter 3 duration) and the new context Gaussians'
        # offsets and covariances, permuted to this task's order (ball first, then goal).
        n = buffer_size(dc + dt)
        base = SVSLConfig(
            alpha=1e-4, beta=0.5, beta_w=0.2, n_experts=20, iterations_per_expert=1000,
            new_samples_expert=200, new_samples_context=int(0.4 * buffer_size(dc)),
            buffer_size=n, context_init_offset_std=(0.58, 0.75, 0.625, 0.75),
            context_init_cov=(0.29, 0.375, 0.32, 0.375), expert_init_cov=(1.0,) * dt,
            kl_context=0.01, kl_expert=0.01, kl_weights=0.5, delete_threshold=1e-5,
        )  # fmt: skip
    elif task == "reacher5-ch3":
        table = {
            "3.8": (1e-6, 15.0, 15.0, 250),
            "3.9": (0.01, 1.0, 2.5, 250),
            "3.10": (1.0, 25.0, 25.0, 800),
        }
        if reward not in table:
            raise ValueError(
                f"reward must be one of {sorted(table)} for reacher5-ch3, got {reward!r}"
            )
        alpha, beta, beta_w, k = table[reward]
        dc, dt = 2, 25
        # Not stated anywhere: sample counts follow the beer-pong rule, initial covariances are
        # the identity, context box centre ± a third of its size.
        base = SVSLConfig(
            alpha=alpha, beta=beta, beta_w=beta_w, n_experts=40, iterations_per_expert=k,
            new_samples_expert=_popsize(dc + dt), new_samples_context=_popsize(dc),
            buffer_size=buffer_size(dc + dt), context_init_offset_std=(0.1, 0.15),
            context_init_cov=(0.01, 0.04), expert_init_cov=(1.0,) * dt,
            delete_local_optima=True,
        )  # fmt: skip
    else:
        raise ValueError(
            f"no SVSL configuration for task {task!r}; expected planar-reacher, beer-pong, "
            "table-tennis-ch3, reacher5-ch3 or table-tennis-4d"
        )
    if reward is not None and task != "reacher5-ch3":
        raise ValueError(f"reward= only applies to reacher5-ch3, got reward={reward!r} for {task}")
    return replace(base, **overrides)
