"""vslbook: a reproducible companion to *Learning Versatile Skills using Reinforcement Learning*.

The package is the source of truth; the chapter notebooks in ``notebooks/`` only call it.
Modules are small and named after what they implement:

``budget``    smoke / reduced / full presets (``VSLBOOK_BUDGET``)
``seeding``   one call seeds python, numpy, torch and a gymnasium env
``results``   run directories, resume, the ``data/`` schema, the paper's curves
``stats``     IQM with stratified-bootstrap CIs (rliable), performance profiles
``plots``     one matplotlib style, learning curves, thesis-vs-ours overlays
``sweep``     grids of (config, seed) on submitit (local or SLURM)
``dists``     Gaussian and mixture-of-experts densities
``movement``  ProMP, DMP, ProDMP
``bounds``    numerical checks of the thesis's derivations
"""

from __future__ import annotations

import inspect

__version__ = "0.1.0"

__all__ = ["__version__", "show_source"]


def show_source(obj: object) -> object:
    """Render the source code of a library object in a notebook (d2l-style).

    Returns an ``IPython.display.Markdown`` object when IPython is available (so the
    notebook shows highlighted code), otherwise the source text itself.

    Raises:
        TypeError: if ``obj`` has no retrievable source (e.g. a builtin or an instance).
    """
    try:
        source = inspect.getsource(obj)  # type: ignore[arg-type]
        where = inspect.getsourcefile(obj)  # type: ignore[arg-type]
    except (TypeError, OSError) as err:
        raise TypeError(
            f"show_source expects a module, class, method or function defined in Python; "
            f"got {obj!r} of type {type(obj).__name__}"
        ) from err
    try:
        from IPython.display import Markdown
    except ImportError:  # pragma: no cover - IPython ships with the notebooks extra
        return source
    name = getattr(obj, "__qualname__", getattr(obj, "__name__", "object"))
    rel = where.split("vslbook", 1)[-1] if where else ""
    return Markdown(f"`vslbook{rel}` — `{name}`\n\n```python\n{source}```")
