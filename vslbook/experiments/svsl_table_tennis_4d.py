"""SVSL on Chapter 4's table tennis: its curve in Fig. 4.3b (Section 4.5.2, Table B.1).

The thesis compares Di-SkilL with SVSL (Chapter 3's algorithm, linear experts, 20 of
them) on the 4D table-tennis task of Appendix B.4.1.1 (``vslbook/TableTennis4D-v0``, the
ProDMP parameters of Di-SkilL). SVSL's per-expert context distributions π(c | o) are
Gaussians and propose contexts outside the valid region; such a context gets the guiding
punishment R_c(c) = −20 d_c² of B.4.1.1, d_c the distance to the valid contexts
(:meth:`vslbook.envs.robot.table_tennis.TableTennis4D.context_penalty`), and is neither
simulated nor counted as an executed episode (``evaluate(..., out_of_range="penalise")``,
as on SVSL's Chapter 3 tasks). Di-SkilL draws its contexts from p(c) and never meets it.

The hyper-parameters are Table B.1's (:func:`vslbook.erl.svsl_config.svsl_config` with
``"table-tennis-4d"``; what the table leaves open is the Chapter 3 table-tennis preset's);
:func:`svsl_counts` gives what a budget changes, :func:`svsl_tt_config` the configuration
``vslbook run svsl --env vslbook/TableTennis4D-v0 --budget B`` trains
(:mod:`vslbook.experiments.ch3_algorithms`).
"""

from __future__ import annotations

from typing import Any

from vslbook.budget import Budget, get_budget
from vslbook.erl.svsl_config import SVSLConfig, svsl_config

__all__ = ["ENV", "TASK", "svsl_counts", "svsl_tt_config"]

TASK = "table-tennis-4d"
ENV = "vslbook/TableTennis4D-v0"


def svsl_counts(budget: Budget | str | None = None) -> dict[str, Any]:
    """SVSL's counts on Chapter 4's table tennis at a budget (the rest is Table B.1's).

    * full: Table B.1's N = 20 and K = 1000, the authors' 100 weight iterations (Chapter
      3's table tennis), the seeds of Fig. 4.3b's other methods (the thesis: "at least 4";
      :func:`vslbook.experiments.diskill_runs.counts` uses 24), a test every 50 iterations
      on Di-SkilL's 75 test contexts;
    * reduced: N = 2, K = 50, 20 weight iterations, 3 seeds, a test every 10 iterations
      (about 25,000 episodes, as many as Di-SkilL's run at this budget);
    * smoke ("does it run"): one expert for 2 iterations, no weight phase, 1 seed, a test
      after each iteration on 10 contexts.

    H (50), the samples per update, α, β, β_w and the KL bounds are never scaled.
    """
    b = get_budget(budget)
    return {
        "seeds": b.pick(smoke=1, reduced=3, full=24),
        "n_experts": b.pick(smoke=1, reduced=2, full=20),  # N
        "iterations_per_expert": b.pick(smoke=2, reduced=50, full=1000),  # K
        "fine_tune_every": 50,  # H: a hyper-parameter, never scaled
        "weight_iterations": b.pick(smoke=0, reduced=20, full=100),
        "test_every": b.pick(smoke=1, reduced=10, full=50),
        "test_contexts": b.pick(smoke=10, reduced=75, full=75),
    }


def svsl_tt_config(budget: Budget | str | None = None, **overrides: Any) -> SVSLConfig:
    """Table B.1's SVSL configuration with :func:`svsl_counts`'s counts at ``budget``
    (``overrides``: any :class:`~vslbook.erl.svsl_config.SVSLConfig` field)."""
    c = svsl_counts(budget)
    fields = {k: v for k, v in c.items() if k != "seeds"}
    return svsl_config(TASK, **(fields | overrides))
