"""The batch folder: one folder per job, each written atomically, found again by its id.

Layout of ``DIR``::

    .controlmm-output.json   {"kind": "batch", "files": null}: a batch folder, resumable
    batch.json               how the last run was started (jobs, backend, workers, timeout)
    jobs/<id>/result.json    the job's record: status, figures, error, seconds, worker, job spec
    jobs/<id>/...            its files: robot.csv/.npz/.json, report.json (plan: motion.npz, ...)
    summary.csv / .json / .md

A job folder appears complete or not at all (:func:`controlmm.atomic.atomic_dir`): a batch that
is killed leaves finished jobs and nothing half-written, and the next run skips every job whose
``result.json`` holds the same job spec.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from controlmm.atomic import atomic_dir
from controlmm.batch.jobs import Job

BATCH_OUTPUT = "batch"
"""The output kind of a batch folder (:data:`controlmm.atomic.OUTPUT_MARKER`)."""

JOB_OUTPUT = "batch-job"
RESULT = "result.json"
RECORD_FORMAT = "controlmm.batch.job/1"
RETRY_STATUSES = ("error", "crashed", "timeout")
"""Statuses a rerun with ``retry_errors`` runs again (the others are final)."""


def _canonical(value: Any) -> str:
    return json.dumps(value, sort_keys=True, default=str)


class BatchStore:
    """Read and write the job folders of a batch folder ``out``."""

    def __init__(self, out: str | Path) -> None:
        self.out = Path(out)
        self.jobs = self.out / "jobs"

    def job_dir(self, job_id: str) -> Path:
        return self.jobs / job_id

    def load(self, job: Job) -> dict[str, Any] | None:
        """The record of ``job`` when it finished with the same spec; else None."""
        try:
            record = json.loads((self.job_dir(job.id) / RESULT).read_text(encoding="utf-8"))
        except (OSError, ValueError):
            return None
        if not isinstance(record, dict) or _canonical(record.get("job")) != _canonical(job.spec()):
            return None
        return record

    def write(
        self, job: Job, record: dict[str, Any], files: dict[str, bytes] | None = None
    ) -> dict[str, Any]:
        """Write the job's folder (its files and ``result.json``) in one piece; return the full record."""
        full = {
            "format": RECORD_FORMAT,
            "id": job.id,
            "kind": job.kind,
            "source": job.source,
            "family": job.family,
            "input": job.input,
            "scene": job.scene,
            "robot": job.robot,
            **record,
            "files": sorted(files or {}),
            "job": job.spec(),
        }
        with atomic_dir(self.job_dir(job.id), kind=JOB_OUTPUT, force=True, make_parents=True) as tmp:
            for name, data in (files or {}).items():
                path = tmp / name
                path.parent.mkdir(parents=True, exist_ok=True)
                path.write_bytes(data)
            (tmp / RESULT).write_text(json.dumps(full, indent=1, default=str) + "\n", encoding="utf-8")
        return full
