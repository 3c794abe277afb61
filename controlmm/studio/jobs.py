"""Plans in a worker: a queue of checked requests, one thread that holds the loaded model.

```python
from controlmm.studio import PlanService, parse_plan_request

service = PlanService(workdir="studio-plans")          # loads the model in its worker
job = service.submit(parse_plan_request({"scene": "table", "seed": 1}))
service.wait(job.id)                                    # or poll job.status
job.status, job.report["passed"], job.files             # "done", ..., ["report.json", "robot.csv", ...]
```

One plan runs at a time (the planner is sequential and uses every core it is given), so the server
answers requests while a plan runs. Every plan writes its outputs with
:func:`controlmm.pipeline.write_plan` into ``workdir/<id>/`` and keeps its view (all rounds) for the
browser. A plan that fails with bad input or an internal error marks its job ``failed`` with one
line; the worker goes on with the next.
"""

from __future__ import annotations

import io
import json
import queue
import re
import threading
import time
import uuid
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import torch

from controlmm.errors import ControlMMError
from controlmm.generate import MotionModel, load_model
from controlmm.pipeline import PlanConfig, PlanResult, plan, write_plan
from controlmm.studio.schema import PlanRequest
from controlmm.studio.view import dir_view, is_plan_dir, plan_files, plan_view, scene_geometry
from scenes import Scene, load_scene

STATUSES = ("queued", "running", "done", "failed")
WARM_UP_TEXT = "a person walks forward"
_ROUND = re.compile(r"^round (\d+):")


@dataclass
class PlanJob:
    """One plan: its request, where it stands, and (once done) its report, files and view.

    Attributes:
        id: the job's id (hex), also its folder name under the service's workdir.
        config: what is planned (None for a finished plan opened from disk).
        status: one of :data:`STATUSES`.
        progress: the planner's stage lines so far ("round 0: generating ...").
        round: the round being planned (None before the first).
        error: the one-line reason of a failed job.
        report: ``report.json`` of a done job.
        out_dir: the plan's output directory; files: its downloadable files (relative names).
    """

    id: str
    config: PlanConfig | None
    status: str = "queued"
    created: float = field(default_factory=time.time)
    started: float | None = None
    finished: float | None = None
    progress: list[str] = field(default_factory=list)
    round: int | None = None
    error: str | None = None
    report: dict[str, Any] | None = None
    out_dir: Path | None = None
    files: list[str] = field(default_factory=list)
    view: bytes | None = None

    def to_dict(self, report: bool = True) -> dict[str, Any]:
        """The job as ``GET /api/plans/{id}`` answers it."""
        out: dict[str, Any] = {"id": self.id, "status": self.status, "progress": list(self.progress)}
        if self.config is not None:
            out["rounds_allowed"] = self.config.rounds
            out["scene"] = self.config.scene
            out["text"] = self.config.text
        out["round"] = self.round
        if self.started is not None:
            end = self.finished if self.finished is not None else time.time()
            out["seconds"] = round(end - self.started, 3)
        if self.error is not None:
            out["error"] = self.error
        if self.status == "done":
            out["files"] = list(self.files)
            if report:
                out["report"] = self.report
            elif self.report is not None:
                out["passed"] = bool(self.report.get("passed"))
        return out


class _JobLog(io.StringIO):
    """The planner's stage log, line by line into ``job.progress``."""

    def __init__(self, job: PlanJob, lock: threading.Lock) -> None:
        super().__init__()
        self._job, self._lock, self._buffer = job, lock, ""

    def write(self, text: str) -> int:
        self._buffer += text
        *lines, self._buffer = self._buffer.split("\n")
        with self._lock:
            for line in lines:
                line = line.removeprefix("controlmm plan: ").strip()
                if line:
                    self._job.progress.append(line)
                    match = _ROUND.match(line)
                    if match:
                        self._job.round = int(match.group(1))
        return len(text)


class PlanService:
    """The plan queue and its worker thread (see the module docstring).

    Args:
        workdir: where every plan's outputs go (``workdir/<id>/``); created if missing.
        model: model directory (None: the embedded default model); None with ``load=False``.
        load: load the model and start the worker (False: a viewer of finished plans only).
        threads: torch threads of the worker (None: torch's default).
    """

    def __init__(
        self, workdir: str | Path, model: str | None = None, load: bool = True, threads: int | None = None
    ) -> None:
        self.workdir = Path(workdir)
        self.workdir.mkdir(parents=True, exist_ok=True)
        self.model_dir = model
        self.threads = threads
        self.model_state = "loading" if load else "none"
        self.model_error: str | None = None
        self._model: MotionModel | None = None
        self._jobs: dict[str, PlanJob] = {}
        self._lock = threading.Lock()
        self._queue: queue.Queue[PlanJob | None] = queue.Queue()
        self._geometry: dict[tuple[str, int, str], str] = {}
        self._geometry_docs: dict[str, bytes] = {}
        self._worker: threading.Thread | None = None
        if load:
            self._worker = threading.Thread(target=self._work, name="controlmm-plan-worker", daemon=True)
            self._worker.start()

    # ----------------------------------------------------------------------------- jobs
    def submit(self, request: PlanRequest) -> PlanJob:
        """Queue a checked request; returns its job (status ``queued``)."""
        if self._worker is None:
            raise ControlMMError("this server only views finished plans (controlmm view); plan with studio")
        if self.model_state == "failed":
            raise ControlMMError(f"the model did not load: {self.model_error}")
        job = PlanJob(id=uuid.uuid4().hex[:12], config=request.config)
        with self._lock:
            self._jobs[job.id] = job
        self._queue.put(job)
        return job

    def add_finished(self, path: str | Path, job_id: str | None = None) -> PlanJob:
        """Register a finished plan directory (``controlmm plan`` output) as a done job."""
        root = Path(path)
        if not is_plan_dir(root):
            raise ControlMMError(f"'{root}' is not a plan output (report.json, robot.npz, motion.npz)")
        name = job_id or re.sub(r"[^A-Za-z0-9_.-]", "_", root.resolve().name) or "plan"
        try:
            report = json.loads((root / "report.json").read_text(encoding="utf-8"))
        except (OSError, json.JSONDecodeError) as exc:
            raise ControlMMError(f"cannot read '{root / 'report.json'}': {exc}") from None
        job = PlanJob(id=name, config=None, status="done", report=report, out_dir=root)
        job.files = plan_files(root)
        job.progress = ["finished plan opened from disk"]
        with self._lock:
            if name in self._jobs:
                raise ControlMMError(f"two plans named '{name}'")
            self._jobs[name] = job
        return job

    def get(self, job_id: str) -> PlanJob | None:
        with self._lock:
            return self._jobs.get(job_id)

    def jobs(self) -> list[PlanJob]:
        with self._lock:
            return sorted(self._jobs.values(), key=lambda j: j.created)

    def wait(self, job_id: str, timeout: float | None = None) -> PlanJob:
        """Block until the job is done or failed (or ``timeout`` seconds pass); returns it."""
        end = None if timeout is None else time.monotonic() + timeout
        while True:
            job = self.get(job_id)
            if job is None:
                raise ControlMMError(f"no plan '{job_id}'")
            if job.status in ("done", "failed") or (end is not None and time.monotonic() > end):
                return job
            time.sleep(0.05)

    def view_json(self, job: PlanJob) -> bytes:
        """The job's view document (JSON bytes); built from its directory for finished plans."""
        if job.view is None:
            if job.out_dir is None or job.status != "done":
                raise ControlMMError(f"plan '{job.id}' is {job.status}; its view comes when it is done")
            view = dir_view(job.out_dir, geometry=self.geometry_id)
            job.view = json.dumps(view, allow_nan=False).encode()
        return job.view

    # ------------------------------------------------------------------------- geometry
    def geometry_id(self, scene: Scene) -> str:
        """Id of the scene's drawn geometry (built once per scene file and robot)."""
        stat = scene.path.stat()
        key = (str(scene.path), stat.st_mtime_ns, str(scene.robot))
        with self._lock:
            gid = self._geometry.get(key)
        if gid is None:
            doc = json.dumps(scene_geometry(scene), allow_nan=False).encode()
            gid = uuid.uuid5(uuid.NAMESPACE_URL, repr(key)).hex[:16]
            with self._lock:
                self._geometry[key] = gid
                self._geometry_docs[gid] = doc
        return gid

    def geometry_json(self, gid: str) -> bytes | None:
        with self._lock:
            return self._geometry_docs.get(gid)

    def preview(self, scene_ref: str, robot: str) -> tuple[Scene, str]:
        """A scene with the robot at its start, and its geometry id (for placing targets)."""
        scene = load_scene(scene_ref, robot=robot)
        return scene, self.geometry_id(scene)

    # --------------------------------------------------------------------------- worker
    def close(self, timeout: float = 5.0) -> None:
        """Stop the worker after the plan it runs (queued plans are dropped)."""
        if self._worker is not None:
            self._queue.put(None)
            self._worker.join(timeout)

    def _work(self) -> None:
        if self.threads is not None:
            torch.set_num_threads(self.threads)  # per thread: the worker's own OpenMP setting
        try:
            model = load_model(self.model_dir)
            model.encode_text([WARM_UP_TEXT])  # the text encoder loads on first use: load it now, once
            self._model = model
            self.model_state = "ready"
        except Exception as exc:  # noqa: BLE001 - reported on every request, the server keeps running
            self.model_state, self.model_error = "failed", _one_line(exc)
        while True:
            job = self._queue.get()
            if job is None:
                return
            self._run(job)

    def _run(self, job: PlanJob) -> None:
        assert job.config is not None
        with self._lock:
            job.status, job.started = "running", time.time()
        try:
            if self._model is None:
                raise ControlMMError(f"the model did not load: {self.model_error}")
            result = plan(job.config, model=self._model, progress=True, log=_JobLog(job, self._lock))
            out = self.workdir / job.id
            self._say(job, "writing the files")
            write_plan(result, out, progress=False)
            files = plan_files(out)
            view = plan_view(result, files, geometry=self.geometry_id(result.scene))
            with self._lock:
                job.out_dir, job.files = out, files
                job.report = result.to_dict()
                job.view = json.dumps(view, allow_nan=False).encode()
                job.status, job.finished = "done", time.time()
                job.progress.append(_verdict(result))
        except Exception as exc:  # noqa: BLE001 - one failed plan must not stop the service
            with self._lock:
                job.error = _one_line(exc)
                job.status, job.finished = "failed", time.time()

    def _say(self, job: PlanJob, line: str) -> None:
        with self._lock:
            job.progress.append(line)


def _verdict(result: PlanResult) -> str:
    return (
        f"{'PASSED' if result.passed else 'FAILED'} in round {result.best} of {len(result.rounds)}, "
        f"{result.seconds:.1f} s"
    )


def _one_line(exc: BaseException) -> str:
    text = " ".join(str(exc).split())
    return text if isinstance(exc, ControlMMError) else f"internal error: {type(exc).__name__}: {text}"
