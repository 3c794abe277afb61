"""The local backend: a pool of worker processes on this machine, each kept warm between jobs.

Every worker is a fresh Python process (``spawn``) that imports torch and MuJoCo and loads the
models once (:func:`controlmm.batch.worker.setup`), then runs the jobs it is sent one at a
time over a pipe. A worker whose job runs too long is killed and replaced; one that dies
(a crash, the out-of-memory killer) is replaced and its job reported. Workers ignore Ctrl-C:
the driver stops them, and a worker whose driver is gone exits when its pipe closes.
"""

from __future__ import annotations

import contextlib
import multiprocessing as mp
import os
import signal
import sys
from dataclasses import dataclass, field
from multiprocessing.connection import Connection, wait
from multiprocessing.process import BaseProcess
from types import FrameType
from typing import Any

from controlmm.batch.backend import START_FAILURES, Done, load_worker
from controlmm.errors import ControlMMError

STOP_WAIT_S = 3.0
"""How long a stopping worker may take to clean up before it is killed."""

KILL_WAIT_S = 1.0
"""How long a timed-out job's worker may take to unwind before it is killed."""


def _serve(conn: Connection, threads: int, models: list[str | None]) -> None:
    """A worker process: set up, say ready, then run payloads until told to stop or the pipe closes.

    SIGTERM stops it: a job in progress unwinds (its temporary folder is removed), then the
    process ends at once (``os._exit``: tearing down torch and the models would take seconds).
    """
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # the driver decides when to stop
    signal.signal(signal.SIGTERM, _exit_on_term)
    os.environ["OMP_NUM_THREADS"] = str(threads)
    try:
        worker = load_worker()
        conn.send(("ready", worker.setup(threads, models)))
        while True:
            payload = conn.recv()
            if payload is None:
                break
            conn.send(("done", worker.run_job(payload)))
    except (EOFError, OSError, SystemExit):  # the driver is gone, or SIGTERM
        pass
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(0)


def _exit_on_term(signum: int, frame: FrameType | None) -> None:
    raise SystemExit(0)


def exit_reason(code: int | None) -> str:
    """A worker's exit code in words."""
    if code is not None and code < 0:
        with contextlib.suppress(ValueError):
            return f"killed by {signal.Signals(-code).name}"
    return f"exit code {code}"


@dataclass
class _Slot:
    process: BaseProcess
    conn: Connection
    state: str = "starting"  # starting, idle, busy
    info: dict[str, Any] = field(default_factory=dict)


class LocalPool:
    """``workers`` processes with ``threads`` torch threads each, ``models`` loaded at start."""

    name = "local"

    def __init__(self, workers: int, *, threads: int = 1, models: list[str | None] | None = None) -> None:
        if workers < 1:
            raise ControlMMError(f"workers must be at least 1; got {workers}")
        self.workers = workers
        self.threads = threads
        self.models = list(models or [])
        self._ctx = mp.get_context("spawn")
        self._slots: list[_Slot] = []
        self._failures = 0

    def _spawn(self) -> _Slot:
        parent, child = self._ctx.Pipe()
        process = self._ctx.Process(
            target=_serve, args=(child, self.threads, self.models), daemon=True, name="controlmm-batch-worker"
        )
        process.start()
        child.close()
        return _Slot(process, parent)

    def start(self) -> None:
        self._slots = [self._spawn() for _ in range(self.workers)]

    def idle(self) -> list[int]:
        return [i for i, s in enumerate(self._slots) if s.state == "idle"]

    def worker(self, slot: int) -> dict[str, Any]:
        return dict(self._slots[slot].info)

    def submit(self, slot: int, payload: dict[str, Any]) -> None:
        s = self._slots[slot]
        s.state = "busy"
        with contextlib.suppress(OSError):  # a worker that just died is reported by wait()
            s.conn.send(payload)

    def wait(self, timeout: float) -> list[Done]:
        owners: dict[Any, int] = {}
        for i, s in enumerate(self._slots):
            owners[s.conn] = i
            owners[s.process.sentinel] = i
        done: list[Done] = []
        dead: set[int] = set()
        for obj in wait(list(owners), timeout):
            i = owners[obj]
            s = self._slots[i]
            if obj is not s.conn:
                dead.add(i)
                continue
            try:
                kind, value = s.conn.recv()
            except (EOFError, OSError):
                dead.add(i)
                continue
            if kind == "ready":
                s.state, s.info, self._failures = "idle", value, 0
            else:
                s.state = "idle"
                done.append(Done(i, value))
        for i in sorted(dead):
            s = self._slots[i]
            with contextlib.suppress(EOFError, OSError):  # a result sent just before the worker died
                while s.state == "busy" and s.conn.poll():
                    kind, value = s.conn.recv()
                    if kind == "done":
                        s.state = "idle"
                        done.append(Done(i, value))
            s.process.join(STOP_WAIT_S)
            if s.process.is_alive():
                s.process.kill()
                s.process.join()
            reason = exit_reason(s.process.exitcode)
            if s.state == "busy":
                done.append(Done(i, None, f"the worker process died ({reason})"))
            elif s.state == "starting":
                self._failures += 1
                if self._failures >= START_FAILURES:
                    raise ControlMMError(f"batch worker processes die before they start ({reason})")
            s.conn.close()
            self._slots[i] = self._spawn()
        return done

    def kill(self, slot: int) -> None:
        s = self._slots[slot]
        s.process.terminate()  # the job unwinds and its temporary folder goes, unless it is stuck in C
        s.process.join(KILL_WAIT_S)
        if s.process.is_alive():
            s.process.kill()
            s.process.join()
        s.conn.close()
        self._slots[slot] = self._spawn()

    def close(self) -> None:
        for s in self._slots:  # SIGTERM: the worker exits at once, cleaning up its temporary files
            s.process.terminate()
        for s in self._slots:
            s.process.join(STOP_WAIT_S)
            if s.process.is_alive():
                s.process.kill()
                s.process.join()
            s.conn.close()
        self._slots = []
