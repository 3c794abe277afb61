"""What a backend (the local pool, Ray) gives the runner: worker slots that run one job at a time.

The runner hands a job to an idle slot (:meth:`Backend.submit`), waits for finished jobs
(:meth:`Backend.wait`), and replaces the worker of a slot whose job ran too long
(:meth:`Backend.kill`). A worker that dies is replaced by the backend itself; the job it was
running comes back as a :class:`Done` without an outcome.
"""

from __future__ import annotations

from dataclasses import dataclass
from types import ModuleType
from typing import Any, Protocol

START_FAILURES = 3
"""Workers that may die in a row before they start before the backend gives up."""


@dataclass(frozen=True)
class Done:
    """A slot's job ended: ``outcome`` is the worker's ``{"record", "files"}``, or None when the
    worker died, ``error`` saying how."""

    slot: int
    outcome: dict[str, Any] | None
    error: str | None = None


class Backend(Protocol):
    """Worker slots (see the module docstring)."""

    name: str

    @property
    def workers(self) -> int | None:
        """Worker slots (None until a Ray backend has counted the cluster's CPUs)."""

    def start(self) -> None:
        """Start every worker (returns at once; a slot is idle once its worker is set up)."""

    def idle(self) -> list[int]:
        """Slots whose worker is set up and waits for a job."""

    def worker(self, slot: int) -> dict[str, Any]:
        """``{"worker": "host:pid", "pid": pid}`` of the slot's worker."""

    def submit(self, slot: int, payload: dict[str, Any]) -> None:
        """Run a job payload (:func:`controlmm.batch.payload.payload`) on an idle slot."""

    def wait(self, timeout: float) -> list[Done]:
        """Block until a job ends or a worker is set up, at most ``timeout`` seconds."""

    def kill(self, slot: int) -> None:
        """Stop the slot's worker at once (its job is dropped) and start a new one."""

    def close(self) -> None:
        """Stop every worker."""


def load_worker() -> ModuleType:
    """:mod:`controlmm.batch.worker`, in a worker process."""
    # heavy (torch, MuJoCo, the models): imported in worker processes only, so the driver stays light
    from controlmm.batch import worker

    return worker
