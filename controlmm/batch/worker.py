"""A batch worker process: set up once, then run jobs one at a time, models kept warm.

The same two calls serve both backends (a process of the local pool, a Ray actor):

* :func:`setup` sets the CPU threads and loads the models the jobs will need, once;
* :func:`run_job` runs one job payload in a temporary folder and returns its record (status,
  figures, error, seconds, worker) and its output files as bytes. It never raises: an error
  of the job becomes its record, so the batch goes on.
"""

from __future__ import annotations

import contextlib
import io
import os
import socket
import sys
import tempfile
import threading
import time
import traceback
import warnings
from pathlib import Path
from typing import Any

import torch
from threadpoolctl import threadpool_limits
from tqdm import tqdm

from controlmm.atomic import OUTPUT_MARKER
from controlmm.batch.tasks import TASKS, Warm
from controlmm.errors import ControlMMError

_WARM = Warm()
MAX_LOG_LINES = 20
"""Lines of a job's warnings kept in its record."""


def worker_name() -> str:
    """``host:pid`` of this process."""
    return f"{socket.gethostname()}:{os.getpid()}"


def setup(threads: int = 1, models: list[str | None] | None = None) -> dict[str, Any]:
    """Prepare this process: ``threads`` torch CPU threads, ``models`` loaded (None: the default).

    A model that fails to load is left for the job that needs it to report. Returns
    ``{"worker": "host:pid", "pid": pid}``.
    """
    torch.set_num_threads(threads)
    # numpy's BLAS (OpenBLAS starts one spinning thread per core) too: workers share the cores
    threadpool_limits(limits=threads)
    # tqdm's default lock is a multiprocessing semaphore, which a stopped worker would leave behind:
    # a worker writes one bar at most, so a thread lock does
    tqdm.set_lock(threading.RLock())
    for model in models or []:
        with contextlib.suppress(Exception):
            _WARM.model(model)
    return {"worker": worker_name(), "pid": os.getpid()}


def run_job(payload: dict[str, Any]) -> dict[str, Any]:
    """Run one job; return ``{"record": {...}, "files": {relative path: bytes}}``.

    ``payload`` is ``{"id", "kind", "args"}`` with the arguments resolved
    (:func:`controlmm.batch.payload.payload`). The record's ``status`` is ``passed``, ``failed``
    (a check failed), ``done`` (nothing to check) or ``error`` (with ``error``, one line).
    """
    start, cpu = time.perf_counter(), time.process_time()
    record: dict[str, Any] = {"worker": worker_name()}
    files: dict[str, bytes] = {}
    log = io.StringIO()
    with (
        tempfile.TemporaryDirectory(prefix="controlmm-batch-") as tmp,
        warnings.catch_warnings(record=True) as caught,
        contextlib.redirect_stdout(log),
        contextlib.redirect_stderr(log),
    ):
        warnings.simplefilter("always")
        out = Path(tmp) / "out"
        out.mkdir()
        try:
            figures = TASKS[payload["kind"]](payload["args"], out, _WARM)
            passed = figures.get("passed")
            record.update(figures, status="done" if passed is None else ("passed" if passed else "failed"))
            files = _read_files(out)
        except ControlMMError as exc:
            record.update(status="error", error=str(exc))
        except Exception as exc:  # noqa: BLE001 - any failure of one job is recorded, the batch goes on
            record.update(
                status="error",
                error=f"{type(exc).__name__}: {' '.join(str(exc).split())}",
                traceback=traceback.format_exc(limit=8),
            )
        lines = [f"{w.category.__name__}: {w.message}" for w in caught] + log.getvalue().splitlines()
    if lines:
        record["log"] = lines[-MAX_LOG_LINES:]
    record["seconds"] = round(time.perf_counter() - start, 3)
    record["cpu_seconds"] = round(time.process_time() - cpu, 3)
    sys.stdout.flush()
    return {"record": record, "files": files}


def _read_files(out: Path) -> dict[str, bytes]:
    """Every file under ``out`` (paths relative to it), except output markers."""
    return {
        p.relative_to(out).as_posix(): p.read_bytes()
        for p in sorted(out.rglob("*"))
        if p.is_file() and p.name != OUTPUT_MARKER
    }
