"""Batch jobs: one ``plan``, ``retarget`` or ``validate`` run each, with stable ids.

A job is written as a JSON object, ``{"kind": ..., <arguments>}``, with the arguments of the
command of that name (:data:`FIELDS` lists them with their JSON types)::

    {"kind": "plan", "scene": "pillars", "seed": 3, "rounds": 1, "preset": "fast"}
    {"kind": "retarget", "motion": "walk.npz", "robot": "h1", "scene": "table"}
    {"kind": "validate", "trajectory": "robot.csv", "robot": "g1", "fps": 30, "scene": "empty"}
    {"kind": "variations", "scene": "table", "count": 20, "jitter_m": 0.1, "variation_seed": 0}

``variations`` is a generator: ``count`` plan jobs in copies of ``scene`` whose static obstacles
are moved by up to ``jitter_m`` metres in x and y (seeded by ``variation_seed`` and the copy's
index); it takes every ``plan`` argument too. Any job may name its ``id`` (letters, digits,
``.``, ``_``, ``-``) and its ``family`` (a group of the summary). Job ids are stable: the given
``id``, else the kind, a readable name and a hash of the arguments, so a rerun finds the jobs it
already ran. Where jobs come from (JSONL files, folders of motions): :mod:`.sources`.
"""

from __future__ import annotations

import hashlib
import json
import math
import re
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from controlmm.errors import ControlMMError
from controlmm.files import input_dir, input_file
from controlmm.seeds import SEED_MAX

KINDS = ("plan", "retarget", "validate")
"""Kinds of job a batch runs."""

GENERATORS = ("variations",)
"""JSONL kinds that stand for several jobs."""

MAX_VARIATIONS = 10_000
_ID = re.compile(r"^[A-Za-z0-9][A-Za-z0-9._-]{0,99}$")
_UNSAFE = re.compile(r"[^A-Za-z0-9._-]+")

_NUMBER = (int, float)
_PLAN_FIELDS: dict[str, tuple[type, ...]] = {
    "scene": (str,),
    "text": (str,),
    "control": (str, dict),
    "timeline": (str, dict),
    "robot": (str,),
    "seconds": _NUMBER,
    "seed": (int,),
    "rounds": (int,),
    "preset": (str,),
    "model": (str,),
    "fps": _NUMBER,
    "safe_distance": _NUMBER,
    "render": (bool,),
    "plots": (bool,),
}
FIELDS: dict[str, dict[str, tuple[type, ...]]] = {
    "plan": _PLAN_FIELDS,
    "retarget": {
        "motion": (str,),
        "robot": (str,),
        "fps": _NUMBER,
        "scene": (str,),
        "x": _NUMBER,
        "y": _NUMBER,
        "yaw": _NUMBER,
        "validate": (bool,),
        "csv_fps": _NUMBER,
    },
    "validate": {"trajectory": (str,), "scene": (str,), "robot": (str,), "fps": _NUMBER},
    "variations": {**_PLAN_FIELDS, "count": (int,), "jitter_m": _NUMBER, "variation_seed": (int,)},
}
"""The arguments of each kind and their JSON types (``id``, ``kind`` and ``family`` besides)."""

REQUIRED = {"retarget": ("motion",), "validate": ("trajectory",), "variations": ("count",)}
_INPUT_FILES = {"retarget": "motion", "validate": "trajectory"}
_COMMON = ("id", "kind", "family")


@dataclass(frozen=True)
class Job:
    """One run of a batch.

    Attributes:
        id: stable identifier, also the name of the job's output folder.
        kind: ``plan``, ``retarget`` or ``validate`` (``error`` set: the entry could not be read).
        args: the arguments as written (JSON types; paths as given, relative to ``base``).
        base: folder that relative paths in ``args`` are relative to.
        source: where the job came from (``jobs.jsonl:3``, a motion file).
        family: the summary's group (given in the JSONL; for a folder, the motion's folder or its
            corpus family).
        error: why the entry is malformed (the job is recorded as an error, never run).
    """

    id: str
    kind: str
    args: dict[str, Any] = field(default_factory=dict)
    base: str = "."
    source: str = ""
    family: str = ""
    error: str | None = None

    def spec(self) -> dict[str, Any]:
        """What the job runs: a finished job is reused only while its spec is unchanged."""
        return {"kind": self.kind, "args": self.args, "error": self.error}

    def path(self, key: str) -> Path | None:
        """Argument ``key`` as a path (relative ones under :attr:`base`), or None when it names none.

        ``scene`` and ``robot`` are paths when they end in ``.xml`` / ``.json`` or hold a ``/``
        (else packaged names); the other path arguments always are.
        """
        value = self.args.get(key)
        if not isinstance(value, str):
            return None
        if key in ("scene", "robot") and not (value.lower().endswith((".xml", ".json")) or "/" in value):
            return None
        path = Path(value).expanduser()
        return path if path.is_absolute() else Path(self.base) / path

    @property
    def scene(self) -> str:
        """The scene named by the job (the plan default ``table``, ``empty`` for the others)."""
        variation = self.args.get("variation")
        if isinstance(variation, dict):  # a jittered copy: grouped with its scene
            return short_name(variation["scene"])
        return short_name(self.args.get("scene") or ("table" if self.kind == "plan" else "empty"))

    @property
    def robot(self) -> str:
        return short_name(self.args.get("robot") or "g1")

    @property
    def input(self) -> str:
        """The motion, trajectory or prompt the job starts from."""
        if self.kind == "plan":
            timeline = self.args.get("timeline")
            if timeline is not None:
                return f"timeline {timeline}" if isinstance(timeline, str) else "(a timeline)"
            return str(self.args.get("text") or "(the scene's prompt)")
        return str(self.args.get(_INPUT_FILES.get(self.kind, ""), ""))


def file_safe(name: str) -> str:
    """``name`` with every run of characters other than letters, digits, ``.``, ``_``, ``-`` as ``_``."""
    return _UNSAFE.sub("_", name)


def short_name(name: str) -> str:
    """A scene or robot as the summary shows it: the name, or a file's stem."""
    text = str(name)
    return Path(text).stem if text.lower().endswith((".xml", ".json")) else text


def job_id(kind: str, name: str, args: dict[str, Any]) -> str:
    """A stable id: ``kind-name-<8 hex of the arguments>`` (name made file-name safe)."""
    digest = hashlib.sha1(json.dumps([kind, args], sort_keys=True).encode()).hexdigest()[:8]
    slug = file_safe(name).strip("._-")[:60]
    return f"{kind}-{slug}-{digest}" if slug else f"{kind}-{digest}"


def check_job_id(value: object) -> str:
    """``value`` if it is a valid job id (it names a folder); else a one-line ControlMMError."""
    if not isinstance(value, str) or not _ID.match(value):
        raise ControlMMError(
            f"job id {value!r} is not allowed: use 1 to 100 letters, digits, '.', '_' or '-', "
            "starting with a letter or digit"
        )
    return value


def parse_job(entry: object, *, base: Path, source: str) -> list[Job]:
    """The job(s) of one JSONL entry (a ``variations`` line gives several).

    Raises:
        ControlMMError: the entry is not a job (names ``source``, the bad key and what is allowed).
    """
    if not isinstance(entry, dict):
        raise ControlMMError(f"{source}: expected a JSON object; got {type(entry).__name__}")
    kind = entry.get("kind")
    if kind not in FIELDS:
        allowed = ", ".join((*KINDS, *GENERATORS))
        raise ControlMMError(f"{source}: unknown job kind {kind!r}; allowed: {allowed}")
    fields = FIELDS[kind]
    args = {k: v for k, v in entry.items() if k not in _COMMON}
    for key, value in args.items():
        if key not in fields:
            raise ControlMMError(
                f"{source}: unknown key '{key}' for a {kind} job; allowed: {', '.join([*_COMMON, *fields])}"
            )
        _check_type(source, key, value, fields[key])
    for key in REQUIRED.get(kind, ()):
        if key not in args:
            raise ControlMMError(f"{source}: a {kind} job needs '{key}'")
    family = entry.get("family", "")
    if not isinstance(family, str):
        raise ControlMMError(f"{source}: 'family' must be a string; got {family!r}")
    try:
        given_id = check_job_id(entry["id"]) if "id" in entry else None
    except ControlMMError as exc:
        raise ControlMMError(f"{source}: {exc}") from None
    if kind == "variations":
        return scene_variations(args, base=base, source=source, id=given_id, family=family)
    job = Job(given_id or "", kind, args, str(base), source, family)
    _check_paths(job)
    return [_with_id(job, given_id)]


_TYPE_NAMES = {
    (str,): "a string",
    (int,): "a whole number",
    _NUMBER: "a number",
    (bool,): "true or false",
    (str, dict): "a string (a file) or an object",
}


def _check_type(source: str, key: str, value: object, types: tuple[type, ...]) -> None:
    ok = isinstance(value, types) and (bool in types or not isinstance(value, bool))
    if not ok or (isinstance(value, float) and not math.isfinite(value)):
        raise ControlMMError(f"{source}: '{key}' must be {_TYPE_NAMES[types]}; got {json.dumps(value)}")


_PATH_CHECKS: dict[str, tuple[str, Callable[[Path, str], Path]]] = {
    "motion": ("motion file", input_file),
    "trajectory": ("trajectory file", input_file),
    "timeline": ("timeline file", input_file),
    "control": ("control spec", input_file),
    "model": ("model directory", input_dir),
    "scene": ("scene file", input_file),
    "robot": ("robot file", input_file),
}


def _check_paths(job: Job) -> None:
    """Input files must exist now (a job is never started on a missing file)."""
    for key, (label, check) in _PATH_CHECKS.items():
        path = job.path(key)
        if path is not None:
            try:
                check(path, label)
            except ControlMMError as exc:
                raise ControlMMError(f"{job.source}: {exc}") from None


def _with_id(job: Job, given: str | None) -> Job:
    if given is not None:
        return job
    name = {"plan": job.scene, "retarget": f"{Path(job.input).stem}-{job.robot}"}.get(
        job.kind, f"{Path(job.input).stem}-{job.scene}"
    )
    if job.kind == "plan" and "seed" in job.args:
        name += f"-s{job.args['seed']}"
    return Job(job_id(job.kind, name, job.args), job.kind, job.args, job.base, job.source, job.family)


def scene_variations(
    args: dict[str, Any],
    *,
    base: Path | str = ".",
    source: str = "variations",
    id: str | None = None,
    family: str = "",
) -> list[Job]:
    """``count`` plan jobs in jittered copies of ``args["scene"]`` (the ``variations`` generator).

    ``args`` holds the plan arguments plus ``count`` (1..10000), ``jitter_m`` (the largest move of
    an obstacle in x and y, metres, default 0.1) and ``variation_seed`` (default 0). Copy ``k``
    moves every static obstacle body by offsets drawn from ``(variation_seed, k)``
    (:mod:`controlmm.batch.variations`). Ids are ``<id>-v<k>`` (``k`` from 0).
    """
    plan_args = {k: v for k, v in args.items() if k not in ("count", "jitter_m", "variation_seed")}
    count = args["count"]
    if not 1 <= count <= MAX_VARIATIONS:
        raise ControlMMError(f"{source}: 'count' must be from 1 to {MAX_VARIATIONS}; got {count}")
    jitter = float(args.get("jitter_m", 0.1))
    if not 0.0 <= jitter <= 2.0:
        raise ControlMMError(f"{source}: 'jitter_m' must be from 0 to 2 (metres); got {jitter:g}")
    seed = args.get("variation_seed", 0)
    if not 0 <= seed <= SEED_MAX:
        raise ControlMMError(f"{source}: 'variation_seed' must be from 0 to 2^63 - 1; got {seed}")
    scene = str(plan_args.get("scene", "table"))
    prefix = id or job_id("variations", short_name(scene), args)
    jobs = []
    for k in range(count):
        variation = {"scene": scene, "index": k, "jitter_m": jitter, "seed": seed}
        job = Job(f"{prefix}-v{k}", "plan", {**plan_args, "variation": variation}, str(base), source, family)
        _check_paths(job)
        jobs.append(job)
    return jobs
