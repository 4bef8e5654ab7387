"""The audited settings of the robot tasks (Chapters 3 and 4): typed thesis and code values.

Data for :func:`vslbook.experiments.audit.task_audit`. The ``thesis`` and ``code`` values
below are typed, each with where it was read; ``ours`` is an attribute path or a probe of the
task object that :func:`vslbook.envs.robot.make_task` builds. Code locations refer to
``ALRhub/di-skill`` at 3e5a9e2 (with its vendored fancy_gym and MP_PyTorch) and
``Onur4229/SVSL_LMOE`` at 52b5404 (read only; nothing of them is in this repository).
Where a value was taken from ``shared/design/CH3_CH4_FACTS.md`` without a line number, the
source names the file and the section of that note.
"""

from __future__ import annotations

import importlib
import math
from collections.abc import Callable
from typing import Any

import numpy as np

from vslbook.experiments import audit_probes as probe
from vslbook.experiments.audit import NOT_FOUND, NOT_STATED, Setting

__all__ = ["TASK_SETTINGS"]

# ---- where the authors' values stand ---------------------------------------------------
_DS = "ALRhub/di-skill@3e5a9e2 "
_REG = _DS + "diskill/contextual_envs/__init__.py"
_FG = _DS + "fancy_gym/fancy_gym/envs/__init__.py"
_MP = _DS + "MP_PyTorch/mp_pytorch/"
_MJ = _DS + "fancy_gym/fancy_gym/envs/mujoco/"
_SV = "Onur4229/SVSL_LMOE@52b5404 "
_FACTS = " (CH3_CH4_FACTS {})"


# ---- how ours is read ------------------------------------------------------------------
def _const(module: str, name: str) -> Callable[[Any], Any]:
    """A reader of a module constant of ``vslbook.envs.robot.<module>``."""

    def read(task: Any) -> Any:
        return getattr(importlib.import_module(f"vslbook.envs.robot.{module}"), name)

    read.__doc__ = f"vslbook.envs.robot.{module}.{name}"
    return read


def _consts(module: str, *names: str) -> Callable[[Any], Any]:
    readers = [_const(module, n) for n in names]

    def read(task: Any) -> tuple[Any, ...]:
        return tuple(r(task) for r in readers)

    read.__doc__ = f"vslbook.envs.robot.{module}.({', '.join(names)})"
    return read


def _box(task: Any) -> np.ndarray:
    """[task.context_low, task.context_high]"""
    return np.array([task.context_low, task.context_high])


def _order(task: Any) -> str:
    """task.context_names"""
    return ", ".join(task.context_names)


def _mp(attr: str) -> Callable[[Any], Any]:
    """The task's ProDMP spec attribute (``spec`` or ``mp``)."""

    def read(task: Any) -> Any:
        spec = getattr(task, "spec", None) or getattr(task, "mp", None)
        if isinstance(spec, str):  # Reacher5Ch3.mp names the primitive; its ProDMP is spec
            spec = task.spec
        return getattr(spec, attr)

    read.__doc__ = f"task.spec.{attr} (or task.mp.{attr})"
    return read


def _tt_penalty_weights(task: Any) -> tuple[float, float]:
    """-table_tennis.trajectory_penalty at τ, delay 0.1 past their bounds (q_d inside)"""
    from vslbook.envs.robot import table_tennis as tt

    spec = tt.SPEC
    q_d = np.tile(tt.Q0, (spec.n_steps, 1))
    out = []
    for i in (0, 1):
        theta = np.zeros(spec.n_params)
        theta[0], theta[1] = spec.tau_bounds[1], spec.delay_bounds[1]
        theta[i] += 0.1
        out.append(round(-tt.trajectory_penalty(theta, q_d) / 0.1, 9))
    return tuple(out)


def _bpo_probe(task: Any, rod: float, dq: np.ndarray, final: bool = True) -> float:
    """box_pushing.step_reward with the task's reward variant at a probe state: box, goal
    and rod tip on the x-axis (the tip ``rod`` m from the box), the box at the goal pose,
    an upright rod, joints mid-range, joint velocities ``dq``, no torque."""
    from vslbook.envs.robot import box_pushing_reward as bp

    quat, z3 = np.array([1.0, 0, 0, 0]), np.zeros(3)
    q = (bp.Q_MAX + bp.Q_MIN) / 2
    return bp.step_reward(
        z3, quat, z3, quat, np.array([rod, 0, 0]), bp.ROD_QUAT_DESIRED, q, dq, np.zeros(7),
        final, task.reward,
    )  # fmt: skip


def _bpo_reward(task: Any) -> tuple[float, float]:
    """box_pushing.step_reward (task.reward) probed: (weight of the box–rod distance, weight
    of ‖q̇_T‖)"""
    rest = np.zeros(7)
    vel = np.zeros(7)
    vel[0] = 0.5
    rod_w = _bpo_probe(task, 1.0, rest) - _bpo_probe(task, 2.0, rest)
    vel_w = (_bpo_probe(task, 1.0, rest) - _bpo_probe(task, 1.0, vel)) / 0.5
    return round(rod_w, 9), round(vel_w, 9)


def _bpo_tilt_cost(task: Any) -> float:
    """box_pushing.step_reward (task.reward) probed: the cost of an upright rod (tilt 0) in
    one step, what is left after the box–rod term of a tip 0.05 m from the box"""
    rod_w = _bpo_reward(task)[0]
    return round(-_bpo_probe(task, 0.05, np.zeros(7), final=False) - rod_w * 0.05, 9)


def _bpo_distance_rule(task: Any) -> str:
    """task.context_valid on a context 0.21 m (Euclidean) but 0.05 m (in y) from the goal"""
    ok = bool(task.context_valid(np.array([[0.35, -0.3, 1.0, 0.55, -0.25]]))[0])
    return "Euclidean distance >= 0.15" if ok else "y-distance >= 0.15"


def _primitive(task: Any) -> str:
    """the primitive the task builds (ProDMPSpec → ProDMP; Reacher5Ch3.mp)"""
    from vslbook.envs.robot.primitives import ProDMPSpec

    mp = getattr(task, "mp", None)
    if isinstance(mp, str):
        return {"promp": "ProMP", "prodmp": "ProDMP"}[mp]
    spec = getattr(task, "spec", None) or mp
    return "ProDMP" if isinstance(spec, ProDMPSpec) else "ProMP"


# ---- the rows --------------------------------------------------------------------------
Row = tuple[str, Any, str, Any, str, Any, str]


def _rows(subject: str, figures: str, rows: list[Row]) -> list[Setting]:
    return [Setting(subject, f, t, tw, c, cw, o, figures, why) for f, t, tw, c, cw, o, why in rows]


_CODE = "code (made the figure)"
_TT3_WHY = "code (made the figure); settings=\"thesis\" gives A.3.3's"


def _tt3(kind: str, lines: str) -> tuple[str, str, str, str]:
    """(thesis, where, code, where) of a Ch. 3 table-tennis punishment (audit_probes.TT3_*)."""
    thesis, code = getattr(probe, "TT3_" + kind)
    return (thesis, "A.3.3", code, _SV + "util/table_tennis/utils/hierarchical_reward.py l."
            + lines + _FACTS.format("§1.1"))  # fmt: skip
_TT_SPEC_WHY = _CODE
# fmt: off
_TT: list[Row] = [
    ("control dt (s)", NOT_STATED, "B.4.1.1 gives none", 0.008,
     _MJ + "table_tennis/table_tennis_env.py: timestep 0.002 × frame_skip 4" + _FACTS.format("§1.1"),  # noqa: E501
     _mp("dt"), _CODE),
    ("horizon (control steps)", NOT_STATED, "B.4.1.1 gives none", 350,
     _FG + " l.277 MAX_EPISODE_STEPS_TABLE_TENNIS", _mp("n_steps"), _CODE),
    ("primitive", "ProDMP", "Sec. 4.5.1, B.4.1.1", "ProDMP", _REG + " l.151-174", _primitive,
     _CODE),
    ("basis functions per joint", 3, "B.4.1.1", 3, _REG + " l.171", _mp("n_basis"), "both agree"),
    ("basis alpha", NOT_STATED, "B.4.1.1 gives none", 25.0, _REG + " l.172", _mp("alpha"), _CODE),
    ("alpha_phase", NOT_STATED, "B.4.1.1 gives none", 3.0, _REG + " l.174", _mp("alpha_phase"),
     _CODE),
    ("basis bandwidth factor", NOT_STATED, "B.4.1.1 gives none", 3.0, _REG + " l.173",
     _mp("bandwidth_factor"), _CODE),
    ("τ bounds (learned)", NOT_STATED, "B.4.1.1 gives none", (0.56, 1.5), _REG + " l.167, 169",
     _mp("tau_bounds"), "Di-SkilL's (fancy-gym 0.3.0 has [0.8, 1.5])"),
    ("delay bounds (learned)", NOT_STATED, "B.4.1.1 gives none", (0.05, 0.6), _REG + " l.168, 170",
     _mp("delay_bounds"), "Di-SkilL's (fancy-gym 0.3.0 has [0.05, 0.15])"),
    ("goal mode", NOT_STATED, "B.4.1.1 gives none", "disabled",
     _REG + " l.165-166 (relative_goal, disable_goal)", _mp("goal"), _CODE),
    ("weights_scale", NOT_STATED, "B.4.1.1 gives none", 0.7, _REG + " l.163", _mp("weights_scale"),
     _CODE),
    ("parameters θ", 23, "B.4.1.1", 23, _REG + " l.165-171 (2 + 7·3)", "n_params", "both agree"),
    ("PD gains K_p", NOT_STATED, "B.4.1.1 gives none", 0.5 * np.array([1, 4, 2, 4, 1, 4, 1.0]),
     _REG + " l.161", _const("table_tennis", "KP"), _CODE),
    ("PD gains K_d", NOT_STATED, "B.4.1.1 gives none",
     0.5 * np.array([0.1, 0.4, 0.2, 0.4, 0.1, 0.4, 0.1]), _REG + " l.162",
     _const("table_tennis", "KD"), _CODE),
    ("floor contact after the hit counts as landing", False, "A.3.3 cond. 3, B.4.1.1 f4 ('table')",
     True, _MJ + "table_tennis/table_tennis_env.py _get_reward" + _FACTS.format("§1.1"),
     "floor_counts_as_landing", "code (settings=\"thesis\" gives the text's table-only rule)"),
    ("success: landing within (m) of the goal", 0.2, "B.4.1.1", 0.2,
     _MJ + "table_tennis/table_tennis_env.py" + _FACTS.format("§1.1"),
     _const("table_tennis", "SUCCESS_RADIUS"), "both agree"),
    ("invalid θ: penalty weights on τ, delay excess", (0.0, 0.0),
     "B.4.1.1 r_traj (joint term only)", (3.0, 3.0),
     _MJ + "table_tennis/table_tennis_env.py" + _FACTS.format("§1.1"), _tt_penalty_weights,
     "code (the thesis's r_traj is not a joint-limit test)"),
]
# fmt: on

# fmt: off
TASK_SETTINGS: list[Setting] = [
    *_rows(
        "table-tennis-4d",
        "Fig. 4.3b",
        [
            ("context box [low; high] (x_b, y_b, x_g, y_g)",
             [[-1, -0.65, -1, -0.6], [-0.2, 0.65, -0.2, 0.6]], "B.4.1.1",
             [[-1, -0.65, -1, -0.65], [-0.2, 0.65, -0.2, 0.65]],
             _MJ + "table_tennis/table_tennis_utils.py CONTEXT_BOUNDS_4DIMS" + _FACTS.format("§1.1"),  # noqa: E501
             _box, "code (±0.65; settings=\"thesis\" gives B.4.1.1's ±0.6)"),
            *_TT,
        ],
    ),
    *_rows(
        "table-tennis-hard",
        "Fig. 4.4c, 4.6",
        [
            ("context box [low; high] (x_b, y_b, v_x, x_g, y_g)",
             [[-1, -0.65, 1.5, -1, -0.6], [-0.2, 0.65, 4, -0.2, 0.6]], "B.4.1.2 (+ B.4.1.1)",
             [[-1, -0.65, 1.5, -1, -0.65], [-0.2, 0.65, 4, -0.2, 0.65]],
             _MJ + "table_tennis/table_tennis_utils.py CONTEXT_BOUNDS_5DIMS" + _FACTS.format("§1.2"),  # noqa: E501
             _box, "code (±0.65; settings=\"thesis\" gives B.4.1.1's ±0.6)"),
            *_TT,
        ],
    ),
    *_rows(
        "hopper-jump",
        "Fig. 4.4a, B.3",
        [
            ("context order", "q_thigh, q_leg, q_foot, goal_x", "B.4.2",
             "goal_x, q_thigh, q_leg, q_foot",
             _MJ + "hopper_jump/hopper_jump.py CONTEXT_BOUNDS" + _FACTS.format("§1.4"), _order,
             "thesis (a permutation; learning is unaffected)"),
            ("context box in the thesis's order", [[-0.5, -0.2, 0, 0.3], [0, 0, 0.785, 1.35]],
             "B.4.2", [[-0.5, -0.2, 0, 0.3], [0, 0, 0.785, 1.35]],
             _MJ + "hopper_jump/hopper_jump.py CONTEXT_BOUNDS (reordered)" + _FACTS.format("§1.4"),
             _box, "both agree"),
            ("control dt (s)", NOT_STATED, "B.4.2 gives none", 0.008,
             _MJ + "hopper_jump/hopper_jump.py frame_skip 4 × 0.002" + _FACTS.format("§1.4"),
             _mp("dt"), _CODE),
            ("horizon (control steps)", NOT_STATED, "B.4.2 gives none", 250,
             _FG + " l.176 MAX_EPISODE_STEPS_HOPPERJUMP", _mp("n_steps"), _CODE),
            ("basis functions per joint", 3, "B.4.2", 3, _REG + " l.244", _mp("n_basis"),
             "both agree"),
            ("basis alpha", NOT_STATED, "B.4.2 gives none", 10.0, _FG + " l.92 (default dict)",
             _mp("alpha"), _CODE),
            ("alpha_phase", NOT_STATED, "B.4.2 gives none", 3.0,
             _MP + "phase_gn/exp_decay_phase.py l.13 (default)", _mp("alpha_phase"), _CODE),
            ("basis bandwidth factor", NOT_STATED, "B.4.2 gives none", 3.0,
             _MP + "basis_gn/norm_rbf_basis.py l.133 (default)", _mp("bandwidth_factor"), _CODE),
            ("τ (fixed)", NOT_STATED, "B.4.2 gives none", 0.8, _REG + " l.238, 240", _mp("tau"),
             _CODE),
            ("goal mode", "learned", "B.4.2 (12 = 3·3 + 3 goals)", "learned",
             _REG + " l.233-244 (relative_goal default False)", _mp("goal"), "both agree"),
            ("weights_scale, goal_scale", NOT_STATED, "B.4.2 gives none", (1.0, 1.0),
             _REG + " l.241-242", lambda t: (t.spec.weights_scale, t.spec.goal_scale), _CODE),
            ("parameters θ", 12, "B.4.2", 12, _REG + " l.233-244", "n_params", "both agree"),
            ("reward weights: goal dist, contact dist, no-contact fallback", NOT_STATED,
             "B.4.2 (unweighted positive norms)", (3.0, 2.0, 5.0),
             _MJ + "hopper_jump/hopper_jump.py" + _FACTS.format("§1.4"),
             _consts("hopper_jump", "GOAL_WEIGHT", "CONTACT_WEIGHT", "NO_CONTACT_DISTANCE"),
             "code (the thesis's signs reward distance)"),
        ],
    ),
    *_rows(
        "box-pushing-obstacle",
        "Fig. 4.4b, 4.5",
        [
            ("context box [low; high] (x_g, y_g, φ_g, x_o, y_o)",
             [[0.3, -0.7, 0, 0.3, -0.3], [0.6, 0.45, 2 * math.pi, 0.6, 0.15]], "B.4.2.1",
             [[0.3, -0.7, 0, 0.3, -0.3], [0.6, 0.45, 2 * math.pi, 0.6, 0.15]],
             _MJ + "box_pushing/box_pushing_obstacle_env.py" + _FACTS.format("§1.5"), _box,
             "both agree"),
            ("obstacle–goal distance rule", "Euclidean distance >= 0.15", "B.4.2.1",
             "y-distance >= 0.15",
             _MJ + "box_pushing/box_pushing_obstacle_env.py" + _FACTS.format("§1.5"),
             _bpo_distance_rule,
             "code (settings=\"thesis\" gives B.4.2.1's Euclidean distances)"),
            ("control dt (s)", NOT_STATED, "B.4.2.1 gives none", 0.02,
             _MJ + "box_pushing/box_pushing_env.py frame_skip 10 × 0.002" + _FACTS.format("§1.5"),
             _mp("dt"), _CODE),
            ("horizon (control steps)", NOT_STATED, "B.4.2.1 gives none", 100,
             _FG + " l.244-261 MAX_EPISODE_STEPS_BOX_PUSHING", _mp("n_steps"), _CODE),
            ("basis functions per joint", 4, "B.4.2.1", 4, _REG + " l.138", _mp("n_basis"),
             "both agree"),
            ("basis alpha", NOT_STATED, "B.4.2.1 gives none", 10.0, _FG + " l.92 (default dict)",
             _mp("alpha"), _CODE),
            ("alpha_phase", NOT_STATED, "B.4.2.1 gives none", 3.0, _REG + " l.140",
             _mp("alpha_phase"), _CODE),
            ("basis bandwidth factor", NOT_STATED, "B.4.2.1 gives none", 3.0, _REG + " l.139",
             _mp("bandwidth_factor"), _CODE),
            ("τ (fixed)", NOT_STATED, "B.4.2.1 gives none", 1.5, _FG + " l.83 (default dict)",
             _mp("tau"), _CODE),
            ("goal mode", "disabled", "B.4.2.1 (28 = 7·4)", "learned",
             _REG + " l.141-142 (disable_goal False, relative_goal False)", _mp("goal"),
             "code (settings=\"thesis\" gives B.4.2.1's disabled goal)"),
            ("weights_scale", NOT_STATED, "B.4.2.1 gives none", 0.3,
             _REG + " l.131 (the 0.8 of l.118 is overwritten)", _mp("weights_scale"), _CODE),
            ("parameters θ", 28, "B.4.2.1", 35, _REG + " l.138-142 (7·4 + 7 goals)", "n_params",
             "code (settings=\"thesis\" gives B.4.2.1's 28)"),
            ("reward: weight of box–rod distance, of ‖q̇_T‖", (1.0, 0.0), "B.4.2.1", (2.0, 50.0),
             _MJ + "box_pushing/box_pushing_obstacle_env.py BoxPushingObstacleTemporalSparse" + _FACTS.format("§1.5"),  # noqa: E501
             _bpo_reward, "code (settings=\"thesis\" gives B.4.2.1's R_tot)"),
            ("reward: rod tilt cost per step below π/4", 0.25,
             "B.4.2.1 (R_rod_rotation clipped at 0.25)", 0.0,
             _MJ + "box_pushing/box_pushing_obstacle_env.py BoxPushingObstacleTemporalSparse" + _FACTS.format("§1.5"),  # noqa: E501
             _bpo_tilt_cost, "code (settings=\"thesis\" gives B.4.2.1's R_tot)"),
            ("θ outside joint limits rejected unsimulated", NOT_STATED, "B.4.2.1 gives none",
             False,
             _MJ + "box_pushing/box_pushing_obstacle_env.py (no validity check)" + _FACTS.format("§1.5"),  # noqa: E501
             "joint_limit_check",
             "code (settings=\"thesis\" rejects them: asked of this re-implementation)"),
            ("success: position (m), rotation (rad)", (0.05, 0.5), "B.4.2.1", (0.05, 0.5),
             _MJ + "box_pushing/box_pushing_obstacle_env.py" + _FACTS.format("§1.5"),
             _consts("box_pushing", "SUCCESS_POS", "SUCCESS_ROT"), "both agree"),
        ],
    ),
    *_rows(
        "mini-golf",
        "Fig. 4.4d",
        [
            ("context box [low; high] (x_obs, y_obs, x_ball, x_goal)",
             [[0.3, -0.5, 0.25, 0.25], [0.6, -0.1, 0.6, 0.6]], "B.4.4",
             [[0.3, -0.5, 0.25, 0.18], [0.6, -0.1, 0.6, 0.67]],
             _MJ + "mini_golf/mini_golf_env.py MiniGolfOneObsEnv" + _FACTS.format("§1.6"), _box,
             "code (settings=\"thesis\" gives B.4.4's [0.25, 0.6])"),
            ("control dt (s)", NOT_STATED, "B.4.4 gives none", 0.02,
             _MJ + "mini_golf/mini_golf_env.py" + _FACTS.format("§1.6"), _mp("dt"), _CODE),
            ("horizon (control steps)", NOT_STATED, "B.4.4 gives none", 100,
             _FG + " l.309-321 MAX_EPISODE_STEPS_MINI_GOLF", _mp("n_steps"), _CODE),
            ("basis functions per joint", 4, "B.4.4", 4, _REG + " l.205", _mp("n_basis"),
             "both agree"),
            ("basis alpha", NOT_STATED, "B.4.4 gives none", 25.0, _REG + " l.206", _mp("alpha"),
             _CODE),
            ("alpha_phase", NOT_STATED, "B.4.4 gives none", 3.0, _REG + " l.208",
             _mp("alpha_phase"), _CODE),
            ("basis bandwidth factor", NOT_STATED, "B.4.4 gives none", 3.0, _REG + " l.207",
             _mp("bandwidth_factor"), _CODE),
            ("τ bounds (learned)", NOT_STATED, "B.4.4 gives none", (0.45, 1.7),
             _REG + " l.202-203", _mp("tau_bounds"), _CODE),
            ("delay learned", NOT_STATED, "B.4.4 gives none", None,
             _REG + " l.204 (learn_delay False)", _mp("delay_bounds"), _CODE),
            ("goal mode", "disabled", "B.4.4 (29 = 1 + 7·4)", "disabled", _REG + " l.200-201",
             _mp("goal"), "both agree"),
            ("weights_scale", NOT_STATED, "B.4.4 gives none", 0.3, _REG + " l.198",
             _mp("weights_scale"), _CODE),
            ("parameters θ", 29, "B.4.4", 29, _REG + " l.200-205", "n_params", "both agree"),
            ("reward variant (touched, not passed)", "thesis", "B.4.4 case 3", "code",
             _MJ + "mini_golf/mini_golf_env.py" + _FACTS.format("§1.6"), "reward",
             "code (made Fig. 4.4d); reward='thesis' is the text's"),
            ("invalid θ: scale, offset, τ weight", (20.0, -5.0, 3.0), "B.4.4", (20.0, -5.0, 3.0),
             _MJ + "mini_golf/mini_golf_env.py" + _FACTS.format("§1.6"),
             _consts("mini_golf", "INVALID_SCALE", "INVALID_OFFSET", "INVALID_TAU_WEIGHT"),
             "both agree"),
        ],
    ),
    *_rows(
        "reacher5",
        "Fig. 4.2, 4.3c",
        [
            ("goal disk radius (m)", 0.5, "B.4.3", 0.5,
             _DS + "diskill/contextual_envs/gym_wrappers/" "contextual_reacher.py" + _FACTS.format("§1.7"),  # noqa: E501
             lambda t: float(t.context_high[0]), "both agree"),
            ("start posture q0", [0, 0, 0, 0, 0], "B.4.3 ('straight to the right')",
             [0, 0, 0, 0, 0], _MJ + "reacher/reacher.py" + _FACTS.format("§1.7"), "q0",
             "both agree"),
            ("control dt (s)", NOT_STATED, "B.4.3 gives none", 0.02,
             _MJ + "reacher/reacher.py frame_skip 2 × 0.01" + _FACTS.format("§1.7"), _mp("dt"),
             _CODE),
            ("horizon (control steps)", NOT_STATED, "B.4.3 gives none", 200,
             _FG + " l.156 MAX_EPISODE_STEPS_REACHER", _mp("n_steps"), _CODE),
            ("basis functions per joint", 5, "B.4.3", 5, _REG + " l.57", _mp("n_basis"),
             "both agree"),
            ("basis alpha", NOT_STATED, "B.4.3 gives none", 10.0, _FG + " l.92 (default dict)",
             _mp("alpha"), _CODE),
            ("alpha_phase", NOT_STATED, "B.4.3 gives none", 3.0, _REG + " l.59",
             _mp("alpha_phase"), _CODE),
            ("basis bandwidth factor", NOT_STATED, "B.4.3 gives none", 3.0, _REG + " l.58",
             _mp("bandwidth_factor"), _CODE),
            ("τ (fixed)", NOT_STATED, "B.4.3 gives none", 1.5, _FG + " l.83 (default dict)",
             _mp("tau"), _CODE),
            ("goal mode", "disabled", "B.4.3 (25 = 5·5)", "relative", _REG + " l.60-61",
             _mp("goal"), "code (far goals unreachable without it); goal_params=False: thesis"),
            ("weights_scale, goal_scale", NOT_STATED, "B.4.3 gives none", (0.3, 0.3),
             _REG + " l.54-55", lambda t: (t.spec.weights_scale, t.spec.goal_scale), _CODE),
            ("parameters θ", 25, "B.4.3", 30, _REG + " l.57-61 (5·5 + 5 goals)", "n_params",
             "code (see goal mode)"),
        ],
    ),
    *_rows(
        "reacher5-ch3",
        "Fig. 3.5",
        [
            ("context box [low; high] (right half disk)", [[0, -0.5], [0.5, 0.5]],
             "Sec. 3.4.3, A.3.3", NOT_FOUND, NOT_FOUND, _box,
             "thesis (no public code for this variant)"),
            ("start posture q0", [math.pi, 0, 0, 0, 0], "Sec. 3.4.3 (pointing left)", NOT_FOUND,
             NOT_FOUND, "q0", "thesis"),
            ("primitive", "ProMP", "Sec. 3.4.3", NOT_FOUND, NOT_FOUND, _primitive,
             "thesis (basis count ours: 5)"),
            ("out-of-range context factor (Eqs. 3.8, 3.9 / 3.10)", (1000.0, 1000.0, 50000.0),
             "A.3.3", NOT_FOUND, NOT_FOUND,
             lambda t: tuple(importlib.import_module("vslbook.envs.robot.reacher5").CH3_CONTEXT_FACTOR[k] for k in ("3.8", "3.9", "3.10") ),  # noqa: E501
             "thesis"),
        ],
    ),
    *_rows(
        "beer-pong",
        "Fig. 3.2a, c, e, f, g",
        [
            ("context box [low; high] (cup x, y)", [[-0.32, -2.2], [0.32, -1.2]], "A.3.2",
             [[-0.32, -2.2], [0.32, -1.2]],
             _SV + "contextual_environments/mujoco/beerpong.py l.12-17", _box, "both agree"),
            ("simulation dt (s)", NOT_STATED, "A.3.2 gives none", 0.005,
             _SV + "contextual_environments/mujoco/beerpong.py l.36", _const("beer_pong", "DT"),
             _CODE),
            ("parameters θ (duration + 2 weights × 7)", NOT_STATED,
             "Sec. 3.4 ('weights and length')", 15,
             _SV + "contextual_environments/mujoco/beerpong.py l.18", "n_params", _CODE),
            ("weights_scale", NOT_STATED, "A.3.2 gives none", math.sqrt(0.02),
             _SV + "contextual_environments/mujoco/beerpong.py l.96, 102", "weights_scale", _CODE),
            ("duration bounds (s)", (0.1, 1.3), "A.3.2", (0.1, 1.3),
             _SV + "contextual_environments/mujoco/beerpong.py l.97-100",
             _const("beer_pong", "DURATION_BOUNDS"), "both agree"),
            ("steps after release", NOT_STATED, "A.3.2 gives none", 500,
             _SV + "contextual_environments/mujoco/beerpong.py l.252", "extra_steps", _CODE),
            ("PD gains K_p", NOT_STATED, "A.3.2 gives none", [200, 300, 100, 100, 10, 10, 2.5],
             _SV + "contextual_environments/mujoco/beerpong.py l.35",
             _const("beer_pong", "P_GAINS"), _CODE),
            ("reward variant ('in the cup', 'contact')", "thesis", "A.3.2", "code",
             _SV + "contextual_environments/mujoco/beerpong.py l.297-319", "reward",
             "code (made Fig. 3.2); reward='thesis' is the text's"),
            ("invalid θ penalty (joint limits)", -30.0, "A.3.2", -30.0,
             _SV + "contextual_environments/mujoco/beerpong.py l.106",
             _const("beer_pong", "INVALID_PENALTY"), "both agree"),
        ],
    ),
    *_rows(
        "table-tennis-ch3",
        "Fig. 3.2b, d, 3.3",
        [
            ("context box [low; high] (x_des, y_des, x_inc, y_inc)",
             [[-1.2, -0.6, -1.2, -0.65], [-0.2, 0.6, -0.2, 0.65]], "A.3.3",
             [[-1.2, -0.6, -1.2, -0.65], [-0.2, 0.6, -0.2, 0.65]],
             _SV + "contextual_environments/mujoco/table_tennis_multi.py l.10-11", _box,
             "both agree"),
            ("parameters θ (duration + 3 weights × 7)", NOT_STATED, "Sec. 3.4.2", 22,
             _SV + "contextual_environments/mujoco/table_tennis_multi.py l.17", "n_params", _CODE),
            ("primitive", "ProMP", "Sec. 3.4.2", "ProMP blended from q0 by a sigmoid",
             _SV + "util/table_tennis/trajectory/sigmoid_promp_trajectory.py", _primitive,
             "ours: ProMP offset to start at q0 (the Ch. 4 simulation is shared)"),
            ("duration bounds (s)", (0.1, 5.0), "A.3.3", (0.1, 5.0),
             _SV + "contextual_environments/mujoco/table_tennis_multi.py" + _FACTS.format("§1.1"),
             _const("table_tennis_ch3", "DURATION_BOUNDS"), "both agree"),
            ("context out-of-range punishment", *_tt3("CONTEXT", "129-135 (check_valid l.100)"),
             probe.tt3_context_punishment, _TT3_WHY),
            ("duration punishment (l outside [0.1, 5] s, b the bound)",
             *_tt3("DURATION", "137-151"), probe.tt3_duration_punishment, _TT3_WHY),
            ("joint-limit punishment (planned q_d outside the joint box)",
             *_tt3("JOINTS", "156-183"), probe.tt3_joint_punishment, _TT3_WHY),
            ("serve vertical speed v_z (m/s)", NOT_STATED, "A.3.3 gives none", 1.0,
             _SV + "contextual_environments/mujoco/table_tennis_multi.py" + _FACTS.format("§1.1"),
             _const("table_tennis", "BALL_VZ"),
             "Ch. 4 serve (v_z = 1 rejects most of the thesis's box)"),
            ("actuation", NOT_STATED, "A.3.3 gives none", "position actuators",
             _SV + "contextual_environments/mujoco/table_tennis/right_arm_actuator.xml" + _FACTS.format("§1.1"),  # noqa: E501
             lambda t: "motors, PD law (fancy-gym model)", "ours: the Ch. 4 model and PD law"),
        ],
    ),
    *_rows(
        "planar-reacher",
        "Fig. 3.1",
        [
            ("context box [low; high] (target x, y)", [[4.5, -6], [7, 6]], "A.3.1",
             [[4.5, -6], [7, 6]],
             _SV + "contextual_environments/PlanarRobotObstacle_2dim_ctxt.py create_env l.437-442",
             _box, "both agree"),
            ("obstacles [x_lo, x_hi, y_lo, y_hi]", NOT_STATED, "Fig. 3.1 (drawn only)",
             [[2.5, 3.3, -0.5, 0.5], [2.7, 3.5, -3.5, -2.5], [3.0, 3.8, 2.5, 3.5]],
             _SV + "contextual_environments/PlanarRobotObstacle_2dim_ctxt.py l.429-430",
             _const("planar_reacher", "OBSTACLES"), _CODE),
            ("joint penalty leaves out the base joint", False, "A.3.1 (−‖θ‖²)", True,
             _SV + "contextual_environments/PlanarRobotObstacle_2dim_ctxt.py l.245",
             "exclude_base_joint", "code (exclude_base_joint=False gives the thesis's)"),
            ("weights: distance, collision, context", (2.0, 3.0, 10.0), "A.3.1", (2.0, 3.0, 10.0),
             _SV + "contextual_environments/PlanarRobotObstacle_2dim_ctxt.py l.432-435",
             _consts("planar_reacher", "DISTANCE_WEIGHT", "COLLISION_COST", "CONTEXT_COST"),
             "both agree"),
        ],
    ),
]
# fmt: on
