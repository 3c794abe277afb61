"""The Ray backend: one Ray actor per worker slot, each kept warm between jobs.

``address="auto"`` starts a local Ray on this machine (``num_cpus`` = the worker count); any
other address (``HOST:PORT`` of a running cluster's head, or ``ray://HOST:PORT`` for Ray Client)
is checked for a listening port first, so an unreachable cluster is one line, not minutes of
retries. When Ray is already initialised in this process (a notebook, a test), it is used as it
is and left running. Each actor asks for one CPU, sets itself up once
(:func:`controlmm.batch.worker.setup`) and runs one job at a time; an actor that runs past the
timeout is killed and replaced, one that dies is replaced and its job reported. The workers need
controlmm installed where they run; input motions and trajectories travel with the jobs
(:mod:`controlmm.batch.payload`), results come back to the driver, which writes every file.
"""

from __future__ import annotations

import logging
import os
import socket
from dataclasses import dataclass, field
from typing import Any

import ray
from ray.exceptions import RayActorError, RayError

from controlmm.batch.backend import START_FAILURES, Done, load_worker
from controlmm.errors import ControlMMError

CONNECT_TIMEOUT_S = 5.0
"""How long the reachability check of a cluster address waits."""


def parse_address(address: str) -> tuple[str, int]:
    """``(host, port)`` of ``HOST:PORT`` or ``ray://HOST:PORT``; else a one-line ControlMMError."""
    text = address.removeprefix("ray://")
    host, _, port = text.rpartition(":")
    if not host or not port.isdigit() or not 0 < int(port) < 65536:
        raise ControlMMError(
            f"--ray must be 'auto' (a local Ray) or a cluster address HOST:PORT or ray://HOST:PORT; "
            f"got '{address}'"
        )
    return host.strip("[]"), int(port)


def check_reachable(address: str, timeout: float = CONNECT_TIMEOUT_S) -> None:
    """Raise a one-line ControlMMError unless something listens at the Ray ``address``."""
    host, port = parse_address(address)
    try:
        socket.create_connection((host, port), timeout=timeout).close()
    except OSError as exc:
        reason = exc.strerror or type(exc).__name__
        raise ControlMMError(
            f"cannot reach Ray at '{address}' ({reason}); start the cluster (ray start --head) "
            "or use --ray auto for a local Ray"
        ) from None


class _Actor:
    """A worker slot in Ray (made a Ray actor class by :class:`RayBackend`)."""

    def __init__(self, threads: int, models: list[str | None]) -> None:
        os.environ["OMP_NUM_THREADS"] = str(threads)
        self._worker = load_worker()
        self._info = self._worker.setup(threads, models)

    def ready(self) -> dict[str, Any]:
        return self._info

    def run(self, payload: dict[str, Any]) -> dict[str, Any]:
        return self._worker.run_job(payload)


@dataclass
class _Slot:
    actor: Any
    ref: Any  # the pending call: ready() while starting, run() while busy
    state: str = "starting"
    info: dict[str, Any] = field(default_factory=dict)


class RayBackend:
    """``workers`` Ray actors (None: one per CPU of the cluster) on the Ray at ``address``."""

    name = "ray"

    def __init__(
        self, address: str, workers: int | None, *, threads: int = 1, models: list[str | None] | None = None
    ) -> None:
        if address != "auto" and not ray.is_initialized():
            check_reachable(address)  # before any output is written
        self.address = address
        self.workers = workers
        self.threads = threads
        self.models = list(models or [])
        self._owns = False
        self._slots: list[_Slot] = []
        self._failures = 0
        self._remote: Any = None

    def start(self) -> None:
        if not ray.is_initialized():
            options: dict[str, Any] = {"log_to_driver": False, "logging_level": logging.ERROR}
            if self.address == "auto":
                cpus = self.workers or os.cpu_count() or 1
                ray.init(address="local", num_cpus=cpus, include_dashboard=False, **options)
            else:
                try:
                    ray.init(address=self.address, **options)
                except (ConnectionError, RuntimeError, ValueError) as exc:
                    raise ControlMMError(f"cannot connect to Ray at '{self.address}': {exc}") from None
            self._owns = True
        if self.workers is None:
            self.workers = max(1, int(ray.cluster_resources().get("CPU", 1)))
        self._remote = ray.remote(num_cpus=1, max_restarts=0)(_Actor)
        self._slots = [self._spawn() for _ in range(self.workers)]

    def _spawn(self) -> _Slot:
        actor = self._remote.remote(self.threads, self.models)
        return _Slot(actor, actor.ready.remote())

    def idle(self) -> list[int]:
        return [i for i, s in enumerate(self._slots) if s.state == "idle"]

    def worker(self, slot: int) -> dict[str, Any]:
        return dict(self._slots[slot].info)

    def submit(self, slot: int, payload: dict[str, Any]) -> None:
        s = self._slots[slot]
        s.state, s.ref = "busy", s.actor.run.remote(payload)

    def wait(self, timeout: float) -> list[Done]:
        pending = {s.ref: i for i, s in enumerate(self._slots) if s.state != "idle"}
        if not pending:
            return []
        ready, rest = ray.wait(list(pending), num_returns=1, timeout=timeout)
        if ready and rest:
            ready += ray.wait(rest, num_returns=len(rest), timeout=0)[0]
        done: list[Done] = []
        for ref in ready:
            i = pending[ref]
            s = self._slots[i]
            try:
                value = ray.get(ref)
            except RayActorError as exc:  # the actor's process died
                self._replace(i, done, f"the Ray worker died ({_one_line(exc)})")
                continue
            except RayError as exc:
                self._replace(i, done, f"the Ray task failed ({_one_line(exc)})")
                continue
            if s.state == "starting":
                s.state, s.info, self._failures = "idle", value, 0
            else:
                s.state = "idle"
                done.append(Done(i, value))
        return done

    def _replace(self, slot: int, done: list[Done], reason: str) -> None:
        s = self._slots[slot]
        if s.state == "busy":
            done.append(Done(slot, None, reason))
        else:
            self._failures += 1
            if self._failures >= START_FAILURES:
                raise ControlMMError(f"Ray workers die before they start: {reason}")
        ray.kill(s.actor, no_restart=True)
        self._slots[slot] = self._spawn()

    def kill(self, slot: int) -> None:
        ray.kill(self._slots[slot].actor, no_restart=True)
        self._slots[slot] = self._spawn()

    def close(self) -> None:
        for s in self._slots:
            ray.kill(s.actor, no_restart=True)
        self._slots = []
        if self._owns:
            ray.shutdown()
            self._owns = False


def _one_line(exc: BaseException) -> str:
    return " ".join(str(exc).split())[:300]
