import numpy as np
import pytest
import torch

from vslbook.budget import BUDGETS, get_budget
from vslbook.seeding import seed_everything


def test_presets_and_env_var(monkeypatch):
    assert set(BUDGETS) == {"smoke", "reduced", "full"}
    monkeypatch.setenv("VSLBOOK_BUDGET", "smoke")
    assert get_budget().name == "smoke"
    monkeypatch.delenv("VSLBOOK_BUDGET")
    assert get_budget().name == "reduced"
    assert get_budget("FULL").name == "full"


def test_unknown_budget_is_a_clear_error(monkeypatch):
    with pytest.raises(ValueError, match=r"unknown budget 'huge'.*smoke, reduced, full"):
        get_budget("huge")
    monkeypatch.setenv("VSLBOOK_BUDGET", "tiny")
    with pytest.raises(ValueError, match=r"'tiny' \(from \$VSLBOOK_BUDGET\)"):
        get_budget()


def test_budgets_scale_counts_monotonically():
    full = 1_000_000
    counts = [BUDGETS[n].scale(full) for n in ("smoke", "reduced", "full")]
    assert counts == sorted(counts) and counts[-1] == full
    assert BUDGETS["smoke"].scale(10, minimum=5) == 5
    assert BUDGETS["reduced"].pick(smoke=1, reduced=2, full=3) == 2
    with pytest.raises(ValueError, match="must be >= 0"):
        BUDGETS["full"].scale(-1)


def test_seed_everything_reproduces_all_sources():
    import gymnasium as gym

    def draw():
        env = gym.make("Pendulum-v1")
        rng = seed_everything(123, env)
        obs, _ = env.reset()
        return (
            np.random.rand(),  # noqa: NPY002 - the global state is what is tested
            torch.rand(1).item(),
            rng.random(),
            tuple(env.action_space.sample()),
            tuple(obs),
        )

    assert draw() == draw()


@pytest.mark.parametrize("bad", [-1, 1.5, "3", True])
def test_seed_must_be_nonnegative_int(bad):
    with pytest.raises(ValueError, match="non-negative integer"):
        seed_everything(bad)
