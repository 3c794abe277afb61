"""Where a batch's jobs come from: a JSONL file or a folder of motions.

**A JSONL file**: one job per line (:mod:`.jobs` gives the format); relative paths are relative to
the file's folder; blank lines and lines starting with ``#`` are skipped. A line that cannot be
read (not JSON, an unknown kind or key, a wrong type, a missing file) becomes a job with an
``error`` naming its line number: it is recorded as failed and never run.

**A folder of motions** (``.npz``, ``.npy``, ``.bvh``, ``.csv``, searched recursively, hidden
entries skipped; for a HumanML3D-format folder ``new_joint_vecs/*.npy`` only, families from
``meta/<id>.json``) gives one ``retarget`` job per motion and robot: retarget, then validate in
the scene.
"""

from __future__ import annotations

import hashlib
import json
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import Any

from controlmm.batch.jobs import Job, file_safe, parse_job, short_name
from controlmm.errors import ControlMMError
from controlmm.files import input_dir, input_file

MOTION_SUFFIXES = (".npz", ".npy", ".bvh", ".csv")
"""Files of a folder of motions (a ``.csv``: 22 x 3 joint columns, or a robot trajectory)."""


def read_jsonl(path: str | Path) -> list[Job]:
    """Every job of a JSONL file; a line that cannot be read gives a job with ``error`` set."""
    path = input_file(path, "jobs file")
    base = path.resolve().parent
    jobs: list[Job] = []
    try:
        lines = path.read_text(encoding="utf-8").splitlines()
    except UnicodeDecodeError as exc:
        raise ControlMMError(f"jobs file '{path}' is not UTF-8 text ({exc.reason})") from None
    for number, line in enumerate(lines, start=1):
        text = line.strip()
        if not text or text.startswith("#"):
            continue
        source = f"{path.name}:{number}"
        try:
            try:
                entry = json.loads(text)
            except json.JSONDecodeError as exc:
                raise ControlMMError(f"{source}: not valid JSON ({exc.msg} at column {exc.colno})") from None
            jobs.extend(parse_job(entry, base=base, source=source))
        except ControlMMError as exc:
            jobs.append(Job(f"line-{number}", "invalid", {"line": number}, str(base), source, error=str(exc)))
    return jobs


def motion_files(folder: str | Path) -> tuple[Path, list[Path], dict[str, str]]:
    """``(folder, motion files sorted, family by file)`` of a folder of motions.

    A HumanML3D-format folder (``new_joint_vecs/``) gives ``new_joint_vecs/*.npy`` with the
    ``family`` of ``meta/<id>.json`` where present; any other folder every motion file below it
    (hidden entries skipped), its family the file's folder.
    """
    root = input_dir(folder, "motion folder").resolve()
    families: dict[str, str] = {}
    if (root / "new_joint_vecs").is_dir():
        files = sorted((root / "new_joint_vecs").glob("*.npy"))
        for f in files:
            meta = root / "meta" / f"{f.stem}.json"
            if meta.is_file():
                try:
                    families[str(f)] = str(json.loads(meta.read_text(encoding="utf-8")).get("family", ""))
                except (OSError, ValueError, AttributeError):
                    pass
        return root, files, families
    files = sorted(
        p
        for p in root.rglob("*")
        if p.suffix.lower() in MOTION_SUFFIXES
        and p.is_file()
        and not any(part.startswith(".") for part in p.relative_to(root).parts)
    )
    for f in files:
        parent = f.parent.relative_to(root).as_posix()
        families[str(f)] = "" if parent == "." else parent
    return root, files, families


def folder_jobs(
    folder: str | Path,
    robots: Sequence[str] = ("g1",),
    *,
    scene: str = "empty",
    fps: float = 50.0,
    csv_fps: float = 30.0,
) -> list[Job]:
    """One ``retarget`` job (retarget, then validate in ``scene``) per motion file and robot.

    Ids are ``<path below the folder>.<robot>`` (``/`` -> ``__``), e.g. ``walks__012314.npy.g1``.
    """
    root, files, families = motion_files(folder)
    if not files:
        raise ControlMMError(f"motion folder '{folder}' holds no motion files ({', '.join(MOTION_SUFFIXES)})")
    jobs = []
    for f in files:
        rel = f.relative_to(root).as_posix()
        for robot in robots:
            args: dict[str, Any] = {"motion": rel, "robot": robot, "fps": fps, "scene": scene}
            if f.suffix.lower() == ".csv":
                args["csv_fps"] = csv_fps
            name = file_safe(rel.replace("/", "__"))
            jid = f"{name}.{file_safe(short_name(robot))}"[-100:].lstrip("._-")
            jobs.append(Job(jid, "retarget", args, str(root), rel, families.get(str(f), "")))
    return jobs


def duplicate_ids(jobs: Iterable[Job]) -> list[Job]:
    """``jobs`` with a later job whose id is taken turned into an error entry (never run)."""
    seen: dict[str, str] = {}
    out = []
    for job in jobs:
        if job.id in seen:
            error = f"{job.source}: job id '{job.id}' is already used by {seen[job.id]}"
            job = Job(f"{job.id}-dup-{_digest(job.source)}", "invalid", {}, job.base, job.source, error=error)
        seen.setdefault(job.id, job.source)
        out.append(job)
    return out


def _digest(text: str) -> str:
    return hashlib.sha1(text.encode()).hexdigest()[:6]


def load_jobs(
    source: str | Path,
    robots: Sequence[str] | None = None,
    *,
    scene: str | None = None,
    fps: float | None = None,
    csv_fps: float = 30.0,
    strict: bool = False,
) -> list[Job]:
    """The jobs of a JSONL file or a folder of motions (see the module docstring), ids unique.

    ``robots``, ``scene`` and ``fps`` apply to a folder (defaults ``g1``, ``empty``, 50 Hz); a
    JSONL file's jobs carry their own. With ``strict`` the first malformed entry raises its
    one-line ControlMMError instead of becoming an error job.
    """
    path = Path(source).expanduser()
    if path.is_dir():
        jobs = folder_jobs(path, robots or ("g1",), scene=scene or "empty", fps=fps or 50.0, csv_fps=csv_fps)
    else:
        for name, value in (("--robot", robots), ("--scene", scene), ("--fps", fps)):
            if value:
                raise ControlMMError(
                    f"{name} applies to a folder of motions; a JSONL job names its own ('{name[2:]}')"
                )
        jobs = read_jsonl(path)
    jobs = duplicate_ids(jobs)
    if strict:
        for job in jobs:
            if job.error:
                raise ControlMMError(job.error)
    if not jobs:
        raise ControlMMError(f"'{source}' holds no jobs")
    return jobs
