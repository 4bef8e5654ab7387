"""The planar 10-link reacher with three obstacles (Section 3.4.1, Fig. 3.1, App. A.3.1).

The ablation task of Chapter 3 (SVSL's augmented rewards, Fig. 3.1). There is no simulator
and no movement primitive (A.3.1: "the sampled θ ... directly represent the angles of each
joint"): an episode is one evaluation of the forward kinematics, so the task is vectorised
over whole batches in numpy.

Kinematics:
    10 links of length 1 from the base (0, 0); θ ∈ ℝ¹⁰ are the joint angles (relative, so
    link i points along φ_i = θ_1 + … + θ_i) and the link end points are
    p_0 = (0, 0), p_i = Σ_{j≤i} (cos φ_j, sin φ_j); the tip is f(θ) = p_10 (:func:`link_points`).
    All zero ⇒ the arm lies straight along +x. The angles are first wrapped into [−π, π)
    ("the angles θ are always normalized into a range [−π, π]", A.3.1); this does not change
    f(θ), only the joint penalty below.

Context (2-D, A.3.1): the target c = (x, y), p(c) uniform on [4.5, 7] × [−6, 6]; no
    rejection rule.

Parameters: n_params = 10 (the joint angles), any finite values.

Obstacles (:data:`OBSTACLES`, axis-aligned rectangles [x_lo, x_hi] × [y_lo, y_hi], from the
    authors' code; the thesis only draws them in Fig. 3.1): [2.5, 3.3] × [−0.5, 0.5],
    [2.7, 3.5] × [−3.5, −2.5], [3.0, 3.8] × [2.5, 3.5]. A collision is any link segment
    p_{i−1}p_i meeting a closed rectangle (touching counts), computed exactly by slab
    clipping (:func:`segments_hit_rectangles`). The authors test the segments against the
    rectangles' edges; as the base lies outside every rectangle the chain must cross an edge
    to enter one, so both definitions agree.

Reward (A.3.1):
    R(θ, c) = −‖wrap(θ)‖² − 2‖f(θ) − c‖² − l_c(c) − l_o(θ),
    l_c(c) = 10 if c ∉ C else 0,   l_o(θ) = 3 if any link collides else 0.
    ⚠ The authors' code leaves the first (base) joint out of the joint penalty
    (−‖wrap(θ_2:10)‖²). The code drew Fig. 3.1, so that is the default
    (``exclude_base_joint=True``); ``exclude_base_joint=False`` gives the thesis's −‖θ‖².

Contexts outside C (SVSL's context Gaussians can sample them): unlike the simulated tasks,
    where the base class gives such a context only a penalty and does not run it, here the
    thesis's rule is that the punishment l_c = 10 is *added* to the full reward and the
    kinematics are still evaluated. :meth:`PlanarReacherTask.evaluate` is overridden for that
    (``out_of_range="penalise"``): such episodes get R(θ, c) with l_c = 10 and count as
    executed (the episode was evaluated; there is no simulator step to save).
    :meth:`PlanarReacherTask.context_penalty` returns l_c alone (−10 outside, 0 inside).

Success: the thesis defines none for this task (it speaks of "precise" solutions, a small
    tip-to-target distance, and valid ones, without a threshold), so ``has_success`` is False
    and each episode reports ``tip_distance`` = ‖f(θ) − c‖ and ``collision`` (0/1) instead,
    with the tip position and the joint cost.

Evaluation: ``evaluate`` runs in this process and is vectorised (about 2–3·10⁵ episodes/s
    on one core for large batches); here ``workers=None`` means in-process (not the machine's
    cores as in the base class), since a worker pool only adds pickling overhead. An explicit
    ``workers`` > 1 still spreads the batch over the base class's pool, with the same numbers.
"""

from __future__ import annotations

from typing import Any, ClassVar

import numpy as np

from vslbook.envs.robot.task import Episode, EpisodicTask, Rollouts, resolve_workers

#: Number of links (and joints) of the arm.
N_LINKS = 10
#: Length of every link.
LINK_LENGTH = 1.0
#: The obstacles as rows [x_lo, x_hi, y_lo, y_hi] (axis-aligned rectangles).
OBSTACLES = np.array(
    [
        [2.5, 3.3, -0.5, 0.5],
        [2.7, 3.5, -3.5, -2.5],
        [3.0, 3.8, 2.5, 3.5],
    ]
)
OBSTACLES.setflags(write=False)

#: Cost of a context outside the context box (l_c, A.3.1).
CONTEXT_COST = 10.0
#: Cost of a collision of any link with an obstacle (l_o, A.3.1).
COLLISION_COST = 3.0
#: Weight of the squared tip-to-target distance (A.3.1).
DISTANCE_WEIGHT = 2.0

_TINY = 5e-324  # the smallest subnormal float64


def wrap_angles(theta: np.ndarray) -> np.ndarray:
    """Angles wrapped into [−π, π)."""
    return np.mod(np.asarray(theta, dtype=np.float64) + np.pi, 2 * np.pi) - np.pi


def link_points(theta: Any) -> np.ndarray:
    """Base and link end points ``(..., 11, 2)`` of joint angles ``theta`` ``(..., 10)``.

    Row 0 is the base (0, 0), row 10 the tip f(θ). For plotting (Fig. 3.1) and the reward.
    """
    th = np.asarray(theta, dtype=np.float64)
    if th.ndim < 1 or th.shape[-1] != N_LINKS:
        raise ValueError(f"theta must have shape (..., {N_LINKS}), got {th.shape}")
    return _chain(wrap_angles(th))


def _chain(wrapped: np.ndarray) -> np.ndarray:
    phi = np.cumsum(wrapped, axis=-1)
    pts = np.zeros(wrapped.shape[:-1] + (N_LINKS + 1, 2))
    np.cumsum(LINK_LENGTH * np.cos(phi), axis=-1, out=pts[..., 1:, 0])
    np.cumsum(LINK_LENGTH * np.sin(phi), axis=-1, out=pts[..., 1:, 1])
    return pts


def segments_hit_rectangles(
    start: np.ndarray, end: np.ndarray, rects: np.ndarray = OBSTACLES
) -> np.ndarray:
    """Whether each segment meets each closed axis-aligned rectangle.

    Args:
        start, end: segment end points ``(..., 2)``.
        rects: rows [x_lo, x_hi, y_lo, y_hi], shape ``(m, 4)``.

    Returns:
        Boolean ``(..., m)``. Slab clipping (Liang–Barsky): the segment s(t) = a + t(b − a),
        t ∈ [0, 1], meets the rectangle iff the t-intervals inside both slabs overlap
        within [0, 1]. The slabs are widened by the smallest subnormal number (which
        changes no difference of two coordinates that is not exactly zero): a point lying
        on a side then counts as inside, and a zero direction component gives the slab
        (−∞, ∞) or the empty set through 1/0 = ±∞ without 0·∞.
    """
    a = np.asarray(start, dtype=np.float64)[..., None, :]
    d = np.asarray(end, dtype=np.float64)[..., None, :] - a
    r = np.asarray(rects, dtype=np.float64)
    with np.errstate(divide="ignore", over="ignore"):
        inv = 1.0 / d
        t_lo_x = (r[:, 0] - a[..., 0] - _TINY) * inv[..., 0]
        t_hi_x = (r[:, 1] - a[..., 0] + _TINY) * inv[..., 0]
        t_lo_y = (r[:, 2] - a[..., 1] - _TINY) * inv[..., 1]
        t_hi_y = (r[:, 3] - a[..., 1] + _TINY) * inv[..., 1]
    enter = np.maximum(np.minimum(t_lo_x, t_hi_x), np.minimum(t_lo_y, t_hi_y))
    leave = np.minimum(np.maximum(t_lo_x, t_hi_x), np.maximum(t_lo_y, t_hi_y))
    np.maximum(enter, 0.0, out=enter)
    np.minimum(leave, 1.0, out=leave)
    return enter <= leave


class PlanarReacherTask(EpisodicTask):
    """The 10-link planar reacher with obstacles; see the module docstring.

    Args:
        exclude_base_joint: leave the first joint out of the joint penalty, as the
            authors' code does (default True; False: the thesis's −‖θ‖², A.3.1).
    """

    name: ClassVar[str] = "planar-reacher"
    context_names: ClassVar[tuple[str, ...]] = ("x", "y")
    context_low: ClassVar[np.ndarray] = np.array([4.5, -6.0])
    context_high: ClassVar[np.ndarray] = np.array([7.0, 6.0])
    n_params: ClassVar[int] = N_LINKS
    info_keys: ClassVar[tuple[str, ...]] = (
        "tip_distance",
        "collision",
        "tip_x",
        "tip_y",
        "joint_cost",
    )
    has_success: ClassVar[bool] = False

    def __init__(self, exclude_base_joint: bool = True, **kwargs: Any) -> None:
        if not isinstance(exclude_base_joint, (bool, np.bool_)):
            raise TypeError(f"exclude_base_joint must be a bool, got {exclude_base_joint!r}")
        super().__init__(exclude_base_joint=bool(exclude_base_joint), **kwargs)
        self.exclude_base_joint = bool(exclude_base_joint)

    # -- reward -------------------------------------------------------------------------
    def context_penalty(self, contexts: np.ndarray) -> np.ndarray:
        """l_c(c) as a return: −10 for a context outside C, 0 inside (A.3.1)."""
        c = np.asarray(contexts, dtype=np.float64)
        return np.where(self.context_valid(c), 0.0, -CONTEXT_COST)

    def compute(self, theta: np.ndarray, contexts: np.ndarray) -> dict[str, np.ndarray]:
        """The reward and its parts for checked ``(n, 10)`` θ and ``(n, 2)`` contexts.

        Returns arrays of length n: ``return``, ``tip_distance``, ``collision`` (bool),
        ``tip_x``, ``tip_y``, ``joint_cost``, ``context_outside`` (bool).
        """
        wrapped = wrap_angles(theta)
        pts = _chain(wrapped)
        tip = pts[:, -1]
        hits = segments_hit_rectangles(pts[:, :-1], pts[:, 1:])
        collision = hits.reshape(len(hits), -1).any(axis=1)
        joints = wrapped[:, 1:] if self.exclude_base_joint else wrapped
        joint_cost = np.einsum("ij,ij->i", joints, joints)
        diff = tip - contexts
        dist2 = np.einsum("ij,ij->i", diff, diff)
        outside = ~self.context_valid(contexts)
        ret = (
            -joint_cost
            - DISTANCE_WEIGHT * dist2
            - CONTEXT_COST * outside
            - COLLISION_COST * collision
        )
        return {
            "return": ret,
            "tip_distance": np.sqrt(dist2),
            "collision": collision,
            "tip_x": tip[:, 0].copy(),
            "tip_y": tip[:, 1].copy(),
            "joint_cost": joint_cost,
            "context_outside": outside,
        }

    # -- episodes -----------------------------------------------------------------------
    def path(self, theta: Any, context: Any) -> dict[str, np.ndarray]:
        """Not available: an episode is one pose, not a movement (the arm's link end points
        are :func:`link_points`)."""
        raise NotImplementedError(
            f"{self.name}: records no path over an episode (the task is kinematic: an episode "
            "is one pose; link_points(theta) gives the arm)"
        )

    def episode(self, theta: np.ndarray, context: np.ndarray) -> Episode:
        return self.episodes(np.asarray(theta)[None], np.asarray(context)[None])[0]

    def episodes(self, theta: np.ndarray, contexts: np.ndarray) -> list[Episode]:
        """A batch as :class:`Episode` objects (vectorised; contexts outside C get l_c)."""
        th = self.check_theta(theta)
        c = self.check_contexts(contexts, allow_invalid=True)
        if len(th) != len(c):
            raise ValueError(f"{self.name}: {len(th)} parameter vectors for {len(c)} contexts")
        out = self.compute(th, c)
        info = np.stack([np.asarray(out[k], dtype=np.float64) for k in self.info_keys], axis=1)
        return [
            Episode(float(r), False, True, dict(zip(self.info_keys, row.tolist(), strict=True)))
            for r, row in zip(out["return"].tolist(), info, strict=True)
        ]

    def evaluate(
        self,
        theta: Any,
        contexts: Any,
        *,
        workers: int | None = None,
        out_of_range: str = "error",
    ) -> Rollouts:
        """Returns and info for a batch of (θ, c) pairs, vectorised in this process.

        As :meth:`EpisodicTask.evaluate`, except that ``workers=None`` (the default) means
        this process, and that with ``out_of_range="penalise"`` a context outside C is still
        evaluated, with l_c = 10 subtracted (A.3.1), and counts as executed.
        """
        th, c = self.check_batch(theta, contexts, out_of_range)
        n_workers = 1 if workers is None else resolve_workers(workers)
        if n_workers > 1 and len(th) > 1:
            return Rollouts.from_episodes(self._run(th, c, n_workers), self.info_keys)
        out = self.compute(th, c)
        return Rollouts(
            returns=out["return"],
            success=np.zeros(len(th), dtype=bool),
            executed=np.ones(len(th), dtype=bool),
            info={k: np.asarray(out[k], dtype=np.float64) for k in self.info_keys},
        )
