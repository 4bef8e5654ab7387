"""Di-SkilL: diverse skills by a curriculum mixture of deep experts (Chapter 4, Algorithms 2 and 3).

The policy is the mixture of Eq. 4.2 with a uniform, fixed prior π(o) = 1/K:

* experts π(θ | c, o) = N(μ_o(c), L_o L_oᵀ): a tanh network per expert for the mean and a
  context-independent Cholesky factor (Appendix B.3.1;
  :class:`~vslbook.erl.diskill_nets.GaussianExperts`);
* per-expert context distributions π(c | o) ∝ exp φ_o(c) (Eq. 4.6), energy networks
  (:class:`~vslbook.erl.diskill_nets.EnergyNets`);
* the gating π(o | c) = π(c | o) π(o) / π(c) by Bayes' rule (Algorithm 3).

The curriculum objective 4.3 is split into the per-expert lower bounds 4.4 (experts) and
4.5 (context distributions) with the responsibilities π̃ of the model before the update
(Appendix B.1). Each iteration of :func:`train` is Algorithm 2:

1. draw ``env_contexts`` contexts c ~ p(c) (the task's sampler: "resetting the environment");
2. every expert o draws its ``samples_per_expert`` training contexts from the categorical
   π(c_i | o) = softmax_i φ_o(c_i) over that batch (with replacement), and one θ per
   context from π(θ | c, o);
3. all K·n episodes are run;
4. the experts are updated on Eq. 4.7 with the trust-region projection layer
   (:mod:`vslbook.erl.trpl`): ``epochs`` full-batch Adam steps on
   −E[r A] − α H[π̃] + α_TR m(π ‖ sg(π̃)), r = π̃(θ | c) / π_old(θ | c),
   A = standardise(R − V_o(c) + α log π̃(o | c, θ)), π̃ the projection of the network's
   output onto the trust region around the sampling policy; afterwards the expert's
   covariance is set to its projected value;
5. the critics V_o(c) regress the returns (``critic_epochs`` full-batch steps);
6. the energy networks are updated on Eq. 4.8 by PPO: the sampled contexts carry
   L_c(o, c) ≈ R − b_o + α log π̃(o | c, θ) + α H[π(θ | c, o)] (b_o: the expert's mean
   return over its last ``reward_baseline_batches`` batches), and the closed-form terms
   β H[π(·|o)] + (β − α) Σ_i π(c_i | o) log π̃(o | c_i) are summed over all drawn contexts.

All K experts, critics and energy networks are updated together
(:mod:`vslbook.erl.diskill_updates`): every parameter has a leading expert axis and one
loss, the sum of the experts' losses, is differentiated; Adam is elementwise and the
gradient-norm clip of the energy update is applied per expert, so this is K independent
updates done in one pass. The networks are float32 unless ``config.dtype`` says float64
(:mod:`vslbook.erl.diskill_config`); they start from the same seeded float64 initialisation
either way, and the environment sees θ and the contexts in float64.

The normaliser of π(c | o). The thesis approximates Z_o = ∫ exp φ_o(c) dc by a sum over
contexts drawn from p(c). The authors' code normalises over whatever batch is at hand (the
n samples, the 75 test contexts), which makes the gating depend on the batch
(CH3_CH4_FACTS §2.5). Here Z_o is always a sum over a large batch from p(c): the
iteration's ``env_contexts`` during training (the categorical the contexts were drawn
from, also in the PPO ratio), and a fixed batch of ``normaliser_contexts`` per seed at
evaluation. :func:`vslbook.bounds.diskill.check_gating` shows what batch normalisation
costs.

Evaluation (Algorithm 3) every ``test_every`` iterations: on fixed contexts from p(c),
o ~ π(o | c), and the expert's mean θ is executed. Samples are counted as executed
episodes (an invalid θ is given the task's penalty without simulation and not counted).

BBRL (``curriculum=False``): one expert, contexts straight from p(c), no responsibilities;
LinDi-SkilL: ``expert_hidden=()``. See :mod:`vslbook.erl.diskill_config`.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

import numpy as np
import torch

from vslbook.envs.robot.task import EpisodicTask
from vslbook.erl import diskill_updates as updates
from vslbook.erl.diskill_config import DiSkillConfig, diskill_config
from vslbook.erl.diskill_nets import (
    EnergyNets,
    GaussianExperts,
    ValueCritics,
    log_gating,
    log_responsibilities,
)
from vslbook.erl.diskill_updates import energy_pass, standardise
from vslbook.results import DivergenceError

__all__ = ["DiSkill", "DiSkillConfig", "diskill_config", "train"]

Callback = Callable[[int, dict[str, float]], None]


def _adam(module: torch.nn.Module, lr: float) -> torch.optim.Adam:
    return torch.optim.Adam(module.parameters(), lr=lr, eps=1e-8, fused=True)


class DiSkill:
    """A Di-SkilL model with its optimisers and random streams; one instance per seed.

    Args:
        task: a Chapter 4 :class:`~vslbook.envs.robot.task.EpisodicTask`.
        config: :class:`DiSkillConfig` (see :func:`diskill_config`).
        seed: the seed of the initialisation and of every sample.
        workers: processes for the episodes (None: ``VSLBOOK_WORKERS`` or the cores).
    """

    def __init__(
        self, task: EpisodicTask, config: DiSkillConfig, seed: int, workers: int | None = None
    ) -> None:
        self.task, self.config, self.seed, self.workers = task, config, int(seed), workers
        self.dtype = getattr(torch, config.dtype)
        with torch.random.fork_rng(devices=[]):
            torch.manual_seed(self.seed)
            nets = self._networks(torch.float64)  # the seeded initialisation, in float64
        if self.dtype != torch.float64:  # the same start, rounded to the networks' dtype
            with torch.random.fork_rng(devices=[]):
                cast = self._networks(self.dtype)
            for net, start in zip(cast, nets, strict=True):
                if net is not None:
                    net.load_state_dict(start.state_dict())
            nets = cast
        self.experts, self.critics, self.energies = nets
        # Adam's fused CPU kernel: one call per parameter instead of a dozen
        self.opt_expert = _adam(self.experts, config.lr_policy)
        self.opt_critic = _adam(self.critics, config.lr_critic)
        self.opt_context = _adam(self.energies, config.lr_context) if self.energies else None
        self.rng = np.random.default_rng([self.seed, 0])  # contexts from p(c)
        self.gen = torch.Generator().manual_seed(self.seed)  # context indices and θ
        self.test_contexts = task.sample_contexts(
            config.test_contexts, np.random.default_rng([self.seed, 1])
        )
        self.normaliser_contexts = task.sample_contexts(
            config.normaliser_contexts, np.random.default_rng([self.seed, 2])
        )
        self.reward_history = np.zeros((config.n_experts, 0))  # the EBM advantage's baseline
        self.iteration = 0
        self.samples = 0  # executed episodes
        self.episodes = 0  # all episodes, rejected θ included

    def _networks(
        self, dtype: torch.dtype
    ) -> tuple[GaussianExperts, ValueCritics, EnergyNets | None]:
        cfg, task = self.config, self.task
        k, dc, d = cfg.n_experts, task.context_dim, task.n_params
        experts = GaussianExperts(k, dc, d, cfg.expert_hidden, init_std=cfg.init_std, dtype=dtype)
        critics = ValueCritics(k, dc, cfg.critic_hidden, dtype=dtype)
        energies = EnergyNets(k, dc, cfg.context_hidden, dtype=dtype) if cfg.curriculum else None
        return experts, critics, energies

    def _tensor(self, x: Any) -> torch.Tensor:
        """Contexts or returns as a tensor of the networks' dtype."""
        return torch.as_tensor(x, dtype=self.dtype)

    def _energies(self, contexts: torch.Tensor) -> torch.Tensor:
        """φ_o(c_i) (K, N) of contexts (N, dc) shared by all experts (Eq. 4.6)."""
        assert self.energies is not None
        return energy_pass(self.energies, contexts, backward=False)[0]

    # -- Algorithm 2, lines 2-6 -----------------------------------------------------------
    def draw_contexts(self) -> tuple[torch.Tensor, torch.Tensor | None, torch.Tensor | None]:
        """Lines 2 and 4: training contexts (K, n, dc), and the batch and indices they came from."""
        cfg = self.config
        n = cfg.samples_per_expert
        if self.energies is None:  # BBRL: contexts from p(c)
            c = self._tensor(self.task.sample_contexts(n, self.rng))
            return c[None], None, None
        c_env = self._tensor(self.task.sample_contexts(cfg.env_contexts, self.rng))  # line 2
        probs = torch.softmax(self._energies(c_env), dim=-1)  # π(c_i|o), Eq. 4.6
        idx = torch.multinomial(probs, n, replacement=True, generator=self.gen)  # line 4
        return c_env[idx], c_env, idx

    def collect(self) -> dict[str, Any]:
        """Lines 2-6: contexts, θ ~ π(θ | c, o), episodes, and what the updates need."""
        cfg, task = self.config, self.task
        k, n = cfg.n_experts, cfg.samples_per_expert
        ctx, c_env, idx = self.draw_contexts()
        with torch.no_grad():
            theta, mean_old = self.experts.sample(ctx, self.gen)  # line 5
            chol_old = self.experts.chol().clone()
        roll = task.evaluate(  # line 6
            theta.reshape(k * n, -1).double().numpy(),
            ctx.reshape(k * n, -1).double().numpy(),
            workers=self.workers,
        )
        batch = {
            "ctx": ctx, "theta": theta, "mean_old": mean_old, "chol_old": chol_old,
            "returns": self._tensor(roll.returns).reshape(k, n), "c_env": c_env, "idx": idx,
            "episode_returns": roll.returns.reshape(k, n),
            "success": roll.success.reshape(k, n), "executed": roll.executed.reshape(k, n),
        }  # fmt: skip
        batch |= self._responsibilities(batch)
        self.samples += roll.n_executed
        self.episodes += k * n
        return batch

    def _responsibilities(self, b: dict[str, Any]) -> dict[str, torch.Tensor]:
        """log π̃(o | c, θ) of the samples, log π̃(o | c_i) on the drawn contexts (Appendix B.1)."""
        cfg = self.config
        k, n = cfg.n_experts, cfg.samples_per_expert
        zeros = torch.zeros(k, n, dtype=self.dtype)
        if self.energies is None or k == 1:
            return {"log_resp": zeros, "log_gate_env": None}
        with torch.no_grad():
            phi_env = self._energies(b["c_env"])  # (K, N)
            log_z = torch.logsumexp(phi_env, dim=-1)  # (K,)
            log_pc = self._energies(b["ctx"].reshape(k * n, -1)) - log_z[:, None]
            log_resp = log_responsibilities(
                b["theta"], b["ctx"], self.experts, log_pc.reshape(k, k, n)
            )
            log_gate_env = None
            if cfg.context_responsibilities:
                log_gate_env = log_gating(phi_env - log_z[:, None])  # (K, N)
        return {"log_resp": log_resp, "log_gate_env": log_gate_env}

    # -- line 7: experts, Eq. 4.7, and critics -----------------------------------------------
    def update_experts(self, b: dict[str, Any]) -> dict[str, float]:
        """Trust-region policy gradient on Eq. 4.7, all experts at once
        (:func:`vslbook.erl.diskill_updates.update_experts`)."""
        cfg = self.config
        with torch.no_grad():  # A = standardise(R − V_o(c) + α log π̃(o | c, θ))
            values = self.critics.values(b["ctx"])
            adv = standardise(b["returns"] - values + cfg.alpha * b["log_resp"])
        metrics = updates.update_experts(self.experts, self.opt_expert, b, adv, cfg)
        self._check_finite("expert or critic parameters", self.experts)
        return metrics

    def update_critics(self, b: dict[str, Any]) -> dict[str, float]:
        """Line 7: the critics V_o(c) regress the returns."""
        metrics = updates.update_critics(
            self.critics, self.opt_critic, b["ctx"], b["returns"], self.config.critic_epochs
        )
        self._check_finite("expert or critic parameters", self.critics)
        return metrics

    # -- line 8: context distributions, Eq. 4.8 ----------------------------------------------
    def update_contexts(self, b: dict[str, Any], entropy_old: torch.Tensor) -> dict[str, float]:
        """PPO on the sample form Eq. 4.8 of the context bound 4.5, all energy networks at once
        (:func:`vslbook.erl.diskill_updates.update_contexts`)."""
        cfg = self.config
        assert self.energies is not None and self.opt_context is not None
        returns = b["episode_returns"]
        self.reward_history = np.concatenate([self.reward_history, returns], axis=1)
        self.reward_history = self.reward_history[
            :, -cfg.reward_baseline_batches * returns.shape[1] :
        ]
        baseline = self._tensor(self.reward_history.mean(axis=1))
        # L_c(o, c) of Eq. 4.5 with one θ per context, less a per-expert constant baseline
        adv = (
            b["returns"] - baseline[:, None] + cfg.alpha * b["log_resp"]
            + cfg.alpha * entropy_old[:, None]
        )  # fmt: skip
        metrics = updates.update_contexts(self.energies, self.opt_context, b, adv, cfg)
        self._check_finite("energy-network parameters", self.energies)
        return metrics

    def _check_finite(self, what: str, *modules: torch.nn.Module) -> None:
        for m in modules:
            for p in m.parameters():
                if not torch.isfinite(p).all():
                    raise DivergenceError(self.iteration + 1, what)

    # -- Algorithm 3 -------------------------------------------------------------------------
    def choose_experts(self, contexts: np.ndarray, generator: torch.Generator) -> np.ndarray:
        """o ~ π(o | c) per context (Algorithm 3, line 2; Z_o over the fixed normaliser batch)."""
        c = self._tensor(contexts)
        if self.energies is None or self.config.n_experts == 1:
            return np.zeros(len(c), dtype=np.int64)
        with torch.no_grad():
            log_z = torch.logsumexp(self._energies(self._tensor(self.normaliser_contexts)), dim=-1)
            gate = log_gating(self._energies(c) - log_z[:, None]).exp()  # (K, M)
        return torch.multinomial(gate.T, 1, generator=generator)[:, 0].numpy()

    def mean_parameters(self, contexts: np.ndarray, experts: np.ndarray) -> np.ndarray:
        """The chosen experts' mean θ at each context: (M, n_params)."""
        c = self._tensor(contexts)
        k = self.config.n_experts
        with torch.no_grad():
            means = self.experts.mean(c[None].expand(k, -1, -1))  # (K, M, d)
        return means[torch.as_tensor(experts), torch.arange(len(c))].double().numpy()

    def test(self) -> dict[str, float]:
        """Algorithm 3 on the fixed test contexts with the experts' means: mean return, success,
        share executed, the mean return of the executed episodes alone
        (``test_executed_return``, None when every θ was rejected: a rejected θ's penalty
        can dominate ``test_return`` early on), experts used, and the mean of each
        per-episode number of the task over the episodes where it applies (``test_<key>``,
        e.g. the hopper's max height)."""
        gen = torch.Generator().manual_seed(self.seed * 1_000_003 + self.iteration)
        o = self.choose_experts(self.test_contexts, gen)
        theta = self.mean_parameters(self.test_contexts, o)
        roll = self.task.evaluate(theta, self.test_contexts, workers=self.workers)
        out = {
            "test_return": float(roll.returns.mean()),
            "test_executed": float(roll.executed.mean()),
            "test_executed_return": _mean_where(roll.returns, roll.executed),
        }
        if self.task.has_success:
            out["test_success"] = float(roll.success.mean())
        for key, values in roll.info.items():  # e.g. the hopper's max_height (Fig. B.3)
            finite = values[np.isfinite(values)]
            if key != "success" and len(finite):
                out[f"test_{key}"] = float(finite.mean())
        out["test_experts_used"] = float(len(np.unique(o)))
        return out

    # -- one iteration of Algorithm 2 ---------------------------------------------------------
    def iterate(self) -> dict[str, float]:
        """Lines 2-8 for every expert, batched."""
        t0 = time.perf_counter()
        b = self.collect()
        with torch.no_grad():
            entropy_old = self.experts.entropy(b["chol_old"])
        metrics = {
            "mean_return": float(b["episode_returns"].mean()),
            "rejected": float((~b["executed"]).mean()),
            "executed_return": _mean_where(b["episode_returns"], b["executed"]),
        }
        if self.task.has_success:
            metrics["success"] = float(b["success"].mean())
        metrics |= self.update_experts(b)
        metrics |= self.update_critics(b)
        if self.energies is not None:
            metrics |= self.update_contexts(b, entropy_old)
        self.iteration += 1
        metrics |= {
            "samples": self.samples, "episodes": self.episodes,
            "iteration_seconds": time.perf_counter() - t0,
        }  # fmt: skip
        return metrics

    # -- checkpoints ---------------------------------------------------------------------------
    def state_dict(self) -> dict[str, Any]:
        return {
            "experts": self.experts.state_dict(),
            "critics": self.critics.state_dict(),
            "energies": self.energies.state_dict() if self.energies is not None else None,
            "opt_expert": self.opt_expert.state_dict(),
            "opt_critic": self.opt_critic.state_dict(),
            "opt_context": self.opt_context.state_dict() if self.opt_context is not None else None,
            "rng": self.rng.bit_generator.state,
            "gen": self.gen.get_state(),
            "reward_history": self.reward_history,
            "iteration": self.iteration,
            "samples": self.samples,
            "episodes": self.episodes,
        }

    def load_state_dict(self, state: dict[str, Any]) -> None:
        saved = state["experts"]["chol_flat"].dtype
        if saved != self.dtype:
            raise ValueError(
                f"the checkpoint holds {saved} networks, the configuration asks for {self.dtype} "
                "(config.dtype)"
            )
        self.experts.load_state_dict(state["experts"])
        self.critics.load_state_dict(state["critics"])
        self.opt_expert.load_state_dict(state["opt_expert"])
        self.opt_critic.load_state_dict(state["opt_critic"])
        if self.energies is not None:
            self.energies.load_state_dict(state["energies"])
            self.opt_context.load_state_dict(state["opt_context"])  # type: ignore[union-attr]
        self.rng.bit_generator.state = state["rng"]
        self.gen.set_state(state["gen"])
        self.reward_history = np.asarray(state["reward_history"], dtype=np.float64)
        self.iteration = int(state["iteration"])
        self.samples = int(state["samples"])
        self.episodes = int(state["episodes"])


def train(
    task: EpisodicTask,
    config: DiSkillConfig,
    seed: int,
    *,
    state: DiSkill | None = None,
    until: int | None = None,
    callback: Callback | None = None,
    checkpoint: Callable[[DiSkill], None] | None = None,
    checkpoint_every: int = 25,
    checkpoint_due: Callable[[], bool] | None = None,
    workers: int | None = None,
) -> DiSkill:
    """Algorithm 2, resumable: continue ``state`` if given.

    Args:
        task: a Chapter 4 task.
        config: :class:`DiSkillConfig`.
        seed: the run's seed.
        state: a :class:`DiSkill` to continue (e.g. restored from a checkpoint).
        until: stop after this many iterations in total (default: ``config.iterations``).
        callback: ``callback(iteration, metrics)`` after every iteration (with the
            evaluation's numbers every ``test_every`` iterations and after the last).
        checkpoint: ``checkpoint(model)`` every ``checkpoint_every`` iterations and at the end.
        checkpoint_due: also checkpoint when it returns True (a run directory's
            :meth:`~vslbook.results.RunDir.checkpoint_due`: a time limit on lost work).
    """
    s = state if state is not None else DiSkill(task, config, seed, workers)
    cfg = s.config
    stop = cfg.iterations if until is None else min(until, cfg.iterations)
    if s.iteration == 0 and stop > 0 and callback is not None:
        # the initial policy; no checkpoint here: a run stopped before its first one starts
        # again from its seed (its rows dropped), so step 0 is never logged twice
        callback(0, {"samples": 0, "episodes": 0} | s.test())
    while s.iteration < stop:  # line 1
        metrics = s.iterate()  # lines 2-8
        if s.iteration % cfg.test_every == 0 or s.iteration == cfg.iterations:
            metrics |= s.test()
        if callback is not None:
            callback(s.iteration, metrics)
        due = s.iteration % checkpoint_every == 0 or s.iteration == stop
        if checkpoint is not None and (due or (checkpoint_due is not None and checkpoint_due())):
            checkpoint(s)
    return s


def _mean_where(values: Any, mask: Any) -> float | None:
    """Mean of ``values`` where ``mask`` holds; None where it holds nowhere."""
    values, mask = np.asarray(values, dtype=np.float64), np.asarray(mask, dtype=bool)
    return float(values[mask].mean()) if mask.any() else None
