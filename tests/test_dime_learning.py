"""DIME learns: a short run on a cheap task beats what a random or an untrained policy reaches.

Task. Gymnasium's ``InvertedPendulum-v5`` (MuJoCo): reward 1 per step while the pole is up,
termination when it falls, at most 1000 steps. Its return rises clearly within about a
thousand environment steps, so a run fits the test's time; ``Pendulum-v1`` did not (see
"Why not Pendulum-v1" below).

Configuration (a *test* configuration, not the thesis's). Against Table C.2 it changes:
critic and actor width 64 (2048 / 256), 2 diffusion steps (16), batch 128 (256),
``learning_starts`` 100 (5000 exploration steps: the whole run is 1500), initial temperature
``init_log_alpha = -3`` (α₀ ≈ 0.05 instead of 1; the autotuning still runs, but Adam at
``alpha_lr = 1e-3`` moves log α by about 1e-3 per actor update, too slowly for a short run:
starting at α = 1, trial runs on Pendulum-v1 and the point mass still had α = 0.47-0.72 after
1000-2000 steps and showed no clear improvement), and the C51 support [-20, 120]
(discounted returns here are in [0, 100] at γ = 0.99). Everything else (UTD 2, policy delay
3, learning rates, Adam β1 0.5, BatchRenorm critics without target network, the
distributional critic, learned β, the entropy target 4·|A|) is Table C.2's.
The ``full`` budget is used because its fraction is 1.0: every count below is then literally a
number of environment steps (``total_steps`` 1500, one evaluation at the end with 10 episodes
of the stochastic policy).

Measured baselines (on the 2-core CPU machine, with this configuration). The test asserts on
the final ``eval_return``, the mean of 10 evaluation episodes, so means of 10 episodes are
the comparable statistic:

======================  ============================  ===============================
policy                  one episode: mean [min, max]  mean of 10 episodes: [min, max]
======================  ============================  ===============================
uniform random actions  4.7 [2, 28]                   4.7 [3.2, 6.5]
untrained DIME          4.0 [2, 31]                   4.0 [2.2, 5.8]
======================  ============================  ===============================

Random: 5 seeds x 50 episodes, actions uniform on [-1, 1] mapped to the action box, resets
seeded per episode. Untrained: 5 initialisation seeds (``seed_everything(seed)`` then
``make_agent`` with this configuration, as ``train`` does) x 50 episodes each with the
stochastic policy (the whole denoising chain), i.e. what the evaluation at step 0 would see.
Means of 10 are over consecutive blocks of 10 of those episodes (25 blocks per policy).

Trained: this test's run (this configuration, final evaluation at step 1500 with 10
episodes) for seeds 0-5 gave 41.7, 183.2, 54.7, 78.9, 85.4, 107.0 (mean 91.8, min 41.7); the
test uses seed 0, the lowest. The same runs evaluated every 250 steps (seeds 0-5; an
evaluation's episodes are seeded by the evaluation's index, so the episodes differ while the
training does not) read 4.0-12.8 at step 250, 11.1-33.9 at 500, 27.6-32.8 at 750, 21.2-45.3
at 1000, 19.8-58.8 at 1250 and 50.0-148.3 at 1500: the return rises over the run, with dips
(seed 0: 37.6 at 1000, 19.8 at 1250, 50.0 at 1500).

Threshold. ``THRESHOLD`` is 20: three times the largest 10-episode mean of either baseline
(6.5), and half the lowest trained final return (41.7).

Time: 85-95 s per run, measured on the 2-core machine while it was also running three niced
single-threaded trainings and a notebook, so a pessimistic figure; the CPU time of the run
is about 60 s. ``num_threads=1``: at these sizes a second thread does not help, and on a
busy machine it made the updates many times slower.

Why not Pendulum-v1. With 64-wide networks, learning_starts 200, batch 128, 2 diffusion steps,
DIME's evaluation returns (5 episodes) at step 1600 were -1228, -1144, -1161 (α₀ = 1, seeds
0-2) and -1285 (α₀ ≈ 0.05, seed 0): those of a uniformly random policy (5-episode means
-1386 to -1031, mean -1207, over 100 episodes). Every learning step costs 50-100 ms here (two
critic updates, a third of an actor update and the sampling chain), so the several thousand
steps Pendulum needs to learn to swing up do not fit a test.
"""

from __future__ import annotations

import pytest

from vslbook.training import run

ENV = "InvertedPendulum-v5"
SEED = 0
CONFIG = dict(
    total_steps=1500,
    learning_starts=100,
    critic_hidden=64,
    actor_hidden=64,
    n_diffusion_steps=2,
    batch_size=128,
    init_log_alpha=-3.0,
    eval_every=1500,  # one evaluation, at the end
    eval_episodes=10,
    checkpoint_every=1500,  # only the final checkpoint
    v_min=-20.0,
    v_max=120.0,
    num_threads=1,
    device="cpu",  # the measured numbers below are CPU runs
)
THRESHOLD = 20.0



@pytest.mark.slow
def test_dime_learns_inverted_pendulum(tmp_path):
    rd = run("dime", ENV, SEED, "full", root=tmp_path, overrides=CONFIG, progress=False)
    assert rd.done
    rows = rd.metrics()
    assert [r["step"] for r in rows] == [CONFIG["total_steps"]]
    final = rows[-1]["eval_return"]
    assert final > THRESHOLD, (
        f"final evaluation return {final:.1f} <= {THRESHOLD}: DIME did not learn "
        f"(uniform random and untrained policies average 4-5, at most 6.5 over 10 episodes)"
    )
