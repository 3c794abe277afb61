"""What the driver sends a worker for one job: its arguments resolved, its input file inside.

A worker may run on another machine (a Ray cluster), so the files a job starts from travel
with it: the motion of a ``retarget`` job and the trajectory of a ``validate`` job as bytes,
a plan's control spec as its JSON. Other paths (a scene or robot file, a model directory, a
timeline) are made absolute and must be readable where the workers run.
"""

from __future__ import annotations

import json
from collections import Counter
from collections.abc import Sequence
from typing import Any

from controlmm.batch.jobs import Job
from controlmm.errors import ControlMMError, InputFileError
from controlmm.files import input_file

INPUT_FILES = {"retarget": ("motion", "motion file"), "validate": ("trajectory", "trajectory file")}
"""The argument of each kind that names the file the job starts from (sent as bytes), and its label."""

PATHS = ("scene", "robot", "model", "timeline")

WORLD_CACHE = 8
"""Scenes (with their check worlds) a worker keeps (the most recently used)."""


def plan_models(jobs: Sequence[Job]) -> list[str | None]:
    """The model directories the plan jobs use (None: the embedded default), as workers receive them."""
    models = set()
    for job in jobs:
        if job.kind == "plan":
            path = job.path("model")
            models.add(str(path.resolve()) if path is not None else None)
    return sorted(models, key=str)


def check_worlds(jobs: Sequence[Job], most: int = WORLD_CACHE) -> list[tuple[str, str]]:
    """The (scene, robot) pairs the retarget and validate jobs check in, as the workers' tasks name
    them (files as absolute paths): at most ``most`` (the worlds a worker keeps), the most used first."""
    counts: Counter[tuple[str, str]] = Counter()
    for job in jobs:
        if job.kind in INPUT_FILES and not job.error:
            scene, robot = (_argument(job, key) for key in ("scene", "robot"))
            counts[(scene or "empty", robot or "g1")] += 1
    return [world for world, _ in counts.most_common(most)]


def _argument(job: Job, key: str) -> str | None:
    """A scene or robot argument as :func:`payload` sends it."""
    path = job.path(key)
    return str(path.resolve()) if path is not None else job.args.get(key)


def payload(job: Job) -> dict[str, Any]:
    """``{"id", "kind", "args"}`` for :func:`controlmm.batch.worker.run_job`.

    Raises:
        ControlMMError: an input file is missing or unreadable now, or the control spec is not JSON.
    """
    if job.error:
        raise ControlMMError(job.error)
    args = dict(job.args)
    if job.kind in INPUT_FILES:
        key, label = INPUT_FILES[job.kind]
        path = job.path(key)
        if path is None:
            raise ControlMMError(f"{job.source}: a {job.kind} job needs '{key}'")
        args[key] = {"name": args[key], "data": input_file(path, label).read_bytes()}
    control = job.path("control")
    if control is not None:
        path = input_file(control, "control spec")
        try:
            args["control"] = json.loads(path.read_text(encoding="utf-8"))
        except (UnicodeDecodeError, json.JSONDecodeError) as exc:
            raise InputFileError(f"control spec '{path}' is not valid JSON ({exc})") from None
    for name in PATHS:
        path = job.path(name)
        if path is not None:
            args[name] = str(path.resolve())
    if "variation" in args and "scene" in args:
        args["variation"] = {**args["variation"], "scene": args["scene"]}
    return {"id": job.id, "kind": job.kind, "args": args}
