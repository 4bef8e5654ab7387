"""A run's status: ``DONE`` (backed by its metrics), ``FAILED`` (diverged), and which code
made it. :class:`RunStatus` is the part of :class:`vslbook.results.RunDir` that reads and
writes them; it works on the run directory's ``path`` and its metrics.
"""

from __future__ import annotations

import hashlib
import json
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from vslbook.jsonfiles import atomic_write, json_bytes, plain_json, read_json
from vslbook.provenance import code_fingerprint
from vslbook.run_errors import DivergenceError, RunDirError

__all__ = ["RunStatus"]


class RunStatus:
    """``DONE``, ``FAILED`` and code identity of a run directory (mixed into ``RunDir``)."""

    path: Path
    DONE = "DONE"
    FAILED = "FAILED"
    ENV = "env.json"
    METRICS = "metrics.jsonl"

    # -- completion ---------------------------------------------------------------------

    def _metrics_record(self) -> dict[str, Any]:
        """What ``DONE`` records of ``metrics.jsonl``: rows, last step and sha256."""
        lines = self._metric_lines()
        data = "".join(line + "\n" for line in lines).encode("utf-8")
        last = json.loads(lines[-1])["step"] if lines else None
        return {"rows": len(lines), "last_step": last, "sha256": hashlib.sha256(data).hexdigest()}

    def mark_done(
        self, summary: Mapping[str, Any] | None = None, *, last_step: int | None = None
    ) -> None:
        """Write ``DONE`` (a JSON summary); call it as the run's very last step.

        ``DONE`` also records the rows of ``metrics.jsonl`` it covers (``"metrics"``: count,
        last step, sha256), which :meth:`check_done` compares whenever the run is reused.

        Args:
            last_step: the step the run's last row must have (its whole length); checked.

        Raises:
            RuntimeError: the run is marked FAILED (a diverged run is never DONE), it has
                no rows, a step repeats or goes back, or the last step is not ``last_step``.
        """
        if self.failed:
            raise RuntimeError(f"{self.path} is marked FAILED ({self.failure}); it cannot be DONE")
        steps = [row["step"] for row in self.metrics()]
        if not steps:
            raise RuntimeError(f"{self.path}: no rows in {self.METRICS}; the run cannot be DONE")
        back = next((i for i in range(1, len(steps)) if steps[i] <= steps[i - 1]), None)
        if back is not None:
            raise RuntimeError(
                f"{self.metrics_path}: step {steps[back]} (row {back + 1}) follows step "
                f"{steps[back - 1]}; rows repeat, so the run cannot be DONE"
            )
        if last_step is not None and steps[-1] != last_step:
            raise RuntimeError(
                f"{self.metrics_path} ends at step {steps[-1]}, expected {last_step}; "
                "the run cannot be DONE"
            )
        body = dict(summary or {}) | {"metrics": self._metrics_record()}
        atomic_write(self.path / self.DONE, json_bytes(plain_json(body, "summary")))

    @property
    def done(self) -> bool:
        """True once :meth:`mark_done` has been called (see :meth:`check_done`)."""
        return (self.path / self.DONE).is_file()

    def check_done(self) -> None:
        """Check that a ``DONE`` run's metrics are the ones ``DONE`` recorded.

        Raises:
            RunDirError: ``metrics.jsonl`` is missing or differs from what ``DONE`` recorded
                (deleted, truncated, appended to), or ``DONE`` records nothing of it.
        """
        done = read_json(self.path / self.DONE)
        recorded = done.get("metrics") if isinstance(done, dict) else None
        what = None
        if not isinstance(recorded, dict):
            what = "records no metrics (written by older code, or by hand)"
        elif not self.metrics_path.exists():
            what = f"covers {recorded.get('rows')} rows but {self.METRICS} is missing"
        else:
            now = self._metrics_record()
            if now != recorded:
                what = (f"covers {recorded.get('rows')} rows (sha256 "
                        f"{str(recorded.get('sha256'))[:12]}) but {self.METRICS} has "
                        f"{now['rows']} (sha256 {now['sha256'][:12]})")  # fmt: skip
        if what is not None:
            raise RunDirError(
                f"run {self.path} is marked DONE but its DONE {what}; rerun with --restart "
                "to move it aside and train it afresh"
            )

    def mark_failed(self, error: DivergenceError | Mapping[str, Any]) -> None:
        """Write ``FAILED`` (JSON: step, quantity, value, message) for a diverged run."""
        if isinstance(error, DivergenceError):
            info = {"step": error.step, "quantity": error.quantity, "message": str(error),
                    "value": None if error.value is None else repr(error.value)}  # fmt: skip
        else:
            info = dict(error)
        atomic_write(self.path / self.FAILED, json_bytes(plain_json(info, "failure")))

    @property
    def failed(self) -> bool:
        """True when the run diverged and was marked FAILED."""
        return (self.path / self.FAILED).is_file()

    @property
    def failure(self) -> dict[str, Any] | None:
        """The FAILED record (step, quantity, value, message), or None."""
        if not self.failed:
            return None
        return json.loads((self.path / self.FAILED).read_text(encoding="utf-8"))

    @property
    def status(self) -> str:
        """``"done"``, ``"failed"`` or ``"incomplete"``."""
        return "failed" if self.failed else "done" if self.done else "incomplete"

    @property
    def code_hash(self) -> str | None:
        """The :func:`code_fingerprint` recorded when the run was created (None if older)."""
        try:
            return self.env.get("code_hash")
        except FileNotFoundError:
            return None

    @property
    def code_matches(self) -> bool:
        """True when the code running now made the run, or replays its first rows
        identically (its fingerprint is then in ``env.json``'s ``code_hashes_verified``,
        :mod:`vslbook.replay`).

        Compared over the same files as when the run was created: ``env.json`` records
        which package paths its fingerprint left out.
        """
        env = self.env
        now = code_fingerprint(tuple(env.get("code_excluded", ())))
        return now == env.get("code_hash") or now in env.get("code_hashes_verified", ())

    def add_verified_code(self) -> str:
        """Record that the code running now reproduces this run (``code_hashes_verified``
        in ``env.json``); returns its fingerprint. Only the lock holder may call it."""
        env = self.env
        now = code_fingerprint(tuple(env.get("code_excluded", ())))
        verified = list(env.get("code_hashes_verified", ()))
        if now not in verified and now != env.get("code_hash"):
            env["code_hashes_verified"] = verified + [now]
            atomic_write(self.path / self.ENV, json_bytes(env))
        return now
