"""Registries of algorithms and figures, filled by the modules that implement them.

`vslbook run ALGO` and `vslbook figure ID` look names up here. A chapter module
registers itself at import time::

    register_algorithm("erl-pg", train=train, config=ERLPGConfig, envs=(...), doc="...")

The CLI imports :data:`PLUGIN_MODULES` first so every registration has happened.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

#: Modules that register algorithms or figures when imported.
PLUGIN_MODULES: tuple[str, ...] = (
    "vslbook.erl.pg",
    "vslbook.srl.dime",
    "vslbook.experiments.ch3_algorithms",
    "vslbook.experiments.ch4_algorithms",
    "vslbook.figures",
)


@dataclass(frozen=True)
class Algorithm:
    """A trainable algorithm.

    Attributes:
        name: registry key (``vslbook run NAME``).
        train: ``train(run, config, budget, *, progress, stop_after) -> dict`` that trains
            inside a :class:`vslbook.results.RunDir`, resuming from its checkpoint.
        config: frozen dataclass of hyper-parameters with the thesis's defaults.
        envs: environment ids the algorithm is meant for (empty: any).
        doc: one line for ``vslbook algorithms``.
        independent_of: package-relative paths (``"erl/"``) the algorithm's runs never
            import; editing them does not make its finished runs stale
            (:func:`vslbook.results.code_fingerprint`).
        defaults: ``defaults(env, budget, overrides) -> config``, the configuration of
            ``env`` at ``budget`` for an algorithm whose hyper-parameters depend on the task
            (the Chapter 3 presets, Tables A.1-A.5); it receives the ``--set`` overrides
            so that a preset chosen by one of them (the 5-link reacher's reward) can be
            found. Such a config holds the budget's counts itself; None: ``config()``,
            whose full-budget counts the training loop scales.
        train_seeds: ``train_seeds(runs, records, budget, *, progress, stop_after) -> list``
            that trains several seeds in one process (``vslbook run ALGO --seeds 0 1 2``);
            None: one seed per process.
        validate_env: ``validate_env(env)`` raises a clear ValueError for an env the
            algorithm cannot train on (e.g. DIME on an episodic task without a bounded
            action space); called before anything is written. None: ``envs`` decides.
    """

    name: str
    train: Callable[..., dict]
    config: type
    envs: tuple[str, ...] = ()
    doc: str = ""
    independent_of: tuple[str, ...] = ()
    defaults: Callable[..., Any] | None = None
    train_seeds: Callable[..., list] | None = None
    validate_env: Callable[[str], None] | None = None

    def check_env(self, env: str) -> None:
        """Raise a clear error if ``env`` is not one this algorithm is meant for."""
        if self.envs and env not in self.envs:
            raise ValueError(
                f"algorithm {self.name!r} does not support env {env!r}; "
                f"expected one of {', '.join(self.envs)}"
            )
        if self.validate_env is not None:
            self.validate_env(env)

    def default_config(self, env: str, budget: Any, overrides: dict[str, Any] | None) -> Any:
        """The configuration ``--set`` overrides apply to: the task's preset or ``config()``."""
        if self.defaults is None:
            return self.config()
        return self.defaults(env, budget, dict(overrides or {}))


@dataclass(frozen=True)
class Figure:
    """A reproducible figure: ``make(budget, out_dir) -> list[Path]``."""

    id: str
    make: Callable[..., list]
    doc: str = ""


ALGORITHMS: dict[str, Algorithm] = {}
FIGURES: dict[str, Figure] = {}


def register_algorithm(
    name: str,
    *,
    train: Callable[..., dict],
    config: type,
    envs: tuple[str, ...] = (),
    doc: str = "",
    independent_of: tuple[str, ...] = (),
    defaults: Callable[..., Any] | None = None,
    train_seeds: Callable[..., list] | None = None,
    validate_env: Callable[[str], None] | None = None,
) -> Algorithm:
    algo = Algorithm(
        name=name, train=train, config=config, envs=tuple(envs), doc=doc,
        independent_of=tuple(independent_of), defaults=defaults, train_seeds=train_seeds,
        validate_env=validate_env,
    )  # fmt: skip
    ALGORITHMS[name] = algo
    return algo


def register_figure(fig_id: str, make: Callable[..., list], doc: str = "") -> Figure:
    fig = Figure(id=fig_id, make=make, doc=doc)
    FIGURES[fig_id] = fig
    return fig


def load_plugins() -> None:
    """Import every module that registers something (idempotent)."""
    for mod in PLUGIN_MODULES:
        importlib.import_module(mod)


#: Where each algorithm is registered, so that looking one up imports only its own module
#: (a DIME run never imports the episodic code; see ``Algorithm.independent_of``).
ALGORITHM_MODULES: dict[str, str] = {
    "dime": "vslbook.srl.dime",
    "dime-gaussian": "vslbook.srl.dime",
    "crossq": "vslbook.srl.dime",
    "erl-pg": "vslbook.erl.pg",
    "svsl": "vslbook.experiments.ch3_algorithms",
    "hireps": "vslbook.experiments.ch3_algorithms",
    "ladips": "vslbook.experiments.ch3_algorithms",
    "ppo": "vslbook.experiments.ch3_algorithms",
    **{
        name: "vslbook.experiments.ch4_algorithms"
        for name in ("diskill", "lindiskill", "bbrl", "diskill-v2", "diskill-v3", "ppo-ch4")
    },
}


def get_algorithm(name: str) -> Algorithm:
    if name in ALGORITHM_MODULES:
        importlib.import_module(ALGORITHM_MODULES[name])
    if name not in ALGORITHMS:
        load_plugins()
    if name not in ALGORITHMS:
        raise ValueError(
            f"unknown algorithm {name!r}; expected one of {', '.join(sorted(ALGORITHMS))}"
        )
    return ALGORITHMS[name]


#: Seeds are 32-bit: numpy's legacy global RNG and gymnasium's spaces take at most 2**32 - 1,
#: so one range holds for every algorithm.
SEED_LIMIT = 2**32


def check_seed(seed: Any) -> int:
    """``seed`` as an int in ``[0, 2**32)``; anything else (-1, 2.5, "x", True, 2**32) is a
    clear error."""
    import numbers

    if isinstance(seed, bool) or not isinstance(seed, numbers.Integral) or not (
        0 <= seed < SEED_LIMIT
    ):
        raise ValueError(f"seed must be an integer with 0 <= seed < 2**32, got {seed!r}")
    return int(seed)


def check_run_request(spec: Algorithm, env: str, seed: Any) -> None:
    """Validate a run's env id and seed before anything is written to disk.

    Raises:
        ValueError: for an env id neither vslbook nor gymnasium knows (with close matches),
            one the algorithm is not meant for, or a seed outside ``[0, 2**32)``.
    """
    from vslbook.envs import check_env_id

    check_seed(seed)
    check_env_id(env)
    spec.check_env(env)


def get_figure(fig_id: str) -> Figure:
    load_plugins()
    if fig_id not in FIGURES:
        raise ValueError(f"unknown figure {fig_id!r}; expected one of {', '.join(sorted(FIGURES))}")
    return FIGURES[fig_id]


def _convert(config_cls: type, field: Any, value: str, base: Any = None) -> Any:
    """Parse the command-line string ``value`` for ``field`` (its value in ``base``, by
    default ``config_cls()``, or its annotation)."""
    default = getattr(config_cls() if base is None else base, field.name)
    annotation = str(field.type)
    if default is None or "None" in annotation:  # an optional field: "none" clears it
        if value.strip().lower() in ("none", "null"):
            return None
        for name, kind in (("bool", bool), ("int", int), ("float", float), ("str", str)):
            if name in annotation:
                default = kind()
                break
    if isinstance(default, bool):
        if value.lower() not in ("true", "false", "1", "0"):
            raise ValueError(f"expected true/false/1/0, got {value!r}")
        return value.lower() in ("true", "1")
    if default is None:
        return value
    if isinstance(default, tuple):  # "0.1,0.2" or "(0.1, 0.2)": the element type of the base
        kind = type(default[0]) if default else float
        items = [v for v in value.strip().strip("()[]").split(",") if v.strip()]
        try:
            return tuple(kind(v.strip()) for v in items)
        except ValueError:
            raise ValueError(f"{field.name}={value}: expected comma-separated numbers") from None
    if isinstance(default, int):
        try:
            return int(value)
        except ValueError:
            raise ValueError(f"{field.name}={value}: expected an integer") from None
    return type(default)(value)


def _is_int(value: Any) -> bool:
    import numbers

    return isinstance(value, numbers.Integral) and not isinstance(value, bool)


def config_from_overrides(
    config_cls: type, overrides: dict[str, Any] | None, base: Any = None
) -> Any:
    """Build ``config_cls`` with ``overrides``, converting strings to the field's type.

    Strings (from ``--set key=value``) are parsed by the field's value in ``base`` (an
    instance of ``config_cls``, e.g. a task's preset; default ``config_cls()``) or its
    annotation; ``none`` clears an optional field (e.g. ``fixed_alpha=none``); a tuple field
    takes comma-separated numbers. The overrides replace ``base``'s fields.

    Raises:
        ValueError: for a field the config does not have (the message lists the valid ones)
            or a value that cannot be converted.
    """
    import dataclasses

    fields = {f.name: f for f in dataclasses.fields(config_cls)}
    kwargs: dict[str, Any] = {}
    for key, value in (overrides or {}).items():
        if key not in fields:
            raise ValueError(
                f"{config_cls.__name__} has no field {key!r}; expected one of {', '.join(fields)}"
            )
        kind = str(fields[key].type)
        if isinstance(value, str) and kind != "str":
            try:
                value = _convert(config_cls, fields[key], value, base)
            except (TypeError, ValueError) as err:
                if "expected an integer" in str(err):
                    raise ValueError(f"{err} (config field {key}: {kind})") from None
                raise ValueError(f"cannot convert {key}={value!r} to {kind}") from err
        elif kind in ("int", "int | None") and value is not None and not _is_int(value):
            raise ValueError(f"{key}={value!r}: expected an integer (config field {key}: {kind})")
        kwargs[key] = value
    if base is not None:
        if not isinstance(base, config_cls):
            raise TypeError(f"base must be a {config_cls.__name__}, got {type(base).__name__}")
        return dataclasses.replace(base, **kwargs)
    return config_cls(**kwargs)


def config_from_record(config_cls: type, record: dict[str, Any]) -> Any:
    """Build ``config_cls`` from a run's config record, ignoring keys it has no field for.

    A record (``RunDir.config``) holds ``algo``, ``env``, ``seed`` and ``budget`` beside
    the algorithm's fields.
    """
    import dataclasses

    names = {f.name for f in dataclasses.fields(config_cls)}
    # JSON gives lists where the config had tuples
    return config_cls(
        **{k: tuple(v) if isinstance(v, list) else v for k, v in record.items() if k in names}
    )
