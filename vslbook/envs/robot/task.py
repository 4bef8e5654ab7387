"""The episodic (black-box) task interface shared by every robot task of Chapters 3 and 4.

One episode maps a parameter vector θ and a context c to a return R(θ, c) (Eq. 2.27):

    θ → movement primitive trajectory (``vslbook.movement``)
      → validity check *before* simulation (an invalid θ gets the task's penalty, is not
        simulated and is not counted as an executed sample)
      → PD tracking in the simulator → episode → reward.

A task implements :meth:`EpisodicTask.episode` for one (θ, c); the base class adds the
context distribution p(c) with its rejection rules (:meth:`EpisodicTask.sample_contexts`),
input checks with clear errors, and batched evaluation (:meth:`EpisodicTask.evaluate`)
through a pool of worker processes, each holding its own simulator. Episodes are
deterministic given (θ, c), so a batch gives the same numbers with any number of workers.

:meth:`EpisodicTask.path` replays one episode and returns the world positions of the
task's moving points (the ball, the box, the fingertip, ...) over it, recorded by the very
simulation loop :meth:`EpisodicTask.episode` runs (a :class:`PathRecorder` the loop calls
once at the start and after every control step; it is off for ordinary episodes).

:class:`EpisodicEnv` wraps a task as a one-step gymnasium environment (observation = c,
action = θ), the form used by ``gym.make``; it and the reset/step input helpers of the
step-based environments are in :mod:`vslbook.envs.robot.gym_env` and re-exported here.
"""

from __future__ import annotations

import math
import os
import signal
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np

from vslbook.envs.robot.gym_env import (  # noqa: F401  (re-exported; they live in gym_env)
    EpisodicEnv,
    check_action,
    context_from_options,
)


@dataclass
class Episode:
    """What one episode returns.

    Attributes:
        ret: the episode return R(θ, c) (sum of step rewards, or the penalty).
        success: the task's success flag (False for tasks without one).
        executed: False when θ was rejected before simulation (or c was out of range and
            penalised without simulation): such an episode is not an executed sample.
        info: per-episode numbers (floats), the same keys for every episode of a task
            (see :attr:`EpisodicTask.info_keys`); NaN where a number does not apply.
    """

    ret: float
    success: bool = False
    executed: bool = True
    info: dict[str, float] = field(default_factory=dict)


@dataclass
class Rollouts:
    """A batch of episodes: arrays of length n, in the order of the inputs."""

    returns: np.ndarray
    success: np.ndarray
    executed: np.ndarray
    info: dict[str, np.ndarray]

    @property
    def n_executed(self) -> int:
        """Episodes actually simulated (invalid θ are not counted as samples)."""
        return int(self.executed.sum())

    @property
    def n_rejected(self) -> int:
        """Episodes given the penalty without simulation."""
        return int((~self.executed).sum())

    @classmethod
    def from_episodes(cls, episodes: list[Episode], info_keys: tuple[str, ...]) -> Rollouts:
        return cls(
            returns=np.array([e.ret for e in episodes], dtype=np.float64),
            success=np.array([e.success for e in episodes], dtype=bool),
            executed=np.array([e.executed for e in episodes], dtype=bool),
            info={
                k: np.array([e.info.get(k, math.nan) for e in episodes], dtype=np.float64)
                for k in info_keys
            },
        )


class PathRecorder:
    """Collects world positions of named points from a simulation loop.

    The loop calls ``recorder(ball=xyz, ...)`` once at the start and after every control
    step; :meth:`paths` stacks each name's points into a ``(T, 3)`` float64 array.
    """

    def __init__(self) -> None:
        self._points: dict[str, list[np.ndarray]] = {}

    def __call__(self, **points: np.ndarray) -> None:
        for name, xyz in points.items():
            self._points.setdefault(name, []).append(np.array(xyz, dtype=np.float64))

    def paths(self) -> dict[str, np.ndarray]:
        """name → ``(T, 3)`` positions, in the order they were recorded."""
        return {k: np.asarray(v, dtype=np.float64).reshape(-1, 3) for k, v in self._points.items()}


def _options(cls: type) -> set[str]:
    """The keyword arguments a task class takes: the named parameters of the ``__init__``
    of every class along its MRO (a subclass passes its own on to this base)."""
    import inspect

    named = (inspect.Parameter.POSITIONAL_OR_KEYWORD, inspect.Parameter.KEYWORD_ONLY)
    inits = [k.__dict__["__init__"] for k in cls.__mro__ if "__init__" in k.__dict__]
    return {p.name for init in inits for p in inspect.signature(init).parameters.values()
            if p.name != "self" and p.kind in named}  # fmt: skip


class EpisodicTask:
    """Base class: subclasses set the class attributes and implement :meth:`episode`.

    Class attributes:
        name: short name (``make_task`` key).
        context_names: names of the context dimensions, in the thesis's order.
        context_low, context_high: the box that holds p(c)'s support.
        n_params: dimension of θ.
        info_keys: keys of :attr:`Episode.info`.
        has_success: whether the task defines success.
        path_names: the points :meth:`path` records (empty: the task records none).

    Subclasses may override :meth:`context_valid` (rejection rules beyond the box),
    :meth:`sample_contexts` (a distribution that is not uniform-with-rejection) and
    :meth:`context_penalty` (the punishment SVSL gives to contexts outside the range).
    Constructor keyword arguments must be picklable: workers rebuild the task from them.
    """

    name: ClassVar[str] = ""
    context_names: ClassVar[tuple[str, ...]] = ()
    context_low: ClassVar[np.ndarray]
    context_high: ClassVar[np.ndarray]
    n_params: ClassVar[int] = 0
    info_keys: ClassVar[tuple[str, ...]] = ()
    has_success: ClassVar[bool] = True
    path_names: ClassVar[tuple[str, ...]] = ()
    #: Set only while :meth:`path` runs: the simulation loop hands it the path points.
    _recorder: PathRecorder | None = None

    def __init__(self, **kwargs: Any) -> None:
        known = _options(type(self))
        unknown = sorted(set(kwargs) - known)
        if unknown:
            raise ValueError(
                f"{type(self).__name__} has no option {', '.join(map(repr, unknown))}; "
                f"expected some of {', '.join(sorted(known)) or '(none)'}"
            )
        self._kwargs = dict(kwargs)
        self._pool: ProcessPoolExecutor | None = None
        self._pool_size = 0

    # -- contexts -----------------------------------------------------------------------
    @property
    def context_dim(self) -> int:
        return len(self.context_names)

    def context_valid(self, contexts: np.ndarray) -> np.ndarray:
        """Boolean mask: inside the box and passing the task's rejection rules."""
        c = np.asarray(contexts, dtype=np.float64)
        return np.all((c >= self.context_low) & (c <= self.context_high), axis=-1)

    def sample_contexts(self, n: int, rng: np.random.Generator) -> np.ndarray:
        """``n`` contexts from p(c): uniform on the box, rejecting invalid draws."""
        n = _check_count("n", n)
        if not isinstance(rng, np.random.Generator):
            raise TypeError(f"rng must be a numpy Generator, got {type(rng).__name__}")
        out = np.empty((0, self.context_dim))
        for _ in range(1000):
            draw = rng.uniform(
                self.context_low, self.context_high, (max(2 * n, 16), self.context_dim)
            )
            out = np.concatenate([out, draw[self.context_valid(draw)]])
            if len(out) >= n:
                return out[:n]
        raise RuntimeError(f"{self.name}: rejection sampling found only {len(out)} of {n} contexts")

    def context_penalty(self, contexts: np.ndarray) -> np.ndarray:
        """Return given to a context outside the valid range (default: −(distance to the box)²)."""
        c = np.asarray(contexts, dtype=np.float64)
        excess = np.maximum(self.context_low - c, 0) + np.maximum(c - self.context_high, 0)
        return -np.sum(excess**2, axis=-1)

    def check_contexts(self, contexts: Any, *, allow_invalid: bool = False) -> np.ndarray:
        """``contexts`` as an ``(n, d)`` float array, or a clear error naming what is wrong."""
        c = np.asarray(contexts, dtype=np.float64)
        if c.ndim == 1:
            c = c[None]
        if c.ndim != 2 or c.shape[1] != self.context_dim:
            raise ValueError(
                f"{self.name}: contexts must have shape (n, {self.context_dim}) "
                f"({', '.join(self.context_names)}), got shape {np.shape(contexts)}"
            )
        if not np.all(np.isfinite(c)):
            raise ValueError(f"{self.name}: contexts must be finite, got {c[~np.isfinite(c)][:3]}")
        if not allow_invalid:
            bad = ~self.context_valid(c)
            if bad.any():
                i = int(np.argmax(bad))
                raise ValueError(
                    f"{self.name}: context {c[i].tolist()} (row {i}) is outside the task's "
                    f"context space: {self.describe_contexts()}"
                )
        return c

    def describe_contexts(self) -> str:
        """One line: each context dimension with its range (and the rejection rules)."""
        parts = [
            f"{n} in [{lo:g}, {hi:g}]"
            for n, lo, hi in zip(
                self.context_names, self.context_low, self.context_high, strict=True
            )
        ]
        return "; ".join(parts)

    def check_theta(self, theta: Any, n: int | None = None) -> np.ndarray:
        """``theta`` as an ``(n, n_params)`` float array, or a clear error."""
        th = np.asarray(theta, dtype=np.float64)
        if th.ndim == 1:
            th = th[None]
        if th.ndim != 2 or th.shape[1] != self.n_params or (n is not None and th.shape[0] != n):
            want = f"({n if n is not None else 'n'}, {self.n_params})"
            raise ValueError(f"{self.name}: theta must have shape {want}, got {np.shape(theta)}")
        if not np.all(np.isfinite(th)):
            raise ValueError(f"{self.name}: theta must be finite")
        return th

    # -- pictures -----------------------------------------------------------------------
    def scene(self, context: Any) -> tuple[Any, Any]:
        """The MuJoCo ``(model, data)`` at the start of an episode in ``context``, after a
        forward pass: what :func:`vslbook.envs.robot.render.render_scene` draws.

        Tasks simulated in MuJoCo override it; a task without a simulator (the planar
        reacher) has no scene.
        """
        raise NotImplementedError(f"{self.name}: no MuJoCo scene (the task is not simulated)")

    def path(self, theta: Any, context: Any) -> dict[str, np.ndarray]:
        """World positions of the task's moving points over one episode (θ, c).

        Runs :meth:`episode` once with a :class:`PathRecorder` switched on, so the points
        come from the simulation :meth:`evaluate` runs (same physics, same numbers). Returns
        name → ``(T, 3)`` float64 (metres, world frame), one row for the start state and one
        after every control step (the last one where the episode ended); the names are
        :attr:`path_names`. An invalid θ, which the task rejects before simulating, is a
        ``ValueError``; a task that records no path raises ``NotImplementedError``.
        """
        if not self.path_names:
            raise NotImplementedError(f"{self.name}: records no path over an episode")
        c = self.one_context(context)
        th = self.check_theta(theta, n=1)[0]
        recorder = PathRecorder()
        self._recorder = recorder
        try:
            ep = self.episode(th, c)
        finally:
            self._recorder = None
        if not ep.executed:
            raise ValueError(
                f"{self.name}: theta is invalid and was rejected before simulation (return "
                f"{ep.ret:g}): it has no path"
            )
        paths = recorder.paths()
        missing = set(self.path_names) - set(paths)
        if missing:  # pragma: no cover - a simulation loop that forgot to record
            raise RuntimeError(f"{self.name}: the simulation recorded no {sorted(missing)}")
        return {k: paths[k] for k in self.path_names}

    def one_context(self, context: Any) -> np.ndarray:
        """A single valid context ``(d,)``, or a clear error."""
        c = self.check_contexts(context)
        if len(c) != 1:
            raise ValueError(
                f"{self.name}: expected one context of shape ({self.context_dim},), "
                f"got {np.shape(context)}"
            )
        return c[0]

    # -- episodes -----------------------------------------------------------------------
    def episode_args(self, theta: Any, context: Any) -> tuple[np.ndarray, np.ndarray]:
        """One episode's ``theta`` (n_params,) and ``context`` (d,) as floats, or a clear error."""
        theta = np.asarray(theta, dtype=np.float64)
        context = np.asarray(context, dtype=np.float64)
        if theta.shape != (self.n_params,) or context.shape != (self.context_dim,):
            raise ValueError(
                f"{self.name}: theta must have shape ({self.n_params},) and context "
                f"({self.context_dim},), got {theta.shape} and {context.shape}"
            )
        return theta, context

    def episode(self, theta: np.ndarray, context: np.ndarray) -> Episode:
        """Run one episode for ``theta`` (n_params,) in ``context`` (d,)."""
        raise NotImplementedError

    def episodes(self, theta: np.ndarray, contexts: np.ndarray) -> list[Episode]:
        """Run a batch in this process (tasks without a simulator override it, vectorised)."""
        return [self.episode(t, c) for t, c in zip(theta, contexts, strict=True)]

    def evaluate(
        self,
        theta: Any,
        contexts: Any,
        *,
        workers: int | None = None,
        out_of_range: str = "error",
    ) -> Rollouts:
        """Returns, success and per-episode info for a batch of (θ, c) pairs.

        Args:
            theta: ``(n, n_params)`` (or one vector, broadcast to every context).
            contexts: ``(n, d)`` (or one context, broadcast to every θ).
            workers: processes to spread the batch over; ``None``: the machine's cores
                (``VSLBOOK_WORKERS`` overrides), 0 or 1: this process.
            out_of_range: ``"error"`` (a context outside the task's space is an error) or
                ``"penalise"``: such episodes get :meth:`context_penalty` and are not
                simulated (SVSL's punishment, Algorithm 1).
        """
        th, c = self.check_batch(theta, contexts, out_of_range)
        valid = self.context_valid(c)
        episodes: list[Episode | None] = [None] * len(c)
        for i in np.flatnonzero(~valid):
            pen = float(self.context_penalty(c[i]))
            episodes[i] = Episode(pen, False, False, {})
        idx = np.flatnonzero(valid)
        if len(idx):
            for i, ep in zip(idx, self._run(th[idx], c[idx], workers), strict=True):
                episodes[i] = ep
        return Rollouts.from_episodes(episodes, self.info_keys)  # type: ignore[arg-type]

    def check_batch(
        self, theta: Any, contexts: Any, out_of_range: str = "error"
    ) -> tuple[np.ndarray, np.ndarray]:
        """Checked ``(θ (n, n_params), c (n, d))``, a single θ or c broadcast to the other."""
        if out_of_range not in ("error", "penalise"):
            raise ValueError(f"out_of_range must be 'error' or 'penalise', got {out_of_range!r}")
        c = self.check_contexts(contexts, allow_invalid=out_of_range == "penalise")
        th = self.check_theta(theta)
        if len(th) == 1 and len(c) > 1:
            th = np.repeat(th, len(c), axis=0)
        if len(c) == 1 and len(th) > 1:
            c = np.repeat(c, len(th), axis=0)
        if len(th) != len(c):
            raise ValueError(f"{self.name}: {len(th)} parameter vectors for {len(c)} contexts")
        return th, c

    def _run(self, theta: np.ndarray, contexts: np.ndarray, workers: int | None) -> list[Episode]:
        n_workers = resolve_workers(workers)
        if n_workers <= 1 or len(theta) < 2:
            return self.episodes(theta, contexts)
        pool = self._get_pool(n_workers)
        chunks = np.array_split(np.arange(len(theta)), min(n_workers * 4, len(theta)))
        futures = [
            pool.submit(_worker_episodes, theta[ch], contexts[ch]) for ch in chunks if len(ch)
        ]
        return [ep for f in futures for ep in f.result()]

    def _get_pool(self, n_workers: int) -> ProcessPoolExecutor:
        if self._pool is None or self._pool_size != n_workers:
            self.close()
            import multiprocessing as mp

            self._pool = ProcessPoolExecutor(
                n_workers,
                mp_context=mp.get_context("forkserver"),
                initializer=_worker_init,
                initargs=(type(self), self._kwargs),
            )
            self._pool_size = n_workers
        return self._pool

    def close(self) -> None:
        """Shut the worker pool down (it is also shut down when the task is collected)."""
        if self._pool is not None:
            self._pool.shutdown(cancel_futures=True)
            self._pool = None

    def __del__(self) -> None:  # pragma: no cover - interpreter shutdown order varies
        try:
            self.close()
        except Exception:
            pass

    def __getstate__(self) -> dict[str, Any]:
        raise TypeError(f"{type(self).__name__} is rebuilt from its kwargs, not pickled")


def resolve_workers(workers: int | None) -> int:
    """``workers`` as a count: ``None`` → ``$VSLBOOK_WORKERS`` or the machine's cores."""
    if workers is None:
        env = os.environ.get("VSLBOOK_WORKERS", "").strip()
        if env:
            try:
                workers = int(env)
            except ValueError:
                raise ValueError(f"VSLBOOK_WORKERS must be an integer, got {env!r}") from None
        else:
            workers = (
                len(os.sched_getaffinity(0))
                if hasattr(os, "sched_getaffinity")
                else os.cpu_count() or 1
            )
    if isinstance(workers, bool) or not isinstance(workers, (int, np.integer)) or workers < 0:
        raise ValueError(f"workers must be an integer >= 0, got {workers!r}")
    return int(workers)


def _check_count(name: str, value: Any) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 1:
        raise ValueError(f"{name} must be an integer >= 1, got {value!r}")
    return int(value)


_WORKER_TASK: EpisodicTask | None = None


def _worker_init(cls: type[EpisodicTask], kwargs: dict[str, Any]) -> None:
    global _WORKER_TASK
    # Ctrl-C (or a Jupyter kernel's interrupt) goes to the whole process group: the parent
    # handles it and shuts the pool down; a worker that also raised would only print a
    # KeyboardInterrupt traceback per process.
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    try:
        import torch

        torch.set_num_threads(1)
    except ImportError:  # pragma: no cover
        pass
    _WORKER_TASK = cls(**kwargs)


def _worker_episodes(theta: np.ndarray, contexts: np.ndarray) -> list[Episode]:
    assert _WORKER_TASK is not None, "worker not initialised"
    return _WORKER_TASK.episodes(theta, contexts)
