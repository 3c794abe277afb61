"""Run a batch: every job on a backend's workers, each finished job written as it ends.

```python
from controlmm.batch import BatchConfig, load_jobs, run_batch

jobs = load_jobs("motions/", robots=["g1", "h1"])            # or a JSONL file of jobs
result = run_batch(jobs, "out/batch", BatchConfig(workers=2))  # or BatchConfig(ray="auto")
result.counts                                                  # {"jobs": 8, "passed": 7, ...}
```

Jobs whose folder already holds their record (same spec) are skipped, so a rerun resumes a
stopped or killed batch; ``retry_errors`` runs the ``error``/``crashed``/``timeout`` ones again.
A job that raises, whose worker dies or that runs past ``timeout_s`` is recorded with its error
and the batch goes on. Ctrl-C (KeyboardInterrupt) stops the workers, writes the summary of what
finished and is raised again. The summary files are rewritten at the end of every run.
"""

from __future__ import annotations

import collections
import json
import os
import time
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from tqdm import tqdm

from controlmm import __version__
from controlmm.atomic import check_output_dir, open_growing_dir, write_text
from controlmm.batch.backend import Backend
from controlmm.batch.jobs import Job
from controlmm.batch.payload import payload, plan_models
from controlmm.batch.pool import LocalPool
from controlmm.batch.store import BATCH_OUTPUT, RETRY_STATUSES, BatchStore
from controlmm.batch.summary import write_summary
from controlmm.errors import ControlMMError

TICK_S = 1.0
"""The longest the runner waits before refreshing the progress bar and checking timeouts."""

Event = Callable[[str, Job, dict[str, Any]], None]
"""``on_event(name, job, info)``: ``started`` (info: the worker) and ``finished`` (the record)."""


@dataclass(frozen=True)
class BatchConfig:
    """How to run a batch.

    Attributes:
        workers: worker processes (local) or actors (Ray); None: one per CPU core here
            (local, at most one per job) or per CPU of the cluster (Ray).
        ray: None for the local process pool; ``"auto"`` for a local Ray; a cluster address.
        timeout_s: a job running longer is stopped and recorded as ``timeout`` (None: no limit).
        threads: torch CPU threads per worker.
        retry_errors: run again the jobs recorded as ``error``, ``crashed`` or ``timeout``.
        force: start over in an output folder that holds anything (a previous batch too).
        progress: a progress bar on stderr (jobs done, passed/failed, jobs per minute, ETA).
    """

    workers: int | None = None
    ray: str | None = None
    timeout_s: float | None = None
    threads: int = 1
    retry_errors: bool = False
    force: bool = False
    progress: bool = True

    def __post_init__(self) -> None:
        if self.workers is not None and self.workers < 1:
            raise ControlMMError(f"workers must be at least 1; got {self.workers}")
        if self.timeout_s is not None and not self.timeout_s > 0:
            raise ControlMMError(f"timeout must be greater than 0 seconds; got {self.timeout_s}")
        if self.threads < 1:
            raise ControlMMError(f"threads must be at least 1; got {self.threads}")


@dataclass
class BatchResult:
    """What a run did: every job's record (None: not run), the summary counts, how it ended."""

    out: Path
    jobs: list[Job]
    records: dict[str, dict[str, Any]]
    ran: int = 0
    skipped: int = 0
    seconds: float = 0.0
    interrupted: bool = False
    backend: str = ""
    workers: int = 0
    counts: dict[str, Any] = field(default_factory=dict)

    @property
    def all_passed(self) -> bool:
        """Every job passed its checks (or ran without checks)."""
        return self.counts.get("passed", 0) + self.counts.get("done", 0) == len(self.jobs)


def cpu_count() -> int:
    """CPU cores this process may use."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not Linux
        return os.cpu_count() or 1


def make_backend(config: BatchConfig, jobs: Sequence[Job]) -> Backend:
    """The backend of ``config`` for ``jobs`` (plan models loaded by every worker at start)."""
    models = plan_models(jobs)
    if config.ray is None:
        workers = config.workers or max(1, min(cpu_count(), len(jobs)))
        return LocalPool(workers, threads=config.threads, models=models)
    try:
        # optional (the ray extra): imported only when --ray is given
        from controlmm.batch.ray_backend import RayBackend
    except ImportError:
        raise ControlMMError(
            "Ray is not installed: pip install -e '.[ray]' (or pip install ray), or leave out --ray "
            "for the local process pool"
        ) from None
    return RayBackend(config.ray, config.workers, threads=config.threads, models=models)


def run_batch(
    jobs: Sequence[Job],
    out: str | Path,
    config: BatchConfig = BatchConfig(),
    *,
    on_event: Event | None = None,
) -> BatchResult:
    """Run ``jobs`` into the batch folder ``out`` (see the module docstring and :mod:`.store`)."""
    jobs = list(jobs)
    if len({job.id for job in jobs}) != len(jobs):
        raise ControlMMError("job ids must be unique (controlmm.batch.duplicate_ids marks repeats)")
    start = time.perf_counter()
    out = check_output_dir(out, kind=BATCH_OUTPUT, force=config.force, make_parents=True)
    store = BatchStore(out)
    result = BatchResult(out, jobs, {})
    todo: list[Job] = []
    for job in jobs:
        record = None if config.force else store.load(job)  # force: start over
        if record is not None and not (config.retry_errors and record.get("status") in RETRY_STATUSES):
            result.records[job.id] = record
        elif not job.error:
            todo.append(job)
    result.skipped = len(result.records)
    backend = make_backend(config, todo) if todo else None  # Ray missing or unreachable: fails here
    open_growing_dir(out, kind=BATCH_OUTPUT, force=config.force, make_parents=True)
    for job in jobs:
        if job.error and job.id not in result.records:  # a malformed entry: recorded, never run
            result.records[job.id] = store.write(job, {"status": "error", "error": job.error, "seconds": 0.0})
            result.ran += 1
    bar = _Progress(config.progress, jobs, result.records)
    try:
        if backend is not None:
            result.backend = backend.name
            _write_run(out, config, backend, jobs)
            try:
                _run(backend, todo, store, config, result, bar, on_event)
            finally:
                result.workers = backend.workers or 0
                backend.close()
    except KeyboardInterrupt:
        result.interrupted = True
        raise
    finally:
        bar.close()
        result.seconds = time.perf_counter() - start
        extra = {
            "interrupted": result.interrupted,
            "ran": result.ran,
            "skipped": result.skipped,
            "seconds": round(result.seconds, 3),
            "backend": result.backend,
        }
        result.counts = write_summary(out, jobs, result.records, extra)["counts"]
    return result


def _run(
    backend: Backend,
    todo: list[Job],
    store: BatchStore,
    config: BatchConfig,
    result: BatchResult,
    bar: _Progress,
    on_event: Event | None,
) -> None:
    queue = collections.deque(todo)
    running: dict[int, tuple[Job, float]] = {}

    def finish(job: Job, record: dict[str, Any], files: dict[str, bytes] | None = None) -> None:
        result.records[job.id] = full = store.write(job, record, files)
        result.ran += 1
        bar.advance(full)
        if on_event is not None:
            on_event("finished", job, full)

    backend.start()
    while queue or running:
        for slot in backend.idle():
            if slot in running or not queue:
                continue
            job = queue.popleft()
            try:
                item = payload(job)
            except ControlMMError as exc:
                finish(job, {"status": "error", "error": str(exc), "seconds": 0.0})
                continue
            backend.submit(slot, item)
            running[slot] = (job, time.perf_counter())
            if on_event is not None:
                on_event("started", job, backend.worker(slot))
        wait = TICK_S
        if config.timeout_s is not None and running:
            first = min(t for _, t in running.values())
            wait = max(0.0, min(wait, first + config.timeout_s - time.perf_counter()))
        for done in backend.wait(wait):
            job, started = running.pop(done.slot)
            if done.outcome is not None:
                finish(job, done.outcome["record"], done.outcome["files"])
            else:
                seconds = round(time.perf_counter() - started, 3)
                finish(job, {"status": "crashed", "error": done.error, "seconds": seconds})
        if config.timeout_s is not None:
            now = time.perf_counter()
            for slot, (job, started) in list(running.items()):
                if now - started > config.timeout_s:
                    worker = backend.worker(slot).get("worker")
                    backend.kill(slot)
                    del running[slot]
                    error = f"ran longer than the timeout of {config.timeout_s:g} s; its worker was stopped"
                    finish(
                        job,
                        {
                            "status": "timeout",
                            "error": error,
                            "seconds": round(now - started, 3),
                            "worker": worker,
                        },
                    )
        bar.refresh()


def _write_run(out: Path, config: BatchConfig, backend: Backend, jobs: Sequence[Job]) -> None:
    """``batch.json``: how this run was started (the last run's)."""
    info = {
        "controlmm": __version__,
        "started": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
        "config": asdict(config),
        "backend": backend.name,
        "jobs": len(jobs),
        "sources": sorted({job.source.rsplit(":", 1)[0] for job in jobs})[:20],
    }
    write_text(out / "batch.json", json.dumps(info, indent=1) + "\n")


class _Progress:
    """The progress bar: jobs done of all, passed/failed/errors, this run's jobs per minute, ETA."""

    def __init__(self, enabled: bool, jobs: Sequence[Job], records: dict[str, dict[str, Any]]) -> None:
        self.statuses = collections.Counter(str(r.get("status")) for r in records.values())
        self.ran = 0
        self.start = time.perf_counter()
        self.bar = tqdm(
            total=len(jobs),
            initial=len(records),
            unit="job",
            desc="batch",
            disable=None if enabled else True,  # None: off when stderr is not a terminal
            dynamic_ncols=True,
            smoothing=0.1,
        )
        self._postfix()

    def advance(self, record: dict[str, Any]) -> None:
        status = str(record.get("status"))
        self.statuses[status] += 1
        self.ran += 1
        if status not in ("passed", "done"):
            why = record.get("error") or ", ".join(sorted(record.get("failure_kinds") or {}))
            self.bar.write(f"batch: {record['id']}: {status}{': ' + str(why)[:160] if why else ''}")
        self.bar.update(1)
        self._postfix()

    def _postfix(self) -> None:
        elapsed = time.perf_counter() - self.start
        rate = self.ran / elapsed * 60 if self.ran and elapsed > 0 else 0.0
        errors = sum(self.statuses[s] for s in RETRY_STATUSES)
        self.bar.set_postfix_str(
            f"{self.statuses['passed']} passed, {self.statuses['failed']} failed, {errors} errors, "
            f"{rate:.1f} jobs/min",
            refresh=False,
        )

    def refresh(self) -> None:
        self.bar.refresh()

    def close(self) -> None:
        self.bar.close()
