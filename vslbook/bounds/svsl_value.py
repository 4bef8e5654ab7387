"""Numerical check of SVSL's value baseline V(c) (Appendix A.1.4, Eqs. A.6 and A.7).

Before the weights π(o) are updated (Algorithm 1, line 17), SVSL draws fresh samples from
every expert's curriculum, c ~ π(c|o), θ ~ π(θ|c, o), the same number for each expert, and
records the gating π̂(o|c) of that moment. While π(o) changes, the baseline of Eq. A.7 is
the importance-weighted Nadaraya–Watson regression of the returns on the contexts, with
ratios π(o|c_i)/π̂(o|c_i) (Eq. A.6; :meth:`vslbook.erl.svsl.SVSL.value_baseline`). Read as
an estimator, A.6 targets the expected return in a context,

    V(c) = Σ_o π(o|c) ∫ π(θ|c, o) R(c, θ) dθ.

In the toy of this module V(c) has a closed form: a 1-D context, three linear-Gaussian
experts θ ~ N(K_o c + k_o, σ_o²) with Gaussian π(c|o) and the quadratic reward
R(c, θ) = −(θ − g(c))², so that E[R | c, o] = −(K_o c + k_o − g(c))² − σ_o². The check runs
SVSL's own code (:meth:`~vslbook.erl.svsl.SVSL.start_weight_phase`, then
:meth:`~vslbook.erl.svsl.SVSL.value_baseline`) on a small task with this reward and compares
its estimate with the closed form, computed here from numpy densities.

What the estimator converges to. With n samples per expert and a narrowing kernel, the
numerator of the regression at c becomes proportional to Σ_o n π(c|o) [π(o|c)/π̂(o|c)]
E[R|c, o] and the denominator to the same sum without E[R|c, o]; since
π(c|o)/π̂(o|c) = π̂(c)/π̂(o), the limit is

    V_∞(c) = Σ_o [π(o|c)/π̂(o)] E[R|c, o] / Σ_o π(o|c)/π̂(o)        (:func:`nw_limit`).

It equals V(c) whenever π̂(o) is uniform, for any later π(o) — which is SVSL's case: π(o)
stays uniform until the weight phase starts. If the weight phase started from non-uniform
weights, equal sample counts per expert would make the estimate biased towards the experts
with small π̂(o); weighting expert o's samples by π̂(o) as well (or drawing samples in
proportion to π̂(o)) removes the bias. Written literally, as a sum over o of the
ratio-weighted expected returns without the sampling distribution π̂(o|c) that the ratios
correct, A.6 is Σ_o E[R|c, o] at π = π̂: K expected returns added up instead of averaged
(:func:`literal_value`).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace
from typing import ClassVar

import numpy as np

from vslbook.bounds import Check, CheckReport
from vslbook.bounds.toy_numerics import check_count, check_positive, seeded_rng, worst_check
from vslbook.envs.robot.task import EpisodicTask, Rollouts
from vslbook.erl.reps import nadaraya_watson
from vslbook.erl.svsl import SVSL, SVSLConfig
from vslbook.erl.svsl_model import MixtureModel

__all__ = [
    "Estimator",
    "ValueToy",
    "ValueToyTask",
    "check_value_baseline",
    "expected_returns",
    "gating",
    "goal",
    "kernel_scale",
    "literal_value",
    "nw_limit",
    "svsl_at_weight_phase",
    "svsl_value_at",
    "true_value",
]

#: samples per expert of the convergence study
SAMPLES = (100, 1_000, 10_000, 100_000)
#: the Nadaraya–Watson kernel scale (exp(−d²/scale)) at N_REF samples per expert is SVSL's
#: 0.5; it shrinks as n^(−2/5), the rate that balances the kernel's bias and variance in 1-D
SCALE_REF, N_REF = 0.5, 1_000


def goal(c: np.ndarray) -> np.ndarray:
    """g(c) = c/2 + sin(c)/5: the best θ in context c."""
    return 0.5 * c + 0.2 * np.sin(c)


class ValueToyTask(EpisodicTask):
    """The toy task: R(c, θ) = −(θ − g(c))², a 1-D context on a wide box, 1-D θ."""

    name: ClassVar[str] = "value-baseline-toy"
    context_names: ClassVar[tuple[str, ...]] = ("c",)
    context_low: ClassVar[np.ndarray] = np.array([-50.0])
    context_high: ClassVar[np.ndarray] = np.array([50.0])
    n_params: ClassVar[int] = 1
    has_success: ClassVar[bool] = False

    def evaluate(self, theta, contexts, *, workers=None, out_of_range="error") -> Rollouts:
        """Vectorised: no simulator, every pair is evaluated in this process."""
        th, c = self.check_batch(theta, contexts, out_of_range)
        valid = self.context_valid(c)
        ret = np.where(valid, -((th[:, 0] - goal(c[:, 0])) ** 2), self.context_penalty(c))
        return Rollouts(ret, np.zeros(len(c), bool), valid, {})


class ValueToy:
    """K linear-Gaussian experts (default 3) with Gaussian π(c|o), 1-D c and θ.

    The context means are spread over [−1.5, 1.5], each expert is close to the tangent of
    :func:`goal` at its context mean, and the noise σ_o takes K levels in [0.4, 1.0] in a
    random order, so the experts differ mostly in how noisy they are.

    Attributes:
        mu, s: (K,) mean and standard deviation of π(c|o).
        gain, offset, sigma: (K,) θ ~ N(gain_o c + offset_o, sigma_o²).
    """

    def __init__(self, rng: np.random.Generator, n_experts: int = 3) -> None:
        k = check_count("n_experts", n_experts, 2)
        self.mu = np.linspace(-1.5, 1.5, k) + rng.uniform(-0.1, 0.1, k)
        self.s = 0.7 + rng.uniform(-0.05, 0.05, k)
        # each expert: the tangent of g at its context mean, slightly perturbed; the experts
        # differ mainly in their noise σ_o, so E[R | c, o] is of the same order for every o
        slope = 0.5 + 0.2 * np.cos(self.mu)
        self.gain = slope + rng.uniform(-0.05, 0.05, k)
        self.offset = goal(self.mu) - slope * self.mu + rng.uniform(-0.05, 0.05, k)
        self.sigma = rng.permutation(np.linspace(0.4, 1.0, k)) + rng.uniform(-0.03, 0.03, k)

    @property
    def n_experts(self) -> int:
        return len(self.mu)

    def model(self, weights: np.ndarray) -> MixtureModel:
        """The same mixture as SVSL's :class:`~vslbook.erl.svsl_model.MixtureModel`."""
        return MixtureModel(
            np.log(np.asarray(weights, float)), self.mu[:, None], (self.s**2)[:, None, None],
            self.gain[:, None, None], self.offset[:, None], (self.sigma**2)[:, None, None],
        )  # fmt: skip


def gating(toy: ValueToy, weights: np.ndarray, c: np.ndarray) -> np.ndarray:
    """π(o|c) = π(o) N(c; μ_o, s_o²) / Σ_o' (...), (m, K), from numpy densities."""
    z = (c[:, None] - toy.mu) / toy.s
    joint = np.asarray(weights) * np.exp(-0.5 * z**2) / toy.s
    return joint / joint.sum(axis=1, keepdims=True)


def expected_returns(toy: ValueToy, c: np.ndarray) -> np.ndarray:
    """E[R | c, o] = −(K_o c + k_o − g(c))² − σ_o², (m, K) (closed form)."""
    err = toy.gain * c[:, None] + toy.offset - goal(c)[:, None]
    return -(err**2) - toy.sigma**2


def true_value(toy: ValueToy, weights: np.ndarray, c: np.ndarray) -> np.ndarray:
    """V(c) = Σ_o π(o|c) E[R | c, o] (what A.6 estimates), (m,)."""
    return np.sum(gating(toy, weights, c) * expected_returns(toy, c), axis=1)


def nw_limit(toy: ValueToy, weights: np.ndarray, weights0: np.ndarray, c: np.ndarray) -> np.ndarray:
    """The limit of SVSL's estimate (many samples, narrow kernel), (m,).

    V_∞(c) = Σ_o [π(o|c)/π̂(o)] E[R|c, o] / Σ_o π(o|c)/π̂(o), with π̂(o) = ``weights0`` the
    weights at the start of the weight phase and equal sample counts per expert.
    """
    a = gating(toy, weights, c) / np.asarray(weights0)
    return np.sum(a * expected_returns(toy, c), axis=1) / a.sum(axis=1)


def literal_value(
    toy: ValueToy, weights: np.ndarray, weights0: np.ndarray, c: np.ndarray
) -> np.ndarray:
    """Eq. A.6 read literally: Σ_o [π(o|c)/π̂(o|c)] E[R|c, o], (m,) (Σ_o E[R|c, o] at π = π̂)."""
    ratio = gating(toy, weights, c) / gating(toy, weights0, c)
    return np.sum(ratio * expected_returns(toy, c), axis=1)


def kernel_scale(n: int) -> float:
    """The Nadaraya–Watson kernel scale for ``n`` samples per expert: SVSL's 0.5 at
    :data:`N_REF`, shrinking as n^(−2/5)."""
    return SCALE_REF * (n / N_REF) ** -0.4


def svsl_at_weight_phase(
    toy: ValueToy, weights0: np.ndarray, n: int, scale: float, seed: int
) -> SVSL:
    """An SVSL state holding the toy mixture with weights π̂(o) = ``weights0``, right after
    its weight phase started (``n`` fresh samples per expert, π̂(o|c_i) recorded) and with
    Nadaraya–Watson kernel scale ``scale``."""
    k = toy.n_experts
    cfg = SVSLConfig(
        alpha=0.0, beta=0.0, beta_w=0.0, n_experts=k, iterations_per_expert=1,
        new_samples_expert=1, new_samples_context=1, buffer_size=n,
        context_init_offset_std=(1.0,), context_init_cov=(1.0,), expert_init_cov=(1.0,),
        weight_iterations=1, value_samples=k * n, value_kernel_scale=scale, test_contexts=1,
    )  # fmt: skip
    s = SVSL(ValueToyTask(), cfg, seed)
    s.model = toy.model(weights0)
    s.buffers = replace(
        s.buffers, c=np.zeros((k, n, 1)), theta=np.zeros((k, n, 1)), ret=np.zeros((k, n))
    )
    s.start_weight_phase()
    return s


def svsl_value_at(s: SVSL, query: np.ndarray) -> np.ndarray:
    """SVSL's own V(c) (:meth:`~vslbook.erl.svsl.SVSL.value_baseline`, Eq. A.6) at ``query``.

    ``value_baseline`` predicts at the contexts of the replay buffers; the buffers are
    replaced by the query contexts for the call and restored afterwards.
    """
    q = np.asarray(query, float).reshape(-1, 1)
    saved = s.buffers
    s.buffers = replace(saved, c=q[None], theta=np.zeros((1, len(q), 1)), ret=np.zeros((1, len(q))))
    try:
        return s.value_baseline()[0]
    finally:
        s.buffers = saved


#: a candidate estimator: (SVSL state after the weight phase started, query contexts (m,)) -> (m,)
Estimator = Callable[[SVSL, np.ndarray], np.ndarray]


def check_value_baseline(
    seed: int = 0,
    estimator: Estimator | None = None,
    samples: tuple[int, ...] = SAMPLES,
    tol: float = 0.06,
) -> CheckReport:
    """SVSL's importance-sampled Nadaraya–Watson baseline V(c) against its closed form (A.6).

    On the toy of this module (a new random toy per seed) the estimate of ``estimator``
    (default: SVSL's own, :func:`svsl_value_at`) is compared with the closed-form
    V(c) = Σ_o π(o|c) E[R|c, o] on 41 contexts between the outer context means, for
    ``samples`` samples per expert, with the kernel scale of :func:`kernel_scale`. Cases:

    1. the weight phase starts from uniform π̂(o) = 1/K (SVSL's case: π(o) stays uniform
       while experts are added) and π(o) = π̂(o): the largest error on the grid is below
       ``tol`` at the largest sample count and smaller there than at the count two steps
       below (10³ by default);
    2. π(o) then moves away from π̂(o) (most weight to the noisiest expert), changing V(c) by
       at least 2 ``tol``: the ratios π(o|c)/π̂(o|c) re-weight the samples and the estimate
       follows the new V(c) within ``tol`` (an estimator without the ratios stays near the
       old V and fails);
    3. the weight phase starts from non-uniform π̂(o) (not SVSL's case), π(o) = π̂(o): with
       equal sample counts per expert the estimate converges to :func:`nw_limit` instead of
       V(c); its error exceeds the error of case 1, and weighting expert o's samples by
       π̂(o) as well removes the bias.

    Besides, Eq. A.6 read literally (:func:`literal_value`), which at π = π̂ is Σ_o E[R|c, o],
    is within a factor 2 of K·V(c) (median over the grid of their ratio, which varies with c
    because the experts' returns differ).

    The tolerance comes from the convergence study: over seeds 0–19 the largest error at
    10⁵ samples per expert was about 0.05 (case 2) and 0.03 (case 1), against returns
    between about −1 and −0.2; ``err_uniform`` and ``err_moved`` hold the study of one seed.

    Args:
        seed: the toy and every sample.
        estimator: candidate ``(svsl, query) -> V``; see :data:`Estimator`.
        samples: at least three increasing samples-per-expert counts.
        tol: the largest error allowed at the largest sample count.

    Returns:
        Report with data ``grid``; ``v_uniform`` / ``v_moved`` / ``v_skewed`` (closed-form
        V(c) of the three cases); ``est_uniform`` / ``est_moved`` / ``est_skewed`` (the
        estimates at the largest sample count), ``est_moved_plain`` (case 2 without the
        ratios), ``limit_skewed`` (V_∞ of case 3), ``est_corrected`` (case 3 with the extra
        π̂(o) weights); ``samples``, ``kernel_scale``, ``err_uniform``, ``err_moved`` (largest
        errors per sample count), ``err_skewed``, ``bias_skewed`` (max |V_∞ − V|);
        ``weights_moved``, ``weights_skewed``; ``literal`` (Eq. A.6 literally at π = π̂
        uniform), ``literal_ratio`` (literal / V on the grid); ``tol``.
    """
    estimator = estimator or svsl_value_at
    ns = tuple(check_count("samples", n, 10) for n in samples)
    if len(ns) < 3 or list(ns) != sorted(set(ns)):
        raise ValueError(f"samples must be at least three increasing counts, got {samples!r}")
    tol = check_positive("tol", tol)
    rng = seeded_rng(seed, 11)
    toy = ValueToy(rng)
    k = toy.n_experts
    uniform = np.full(k, 1.0 / k)
    rank = np.argsort(np.argsort(toy.sigma))  # 0: the expert with the least noise
    moved = np.geomspace(1.0, 25.0, k)[rank]  # most weight moves to the noisiest expert
    moved /= moved.sum()
    skewed = np.geomspace(1.0, 1 / 8.0, k)[rank]  # most weight starts on the best expert
    skewed /= skewed.sum()
    grid = np.linspace(toy.mu.min(), toy.mu.max(), 41)
    v_uni, v_mov, v_skew = (true_value(toy, w, grid) for w in (uniform, moved, skewed))

    # cases 1 and 2: the weight phase starts from uniform π̂(o); then π(o) moves
    err_uni, err_mov = [], []
    for n in ns:
        scale = kernel_scale(n)
        s = svsl_at_weight_phase(toy, uniform, n, scale, seed=int(rng.integers(2**31)))
        est_uni = estimator(s, grid)
        s.model.log_w = np.log(moved)
        s.model.changed()
        est_mov = estimator(s, grid)
        err_uni.append(np.max(np.abs(est_uni - v_uni)))
        err_mov.append(np.max(np.abs(est_mov - v_mov)))
    wp = s.weight_phase
    if wp is None:
        raise RuntimeError("the weight phase did not start")
    est_plain = nadaraya_watson(wp["c"], wp["ret"], grid[:, None], scale=scale)  # no ratios
    err_uni_a, err_mov_a = np.array(err_uni), np.array(err_mov)

    # case 3: the weight phase starts from non-uniform π̂(o), π(o) = π̂(o)
    s = svsl_at_weight_phase(toy, skewed, ns[-1], scale, seed=int(rng.integers(2**31)))
    est_skew = estimator(s, grid)
    limit = nw_limit(toy, skewed, skewed, grid)
    bias = float(np.max(np.abs(limit - v_skew)))
    err_skew = float(np.max(np.abs(est_skew - v_skew)))
    wp = s.weight_phase
    if wp is None:
        raise RuntimeError("the weight phase did not start")
    w_corr = skewed[wp["own"]]  # the ratios are 1 at π = π̂; the extra factor π̂(o)
    est_corr = nadaraya_watson(
        wp["c"], wp["ret"], grid[:, None], weights=w_corr / w_corr.sum(), scale=scale
    )

    # Eq. A.6 read literally, at π = π̂ uniform
    literal = literal_value(toy, uniform, uniform, grid)
    ratio = literal / v_uni
    median_ratio = float(np.median(ratio))

    at_n = f"n = {ns[-1]} per expert"

    def study(err: np.ndarray) -> str:
        return ", ".join(f"{e:.3f}" for e in err[:-1])

    rest = ", ".join(str(n) for n in ns[:-1])
    checks = (
        Check(f"π̂(o) uniform, π = π̂: max |V_NW − V| on the grid, {at_n} "
              f"(at n = {rest}: {study(err_uni_a)})", "Eq. A.6", err_uni_a[-1], 0.0, tol),
        Check(f"π̂(o) uniform: the max error shrinks from n = {ns[-3]} to {ns[-1]}", "Eq. A.6",
              err_uni_a[-1], err_uni_a[-3], 0.0, "<="),
        Check("π(o) moved: 2 tol ≤ max |V_new − V_old| (the move matters)", "Eqs. A.6, A.7",
              2 * tol, float(np.max(np.abs(v_mov - v_uni))), 0.0, "<="),
        Check(f"π(o) moved: the ratios π(o|c)/π̂(o|c) track the new V, {at_n} "
              f"(at n = {rest}: {study(err_mov_a)})", "Eqs. A.6, A.7", err_mov_a[-1], 0.0, tol),
        Check(f"π(o) moved: the max error shrinks from n = {ns[-3]} to {ns[-1]}", "Eqs. A.6, A.7",
              err_mov_a[-1], err_mov_a[-3], 0.0, "<="),
        worst_check("π̂(o) non-uniform: the estimate converges to V_∞ = Σ_o π(o|c) E_o / π̂(o) "
                    "/ Σ_o π(o|c) / π̂(o), not to V", "Eq. A.6", est_skew, limit, tol),
        Check(f"π̂(o) non-uniform: its error max |V_NW − V| (bias max |V_∞ − V| = {bias:.3f}) "
              "exceeds the uniform case's", "Eq. A.6", err_uni_a[-1], err_skew, 0.0, "<="),
        worst_check("π̂(o) non-uniform: weighting each sample by π̂(o) as well removes the bias",
                    "Eq. A.6", est_corr, v_skew, tol),
        Check(f"A.6 literally, Σ_o E_o(c) at π = π̂, over V(c): median {median_ratio:.2f} "
              f"(range {ratio.min():.2f}–{ratio.max():.2f}), K = {k}; max(median / K, "
              "K / median) ≤ 2", "Eq. A.6", max(median_ratio / k, k / median_ratio), 2.0, 0.0,
              "<="),
    )  # fmt: skip
    data = {
        "grid": grid,
        "v_uniform": v_uni,
        "v_moved": v_mov,
        "v_skewed": v_skew,
        "est_uniform": est_uni,
        "est_moved": est_mov,
        "est_moved_plain": est_plain,
        "est_skewed": est_skew,
        "limit_skewed": limit,
        "est_corrected": est_corr,
        "samples": np.array(ns),
        "kernel_scale": np.array([kernel_scale(n) for n in ns]),
        "err_uniform": err_uni_a,
        "err_moved": err_mov_a,
        "err_skewed": np.array(err_skew),
        "bias_skewed": np.array(bias),
        "weights_moved": moved,
        "weights_skewed": skewed,
        "literal": literal,
        "literal_ratio": ratio,
        "tol": np.array(tol),
    }
    return CheckReport(
        "SVSL's value baseline V(c) (A.6, A.7) against its closed form", checks, data
    )
