"""What can go wrong with a run, as exceptions: it diverged, or its directory is damaged.

Both are re-exported by :mod:`vslbook.results`, which raises the second.
"""

from __future__ import annotations

__all__ = ["DivergenceError", "RunDirError"]


class DivergenceError(RuntimeError):
    """A training run produced a non-finite loss, value or parameter.

    Attributes:
        step: the environment step (or iteration) at which it was detected.
        quantity: what was non-finite, e.g. ``"critic_loss"`` or ``"parameter policy.x"``.
        value: the offending value as a float (nan or ±inf) where there is one.
    """

    def __init__(self, step: int, quantity: str, value: float | None = None) -> None:
        self.step, self.quantity, self.value = int(step), str(quantity), value
        shown = "" if value is None else f" ({value})"
        super().__init__(f"diverged at step {self.step}: non-finite {self.quantity}{shown}")


class RunDirError(ValueError):
    """A run directory cannot be used as it is: a corrupt checkpoint, a ``DONE`` that its
    metrics do not back, an unreadable ``config.json``. The message names the file and says
    what to do (usually ``--restart``, which moves the run aside and trains it afresh)."""
