"""SVSL: Specializing Versatile Skill Libraries (Chapter 3, Algorithm 1).

The policy is the mixture of Eq. 3.1 (:class:`~vslbook.erl.svsl_model.MixtureModel`). The
curriculum-augmented maximum-entropy objective 3.3 is rewritten with Bayes' rule as 3.4 and
split, with variational responsibilities π̃ fixed at the current model, into one lower bound
per part of the mixture (Appendix A.1):

* experts π(θ | c, o), Eq. 3.5: maximise E_{π(c|o)π(θ|c,o)}[R + α log π̃(o | c, θ)]
  + α E[H[π(θ | c, o)]] — contextual MORE (:func:`vslbook.erl.more.cmore_update`);
* context distributions π(c | o), Eq. 3.6: maximise E_{π(c|o)}[L_c(o, c)
  + (β − α) log π̃(o | c)] + β H[π(c | o)] with L_c(o, c) = E_θ[R + α log π̃(o | c, θ)]
  + α H[π(θ | c, o)] (one θ per context) — MORE (:func:`vslbook.erl.more.more_update`);
* weights π(o), Eq. 3.7 / A.7: the same per-expert value minus the Nadaraya–Watson baseline
  V(c) (A.6), plus β H[π(c | o)], with entropy bonus β_w — REPS on a categorical
  (:func:`vslbook.erl.reps.reps_categorical_update`).

The responsibilities are recomputed from the current model every time a target is built,
which is the "tightening" of the bounds. ``responsibilities=False`` sets log π̃(o | c, θ) and
log π̃(o | c) to zero (the ablation of Fig. 3.1d/f).

Algorithm 1 (Appendix A.2) is :func:`train`: N experts are added one by one; each new
expert (and its context distribution) is trained for K iterations while the others stay
fixed, except every H-th iteration, when all of them are updated; π(o) stays uniform
meanwhile. Then π(o) is updated (``weight_iterations`` iterations, the authors' 100) and
experts with π(o) below ``delete_threshold`` are removed. :func:`train` runs in memory and
is resumable from an :class:`SVSL` state; in a run directory (checkpointed, resumed, reused
when finished) SVSL is trained by ``vslbook run svsl`` / :func:`vslbook.training.run`
(:mod:`vslbook.experiments.ch3_algorithms`).

Each expert keeps a small replay buffer of its last ``buffer_size`` (c, θ, R) samples
(A.2: "newly taken samples replace the oldest"); an expert's buffer is filled with fresh
samples when it is added, and every update of it draws ``new_samples_expert`` (expert
update) or ``new_samples_context`` (context update) new episodes from its own curriculum.
Contexts outside the task's range get the task's punishment
(:meth:`~vslbook.envs.robot.task.EpisodicTask.context_penalty`, A.3).

Differences from the authors' code, and why (CH3_CH4_FACTS §3.5): the thesis's Algorithm 1
trains N experts in total (the code starts with one and adds N more); within an iteration
the thesis box updates the experts first and then the context distributions (the code the
other way round; A.2 says the order is free); line 13, the deletion of an expert that
ended in a local optimum (:meth:`SVSL.delete_if_local_optimum`), also checks the last
expert (the code checks an expert only before adding the next one). As A.2 says, line 13
is off for beer pong and table tennis; the presets switch it on for the two reachers.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np

from vslbook.envs.robot.task import EpisodicTask
from vslbook.erl import more
from vslbook.erl.reps import nadaraya_watson, reps_categorical_update
from vslbook.erl.svsl_config import SVSLConfig, buffer_size, svsl_config
from vslbook.erl.svsl_model import MixtureModel

__all__ = ["SVSL", "SVSLConfig", "buffer_size", "svsl_config", "train"]


@dataclass
class _Buffers:
    """Per-expert replay buffers: contexts (E, n, dc), parameters (E, n, dθ), returns (E, n)."""

    c: np.ndarray
    theta: np.ndarray
    ret: np.ndarray


@dataclass
class SVSL:
    """The state of one SVSL run: model, buffers, random stream and progress counters."""

    task: EpisodicTask
    config: SVSLConfig
    seed: int
    model: MixtureModel = field(init=False)
    buffers: _Buffers = field(init=False)
    rng: np.random.Generator = field(init=False)
    iteration: int = 0  #: completed iterations (of config.total_iterations)
    samples: int = 0  #: executed episodes so far (rejected θ are not counted, A.3.2)
    episodes: int = 0  #: all evaluated (c, θ) pairs, rejected ones included
    test_contexts: np.ndarray = field(init=False)
    weight_phase: dict[str, np.ndarray] | None = None

    def __post_init__(self) -> None:
        if self.task.n_params <= 0 or self.task.context_dim <= 0:
            raise ValueError(f"task {self.task.name!r} has no parameters or contexts")
        dc, dt = self.task.context_dim, self.task.n_params
        for name, length in (
            ("context_init_offset_std", dc), ("context_init_cov", dc), ("expert_init_cov", dt),
        ):  # fmt: skip
            got = len(getattr(self.config, name))
            if got != length:
                raise ValueError(
                    f"config.{name} has {got} entries but task {self.task.name!r} needs {length}"
                )
        self.rng = np.random.default_rng(self.seed)
        # fixed test contexts from p(c), from their own stream so that the schedule of
        # tests does not change the training stream
        self.test_contexts = self.task.sample_contexts(
            self.config.test_contexts, np.random.default_rng([self.seed, 1])
        )
        self.model = MixtureModel.empty(dc, dt)
        n = self.config.buffer_size
        self.buffers = _Buffers(np.zeros((0, n, dc)), np.zeros((0, n, dt)), np.zeros((0, n)))

    # -- sampling -----------------------------------------------------------------------
    def _run_episodes(self, c: np.ndarray, theta: np.ndarray) -> np.ndarray:
        out = self.task.evaluate(theta, c, workers=None, out_of_range="penalise")
        self.samples += int(out.n_executed)
        self.episodes += len(c)
        return np.asarray(out.returns, dtype=np.float64)

    def _refresh(self, experts: np.ndarray, n_new: int) -> None:
        """Draw ``n_new`` episodes from each expert's curriculum into its buffer (oldest out)."""
        pairs = [self.model.sample_curriculum(int(o), n_new, self.rng) for o in experts]
        c = np.concatenate([p[0] for p in pairs])
        th = np.concatenate([p[1] for p in pairs])
        ret = self._run_episodes(c, th).reshape(len(experts), n_new)
        b = self.buffers
        for j, o in enumerate(experts):
            b.c[o] = np.concatenate([b.c[o][n_new:], c[j * n_new : (j + 1) * n_new]])
            b.theta[o] = np.concatenate([b.theta[o][n_new:], th[j * n_new : (j + 1) * n_new]])
            b.ret[o] = np.concatenate([b.ret[o][n_new:], ret[j]])

    def delete_if_local_optimum(self) -> bool:
        """Algorithm 1, lines 13–14: delete the newest expert if it ended in a local optimum.

        A.2 leaves the test open ("comparing the entropy, or achieved task reward"); this is
        the authors' (CH3_CH4_FACTS §3.5): with m_o the mean return in expert o's buffer,
        the newest expert k goes if m_k < f · mean_{o<k} m_o, f = ``local_optimum_factor``
        (5). The rule is written for returns that are costs: when the others' mean is not
        negative nothing is deleted. With a single expert there is nothing to compare with.
        Returns whether the newest expert was deleted.
        """
        e = self.model.n_experts
        if e < 2:
            return False
        means = self.buffers.ret.mean(axis=1)
        others = float(np.mean(means[:-1]))
        if not (others < 0 and means[-1] < self.config.local_optimum_factor * others):
            return False
        keep = np.arange(e) < e - 1
        self.model.keep(keep)
        b = self.buffers
        b.c, b.theta, b.ret = b.c[keep], b.theta[keep], b.ret[keep]
        return True

    def add_expert(self) -> None:
        """Algorithm 1, lines 2–3: a new expert with its context Gaussian; π(o) = 1/k."""
        cfg, task = self.config, self.task
        centre = 0.5 * (task.context_low + task.context_high)
        mean = centre + self.rng.normal(0.0, cfg.context_init_offset_std)
        dc, dt = task.context_dim, task.n_params
        self.model.add_expert(
            mean, np.diag(cfg.context_init_cov), np.zeros((dt, dc)), np.zeros(dt),
            np.diag(cfg.expert_init_cov),
        )  # fmt: skip
        n = cfg.buffer_size
        b = self.buffers
        b.c = np.concatenate([b.c, np.zeros((1, n, dc))])
        b.theta = np.concatenate([b.theta, np.zeros((1, n, dt))])
        b.ret = np.concatenate([b.ret, np.zeros((1, n))])
        self._refresh(np.array([self.model.n_experts - 1]), n)

    # -- targets (Eqs. 3.5, 3.6) ---------------------------------------------------------
    def _log_resp(self, experts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """log π̃(o | c, θ) and log π̃(o | c) of each buffer sample for its own expert, (E', n)."""
        b = self.buffers
        e, n = len(experts), self.config.buffer_size
        c = b.c[experts].reshape(e * n, -1)
        th = b.theta[experts].reshape(e * n, -1)
        log_resp, log_gate = self.model.log_responsibilities(c, th)
        own = np.repeat(experts, n)
        rows = np.arange(e * n)
        return log_resp[rows, own].reshape(e, n), log_gate[rows, own].reshape(e, n)

    def _coefs(self) -> tuple[float, float]:
        """(α, β) inside the augmented rewards: 0 without the responsibilities (Fig. 3.1d)."""
        cfg = self.config
        return (cfg.alpha, cfg.beta) if cfg.responsibilities else (0.0, 0.0)

    def expert_targets(self, experts: np.ndarray) -> np.ndarray:
        """R + α log π̃(o | c, θ) for each buffer sample (Eq. 3.5), (E', n)."""
        a_r, _ = self._coefs()
        log_resp, _ = self._log_resp(experts)
        return self.buffers.ret[experts] + a_r * log_resp

    def context_targets(self, experts: np.ndarray) -> np.ndarray:
        """L_c(o, c) + (β − α) log π̃(o | c) for each buffer sample (Eq. 3.6), (E', n).

        L_c(o, c) is estimated with the one θ drawn for c (Section 3.3.3).
        """
        a_r, b_r = self._coefs()
        log_resp, log_gate = self._log_resp(experts)
        h = self.model.expert_entropy()[experts][:, None]
        return (
            self.buffers.ret[experts]
            + a_r * log_resp
            + self.config.alpha * h
            + (b_r - a_r) * log_gate
        )

    # -- updates ------------------------------------------------------------------------
    def update_experts(self, experts: np.ndarray) -> dict[str, float]:
        """Contextual MORE on Eq. 3.5 for the given experts, all duals solved together."""
        cfg, m, b = self.config, self.model, self.buffers
        self._refresh(experts, cfg.new_samples_expert)
        y = self.expert_targets(experts)
        c = b.c[experts]
        x = np.concatenate([c, b.theta[experts]], axis=2)
        mean, chol = more.joint_whitening(c, m.gain[experts], m.offset[experts], m.cov[experts])
        quad = more.fit_quadratic(x, y, mean=mean, chol=chol)
        h_min = more.entropy_loss_bound(
            m.expert_entropy()[experts], cfg.entropy_gamma, cfg.entropy_h0
        )
        res = more.cmore_update(
            m.gain[experts], m.offset[experts], m.cov[experts], c, quad,
            eps=cfg.kl_expert, entropy_coef=cfg.alpha, h_min=h_min,
        )  # fmt: skip
        ok = res.success
        m.gain[experts[ok]] = res.K[ok]
        m.offset[experts[ok]] = res.k[ok]
        m.cov[experts[ok]] = res.cov[ok]
        m.changed()
        return {"expert_kl": float(np.mean(res.kl)), "expert_fail": int((~ok).sum())}

    def update_contexts(self, experts: np.ndarray) -> dict[str, float]:
        """MORE on Eq. 3.6 for the given experts' context distributions, batched."""
        cfg, m, b = self.config, self.model, self.buffers
        self._refresh(experts, cfg.new_samples_context)
        y = self.context_targets(experts)
        c = b.c[experts]
        mean, chol = more.whitening_gaussian(c)
        quad = more.fit_quadratic(c, y, mean=mean, chol=chol)
        h_min = more.entropy_loss_bound(
            m.context_entropy()[experts], cfg.entropy_gamma, cfg.entropy_h0
        )
        res = more.more_update(
            m.ctx_mean[experts], m.ctx_cov[experts], quad, eps=cfg.kl_context,
            entropy_coef=cfg.beta, h_min=h_min, eig_clip=cfg.context_eig_clip,
        )  # fmt: skip
        ok = res.success
        m.ctx_mean[experts[ok]] = res.mean[ok]
        m.ctx_cov[experts[ok]] = res.cov[ok]
        m.changed()
        return {"context_kl": float(np.mean(res.kl)), "context_fail": int((~ok).sum())}

    def start_weight_phase(self) -> None:
        """Before line 17: fresh buffers for every expert, then freeze what V(c) is trained on."""
        cfg, m = self.config, self.model
        experts = np.arange(m.n_experts)
        self._refresh(experts, cfg.buffer_size)
        b = self.buffers
        per = max(1, min(cfg.buffer_size, cfg.value_samples // m.n_experts))
        idx = np.stack([self.rng.choice(cfg.buffer_size, per, replace=False) for _ in experts])
        c = np.take_along_axis(b.c, idx[..., None], axis=1)
        th = np.take_along_axis(b.theta, idx[..., None], axis=1)
        ret = np.take_along_axis(b.ret, idx, axis=1)
        own = np.repeat(experts, per)
        flat_c = c.reshape(-1, m.context_dim)
        gate0 = m.log_gating(flat_c)[np.arange(len(own)), own]
        self.weight_phase = {
            "c": flat_c, "theta": th.reshape(-1, m.param_dim), "ret": ret.reshape(-1),
            "own": own, "log_gate0": gate0,
        }  # fmt: skip

    def value_baseline(self) -> np.ndarray:
        """V(c) of Eq. A.6 at every buffer context, (E, n) (Nadaraya–Watson, A.7)."""
        wp, m = self.weight_phase, self.model
        assert wp is not None
        log_gate = m.log_gating(wp["c"])[np.arange(len(wp["own"])), wp["own"]]
        w = np.exp(log_gate - wp["log_gate0"])  # π(o | c_i) / π̂(o | c_i)
        b = self.buffers
        v = nadaraya_watson(
            wp["c"], wp["ret"], b.c.reshape(-1, m.context_dim), weights=w / w.sum(),
            scale=self.config.value_kernel_scale,
        )  # fmt: skip
        return v.reshape(b.ret.shape)

    def update_weights(self) -> dict[str, float]:
        """REPS on Eq. A.7 for π(o) (Algorithm 1, line 17)."""
        cfg, m = self.config, self.model
        experts = np.arange(m.n_experts)
        y = self.context_targets(experts) - self.value_baseline()
        r = y.mean(axis=1) + cfg.beta * m.context_entropy()
        h_old = float(-np.sum(np.exp(m.log_w) * m.log_w))
        res = reps_categorical_update(
            m.log_w, r, eps=cfg.kl_weights, entropy_coef=cfg.beta_w,
            h_min=cfg.entropy_gamma * h_old,
        )  # fmt: skip
        m.log_w = res.log_p
        m.changed()
        return {
            "weights_kl": res.kl,
            "weights_entropy": res.entropy,
            "weights_fail": int(not res.success),
        }

    # -- evaluation ---------------------------------------------------------------------
    def test(self) -> dict[str, float]:
        """Mean return (and success rate) of θ ~ π(θ | c) on the fixed test contexts.

        While experts are still being added, the newest one is left out (it is not trained
        yet and would not be chosen if π(o) were not uniform: Fig. 3.2's footnote).
        """
        m = self.model
        adding = self.iteration < self.config.n_experts * self.config.iterations_per_expert
        exclude = np.array([m.n_experts - 1]) if adding and m.n_experts > 1 else None
        rng = np.random.default_rng([self.seed, 2, self.iteration])
        th, _ = m.sample(self.test_contexts, rng, exclude=exclude)
        out = self.task.evaluate(th, self.test_contexts, workers=None)
        return {
            "test_return": float(np.mean(out.returns)),
            "test_success": float(np.mean(out.success)),
        }

    # -- state ------------------------------------------------------------------------------
    def state_dict(self) -> dict[str, Any]:
        return {
            "model": self.model.arrays(),
            "buffers": asdict(self.buffers),
            "rng": self.rng.bit_generator.state,
            "iteration": self.iteration,
            "samples": self.samples,
            "episodes": self.episodes,
            "weight_phase": self.weight_phase,
        }

    def load_state_dict(self, state: dict[str, Any]) -> None:
        self.model = MixtureModel.from_arrays(state["model"])
        self.buffers = _Buffers(**{k: np.array(v) for k, v in state["buffers"].items()})
        self.rng.bit_generator.state = state["rng"]
        self.iteration = int(state["iteration"])
        self.samples = int(state["samples"])
        self.episodes = int(state["episodes"])
        self.weight_phase = state["weight_phase"]


Callback = Callable[[int, dict[str, float]], None]


def train(
    task: EpisodicTask,
    config: SVSLConfig,
    seed: int,
    *,
    state: SVSL | None = None,
    until: int | None = None,
    callback: Callback | None = None,
    checkpoint: Callable[[SVSL], None] | None = None,
    checkpoint_every: int = 50,
    checkpoint_due: Callable[[], bool] | None = None,
) -> SVSL:
    """Algorithm 1 (Appendix A.2), resumable: continue ``state`` if given.

    Args:
        task: a Chapter 3 :class:`~vslbook.envs.robot.task.EpisodicTask`.
        config: :class:`SVSLConfig` (see :func:`svsl_config`).
        seed: the run's seed (model initialisation, every sample).
        state: an :class:`SVSL` to continue (e.g. restored from a checkpoint).
        until: stop after this many iterations in total (default: all of them).
        callback: ``callback(iteration, metrics)`` after every iteration.
        checkpoint: ``checkpoint(svsl)`` every ``checkpoint_every`` iterations and at the end.
        checkpoint_due: also checkpoint when it returns True (a run directory's
            :meth:`~vslbook.results.RunDir.checkpoint_due`: a time limit on lost work).
    """
    s = state if state is not None else SVSL(task, config, seed)
    cfg = s.config
    n_add = cfg.n_experts * cfg.iterations_per_expert
    stop = cfg.total_iterations if until is None else min(until, cfg.total_iterations)
    while s.iteration < stop:
        t0 = time.perf_counter()
        t = s.iteration
        metrics: dict[str, float] = {}
        if t < n_add:
            k, i = divmod(t, cfg.iterations_per_expert)  # expert k (0-based), iteration i + 1
            if i == 0:
                s.add_expert()  # lines 2-3
            newest = np.array([s.model.n_experts - 1])
            everyone = np.arange(s.model.n_experts)
            experts = everyone if (i + 1) % cfg.fine_tune_every == 0 else newest  # line 5
            metrics |= s.update_experts(experts)  # line 6 / 9: Eq. 3.5
            metrics |= s.update_contexts(experts)  # line 7 / 10: Eq. 3.6
            if i == cfg.iterations_per_expert - 1 and cfg.delete_local_optima:  # lines 13-14
                metrics["deleted_local_optimum"] = float(s.delete_if_local_optimum())
        else:
            if s.weight_phase is None:
                s.start_weight_phase()
            metrics |= s.update_weights()  # line 17: Eq. A.7
            if t == cfg.total_iterations - 1:  # line 18
                s.model.keep(np.exp(s.model.log_w) > cfg.delete_threshold)
        s.iteration += 1
        metrics["experts"] = s.model.n_experts
        metrics["samples"] = s.samples
        metrics["iteration_seconds"] = time.perf_counter() - t0
        if s.iteration % cfg.test_every == 0 or s.iteration == cfg.total_iterations:
            metrics |= s.test()
        if callback is not None:
            callback(s.iteration, metrics)
        due = s.iteration % checkpoint_every == 0 or s.iteration == stop
        if checkpoint is not None and (due or (checkpoint_due is not None and checkpoint_due())):
            checkpoint(s)
    return s

