"""One parameter vector θ per robot task that does what the task asks, at one context.

The book's task gallery draws these episodes (``notebooks/01_tasks.py``) and the tests of
the recorded paths replay them (``tests/test_robot_paths.py``); each task's own test file
says how its θ was found. All are in the layout the task's primitive takes: for the ProDMP
tasks mp_pytorch's (``[τ, delay,] per joint [w_1 … w_B, (g)]``, :mod:`vslbook.movement`).

* table tennis (4D and hard): a return that lands on the opponent's half near the goal;
  found for mp_pytorch's basis by a least-squares refit of the weights to an earlier θ's
  tracked command ``K_p q_d + K_d q̇_d`` and a short cross-entropy search;
* table tennis (Chapter 3): a return that succeeds (``tests/test_robot_table_tennis_ch3.py``);
* beer pong: a throw into the cup (a short cross-entropy search, ``tests/test_robot_beer_pong.py``);
* box pushing: the box pushed to its goal within the position and angle tolerances. Under
  the default ``settings="code"`` θ has 35 entries (per joint ``[w_1 … w_4, g]``, goal learned);
  it is the thesis settings' 28-parameter θ (:data:`THESIS_EXAMPLES`, found by IK, a
  least-squares fit and a short cross-entropy search, ``tests/test_robot_box_pushing.py``)
  with each joint's goal set to what the disabled goal uses, the start posture:
  g_j = q0_j / 0.3 (``goal_scale`` 0.3), rounded to 1e-6. Both give the same desired
  trajectory (to 1e-6 rad) and the same success; the returns differ with the reward;
* mini golf: the ball hit through the goal gap;
* hopper jump: a jump (the task has no success);
* the 5-link reachers: a random θ (a plausible reach; no success).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

__all__ = ["EXAMPLES", "THESIS_EXAMPLES", "Example"]


@dataclass(frozen=True)
class Example:
    """θ, the context it was found for, and what it does (``"found θ"``, ``"a jump"``, ...)."""

    theta: tuple[float, ...]
    context: tuple[float, ...]
    what: str
    succeeds: bool  #: whether the task's success criterion holds for it

    def arrays(self) -> tuple[np.ndarray, np.ndarray]:
        """θ and the context as float arrays."""
        return np.asarray(self.theta, dtype=np.float64), np.asarray(self.context, dtype=np.float64)


_TT = (
    1.008634, 0.417206, -0.244005, -0.912505, -0.316006, -0.941875, -0.15136, -0.064655,
    -2.280435, -1.318363, -0.102644, -0.479637, -0.110751, 0.465268, -3.829837, -0.997936,
    -0.70222, 0.618083, 1.017525, 0.221885, -0.252506, -0.033285, -0.379723,
)  # fmt: skip

_BPO_CONTEXT = (0.35, -0.2, math.pi, 0.58, 0.05)

#: task name → its example episode (the task's default settings, the authors' code)
EXAMPLES: dict[str, Example] = {
    "reacher5": Example(tuple(np.random.default_rng(0).normal(size=30)), (0.2, 0.3),
                        "random θ", False),
    "reacher5-ch3": Example(tuple(np.random.default_rng(0).normal(size=25)), (0.2, 0.3),
                            "random θ", False),
    "table-tennis-4d": Example(_TT, (-0.5, 0.0, -0.57, -0.11), "found θ", True),
    "table-tennis-hard": Example(_TT, (-0.5, 0.0, 2.5, -0.57, -0.11), "found θ", True),
    "table-tennis-ch3": Example((
        0.7332, -0.0919, 0.4915, -0.5925, -0.9775, 0.9394, 0.3024, -0.1873, 2.6909, -0.1296,
        -0.0533, 0.2404, -0.3678, -0.5482, -0.2085, -0.3154, -0.5552, -1.4937, 0.1432, 0.1876,
        -0.3788, 0.0639,
    ), (-0.3, 0.0, -0.5, 0.0), "found θ", True),
    "beer-pong": Example((
        0.642637424, -0.667687292, 0.163244006, -6.83075196, -3.65419193, -0.704139562,
        -0.453074444, -5.56583802, -4.84612128, -0.0058760267, 0.767789135, -0.610486646,
        -0.185773959, -1.41648937, -0.827402227,
    ), (0.0, -1.7), "found θ", True),
    "hopper-jump": Example((
        0.743, 0.592, -0.242, 0.187, 6.486, 1.668, -0.948, 1.052, 4.139, -5.249, -0.331, -4.092,
    ), (-0.25, -0.1, 0.4, 0.8), "a jump", False),
    "box-pushing-obstacle": Example((
        0.432, -0.4569, -1.3418, -1.1043, 1.29,
        0.1331, -1.1854, -0.6359, -0.5922, 0.586667,
        0.2453, -0.6642, -1.2187, -1.8743, 0.833333,
        -0.5781, -1.5945, -0.0838, -0.587, -7.996667,
        0.5485, -0.0942, -0.4841, 0.5219, -0.266667,
        -0.3138, -0.1061, 0.1833, 0.1271, 8.563333,
        0.2161, -1.5723, -2.2373, -2.8444, 4.933333,
    ), _BPO_CONTEXT, "found θ", True),
    "mini-golf": Example((
        1.412648, -0.697413, -0.47867, -0.48046, -0.748003, -1.721859, -0.212927, 1.487021,
        1.3175, -1.251709, 1.06103, 0.174545, -1.68043, -1.602168, -2.241059, -1.492407,
        0.136616, -0.712911, 0.804888, 0.305455, 0.527284, -0.997824, -0.844455, -0.389246,
        0.016353, -0.862963, 0.924912, 0.947544, 0.27086,
    ), (0.3, -0.5, 0.44, 0.525), "found θ", True),
}  # fmt: skip

#: task name → its example under ``settings="thesis"``, where θ's layout differs from the
#: default's (box pushing: B.4.2.1's 28 parameters, goal disabled)
THESIS_EXAMPLES: dict[str, Example] = {
    "box-pushing-obstacle": Example((
        0.432, -0.4569, -1.3418, -1.1043, 0.1331, -1.1854, -0.6359, -0.5922, 0.2453, -0.6642,
        -1.2187, -1.8743, -0.5781, -1.5945, -0.0838, -0.587, 0.5485, -0.0942, -0.4841, 0.5219,
        -0.3138, -0.1061, 0.1833, 0.1271, 0.2161, -1.5723, -2.2373, -2.8444,
    ), _BPO_CONTEXT, "found θ", True),
}  # fmt: skip
