"""Episode-based policy gradient with a value baseline (Section 2.3.2.1, Eq. 2.31–2.33).

The smallest complete ERL algorithm in the book, and the reference loop for the run
directory, checkpoint and resume machinery that the chapter algorithms reuse. The
search distribution is linear-Gaussian, π_ω(θ|c) = N(θ | K c + k, diag σ²), ω = (K, k, log σ).

Each iteration (read it next to Eq. 2.31–2.33):

1. draw contexts c_i ~ p(c) and parameters θ_i ~ π_ω(θ|c_i);
2. run the episodes: R_i = R(θ_i, c_i) (black box);
3. fit the baseline V(c) ≈ E_π[R | c] by least squares on quadratic context features
   and form advantages A_i = R_i - V(c_i) (Eq. 2.32), standardised;
4. ascend ∇_ω (1/N) Σ_i log π_ω(θ_i|c_i) A_i (Eq. 2.33) with Adam.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import torch

from vslbook.budget import Budget
from vslbook.envs import make
from vslbook.progress import progress_bar
from vslbook.registry import config_from_record, register_algorithm
from vslbook.results import RunDir
from vslbook.rng_state import restore_rng_state, rng_state


@dataclass(frozen=True)
class ERLPGConfig:
    """Hyper-parameters; ``iterations`` is the full-budget count that budgets scale."""

    iterations: int = 1000
    samples_per_iteration: int = 64
    learning_rate: float = 0.05
    init_std: float = 1.0
    eval_every: int = 10
    eval_contexts: int = 64
    checkpoint_every: int = 25

    def __post_init__(self) -> None:
        for name in (
            "iterations",
            "samples_per_iteration",
            "eval_every",
            "eval_contexts",
            "checkpoint_every",
        ):
            if getattr(self, name) < 1:
                raise ValueError(f"{name} must be >= 1, got {getattr(self, name)}")
        if not (self.learning_rate > 0 and self.init_std > 0):
            raise ValueError(
                f"learning_rate and init_std must be > 0, got {self.learning_rate}, {self.init_std}"
            )


def _features(c: np.ndarray) -> np.ndarray:
    """Quadratic features [1, c, c⊗c] for the baseline V(c)."""
    quad = np.einsum("ni,nj->nij", c, c).reshape(len(c), -1)
    return np.concatenate([np.ones((len(c), 1)), c, quad], axis=1)


def _log_prob(theta, mean, log_std):
    var = torch.exp(2 * log_std)
    return -0.5 * (((theta - mean) ** 2) / var + 2 * log_std + math.log(2 * math.pi)).sum(-1)


def train(
    run: RunDir,
    config: dict,
    budget: Budget,
    *,
    progress: bool = True,
    stop_after: int | None = None,
) -> dict | None:
    """Train in ``run``; resume from its checkpoint if there is one. Returns a summary when
    finished, None when stopped early by ``stop_after``."""
    cfg = config_from_record(ERLPGConfig, config)
    env = make(config["env"]).unwrapped
    n_iter = budget.scale(cfg.iterations, minimum=20)
    rng = np.random.default_rng(config["seed"])
    eval_c = env.sample_contexts(cfg.eval_contexts, np.random.default_rng(config["seed"] + 10_000))

    d_c, d_theta = env.observation_space.shape[0], env.action_space.shape[0]
    K = torch.zeros(d_theta, d_c, dtype=torch.float64, requires_grad=True)
    k = torch.zeros(d_theta, dtype=torch.float64, requires_grad=True)
    log_std = torch.full(
        (d_theta,), math.log(cfg.init_std), dtype=torch.float64, requires_grad=True
    )
    opt = torch.optim.Adam([K, k, log_std], lr=cfg.learning_rate)

    start = 0
    state = run.load_checkpoint()
    if state is not None:
        with torch.no_grad():
            K.copy_(state["K"]), k.copy_(state["k"]), log_std.copy_(state["log_std"])
        opt.load_state_dict(state["optimizer"])
        restore_rng_state(state["rng"], rng)
        start = state["iteration"]

    def checkpoint(iteration: int) -> None:
        run.save_checkpoint(
            {
                "K": K.detach().clone(),
                "k": k.detach().clone(),
                "log_std": log_std.detach().clone(),
                "optimizer": opt.state_dict(),
                "rng": rng_state(rng),
                "iteration": iteration,
            }
        )

    def evaluate() -> tuple[float, float]:
        with torch.no_grad():
            mean = torch.from_numpy(eval_c) @ K.T + k
        ret, succ = env.evaluate(mean.numpy(), eval_c)
        return float(ret.mean()), float(succ.mean())

    bar = progress_bar(
        initial=start,
        total=n_iter,
        disable=not progress,
        desc=f"erl-pg {config['env']} s{config['seed']}",
    )
    done_now = 0
    for it in range(start, n_iter):
        c = env.sample_contexts(cfg.samples_per_iteration, rng)  # c ~ p(c)
        eps = rng.standard_normal((cfg.samples_per_iteration, d_theta))
        c_t = torch.from_numpy(c)
        mean = c_t @ K.T + k
        theta = (mean + torch.exp(log_std) * torch.from_numpy(eps)).detach()  # θ ~ π(θ|c)
        R, succ = env.evaluate(theta.numpy(), c)  # black box
        phi = _features(c)
        w, *_ = np.linalg.lstsq(phi, R, rcond=None)  # V(c)
        adv = R - phi @ w  # Eq. 2.32
        adv = (adv - adv.mean()) / (adv.std() + 1e-8)
        loss = -(_log_prob(theta, mean, log_std) * torch.from_numpy(adv)).mean()  # Eq. 2.33
        opt.zero_grad()
        loss.backward()
        opt.step()

        row = {
            "episodes": (it + 1) * cfg.samples_per_iteration,
            "train_return": float(R.mean()),
            "train_success": float(succ.mean()),
            "std": float(torch.exp(log_std.detach()).mean()),
        }
        if (it + 1) % cfg.eval_every == 0 or it + 1 == n_iter:
            row["eval_return"], row["eval_success"] = evaluate()
        run.log(it + 1, **row)
        bar.update(1)
        bar.set_postfix(ret=f"{row['train_return']:.3f}")
        done_now += 1
        if (it + 1) % cfg.checkpoint_every == 0 or it + 1 == n_iter:
            checkpoint(it + 1)
        if stop_after is not None and done_now >= stop_after and it + 1 < n_iter:
            checkpoint(it + 1)
            bar.close()
            return None
    bar.close()
    ret, succ = evaluate()
    return {"iterations": n_iter, "eval_return": ret, "eval_success": succ}


register_algorithm(
    "erl-pg",
    train=train,
    config=ERLPGConfig,
    envs=("vslbook/PointReach-v0",),
    doc="episode-based policy gradient with a value baseline (Eq. 2.33), linear-Gaussian policy",
    independent_of=("srl/", "experiments/"),
)
