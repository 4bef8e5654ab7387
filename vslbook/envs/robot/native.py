"""MuJoCo's C step for episode loops compiled with numba.

A task whose episode must look at the simulation after every physics sub-step (table
tennis ends an episode at the sub-step of a contact and scores the closest ball–racket
approach over all sub-steps) pays Python's cost on every sub-step: about 16 % of the physics
for a loop that only steps, copies positions and looks at the contact count. Such a loop
can instead run compiled (``numba.njit``) and call ``mj_step`` of the very ``libmujoco``
the ``mujoco`` package loaded, on the addresses of its ``MjModel`` and ``MjData``: the same
C function on the same memory, so the same numbers, without the Python around each call.

:data:`MJ_STEP` is that function (a ``ctypes`` function a compiled loop calls as
``MJ_STEP(model._address, data._address)``); it is bound when this module is imported.
The numpy views of ``MjData`` (``data.xpos``, ``data.ctrl``, ``data.sensordata``, ...)
point into the same memory, so a compiled loop reads and writes them as arrays.

What a compiled loop gives up: MuJoCo's fatal errors (``mju_error``, e.g. an ``mjData``
arena too small for the contacts) reach Python as exceptions only through the ``mujoco``
bindings' own calls, so a task offers its Python loop as well (table tennis:
``compiled=False``), which is also the reference the tests hold the compiled loop to.
"""

from __future__ import annotations

import ctypes
from pathlib import Path

import mujoco

_PATTERNS = ("libmujoco.so*", "libmujoco*.dylib", "mujoco.dll")


def library_path() -> Path:
    """The ``libmujoco`` shared library of the installed ``mujoco`` package."""
    folder = Path(mujoco.__file__).parent
    for pattern in _PATTERNS:
        found = sorted(folder.glob(pattern))
        if found:
            return found[0]
    raise FileNotFoundError(
        f"no MuJoCo shared library ({', '.join(_PATTERNS)}) next to {mujoco.__file__}"
    )


def _bind_step() -> ctypes._CFuncPtr:
    lib = ctypes.CDLL(str(library_path()))
    step = lib.mj_step
    step.argtypes = [ctypes.c_void_p, ctypes.c_void_p]  # const mjModel*, mjData*
    step.restype = None
    return step


#: ``void mj_step(const mjModel* m, mjData* d)`` of the loaded MuJoCo, callable from numba.
MJ_STEP = _bind_step()
