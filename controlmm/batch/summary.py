"""The batch summary: ``summary.csv`` / ``summary.json`` (one row per job) and ``summary.md``.

Statuses: ``passed`` and ``failed`` (the simulation checks' verdict), ``done`` (ran, nothing to
check), ``error`` (the job could not run: bad input, an exception), ``crashed`` (its worker died),
``timeout`` (stopped after ``--timeout`` seconds), ``pending`` (not run yet: the batch was
stopped). A pass rate is ``passed / (jobs run with a verdict)``: every status but ``done`` and
``pending`` counts in the denominator.
"""

from __future__ import annotations

import csv
import io
import json
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from controlmm.atomic import write_text
from controlmm.batch.jobs import Job

STATUSES = ("passed", "failed", "done", "error", "crashed", "timeout", "pending")
COLUMNS = (
    "id",
    "kind",
    "input",
    "robot",
    "scene",
    "family",
    "status",
    "failure_kinds",
    "max_penetration_m",
    "floor_penetration_m",
    "foot_sliding_m",
    "max_constraint_error_m",
    "constraint_errors_m",
    "frames",
    "seconds",
    "worker",
    "error",
    "source",
)
"""The columns of ``summary.csv`` (and the keys of ``summary.json``'s rows)."""

SUMMARY_FORMAT = "controlmm.batch.summary/1"
MD_FAILURES = 100
"""Jobs that did not pass listed in ``summary.md`` (all of them are in the CSV)."""


def summary_rows(jobs: Sequence[Job], records: dict[str, dict[str, Any]]) -> list[dict[str, Any]]:
    """One row per job, in job order (``pending`` for a job without a record)."""
    rows = []
    for job in jobs:
        record = records.get(job.id)
        base = {"id": job.id, "kind": job.kind, "input": job.input, "robot": job.robot}
        base.update(scene=job.scene, family=job.family, source=job.source, status="pending")
        row = {key: (record or {}).get(key, base.get(key)) for key in COLUMNS}
        row["failure_kinds"] = row["failure_kinds"] or {}
        row["constraint_errors_m"] = row["constraint_errors_m"] or []
        rows.append(row)
    return rows


def counts(rows: Sequence[dict[str, Any]]) -> dict[str, Any]:
    """``{"jobs", <status>: n for every status, "pass_rate"}`` of some rows."""
    out: dict[str, Any] = {"jobs": len(rows), **{s: 0 for s in STATUSES}}
    for row in rows:
        out[row["status"]] += 1
    judged = len(rows) - out["done"] - out["pending"]
    out["pass_rate"] = round(out["passed"] / judged, 4) if judged else None
    return out


def grouped(rows: Sequence[dict[str, Any]], key: str) -> dict[str, dict[str, Any]]:
    """:func:`counts` per value of ``key`` (``scene``, ``robot`` or ``family``; ``-`` for none)."""
    groups: dict[str, list[dict[str, Any]]] = {}
    for row in rows:
        groups.setdefault(str(row[key] or "-"), []).append(row)
    return {name: counts(group) for name, group in sorted(groups.items())}


def write_summary(
    out: str | Path,
    jobs: Sequence[Job],
    records: dict[str, dict[str, Any]],
    extra: dict[str, Any] | None = None,
) -> dict[str, Any]:
    """Write ``summary.csv``, ``summary.json`` and ``summary.md`` into ``out``; return the JSON."""
    out = Path(out)
    rows = summary_rows(jobs, records)
    summary = {
        "format": SUMMARY_FORMAT,
        **(extra or {}),
        "counts": counts(rows),
        "by_scene": grouped(rows, "scene"),
        "by_robot": grouped(rows, "robot"),
        "by_family": grouped(rows, "family"),
        "jobs": rows,
    }
    write_text(out / "summary.json", json.dumps(summary, indent=1, default=str) + "\n")
    write_text(out / "summary.csv", _csv(rows))
    write_text(out / "summary.md", _markdown(summary))
    return summary


def _cell(key: str, value: Any) -> str:
    if value is None:
        return ""
    if key == "failure_kinds":
        return ";".join(f"{k}:{n}" for k, n in sorted(value.items()))
    if key == "constraint_errors_m":
        return ";".join(f"{e:g}" for e in value)
    return str(value)


def _csv(rows: Sequence[dict[str, Any]]) -> str:
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow(COLUMNS)
    for row in rows:
        writer.writerow([_cell(key, row[key]) for key in COLUMNS])
    return buffer.getvalue()


def _rate(value: float | None) -> str:
    return "-" if value is None else f"{value * 100:.1f} %"


def _table(title: str, groups: dict[str, dict[str, Any]]) -> list[str]:
    lines = [
        f"## Pass rate by {title}",
        "",
        f"| {title} | jobs | passed | failed | error | crashed | timeout | pending | pass rate |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for name, c in groups.items():
        lines.append(
            f"| {name} | {c['jobs']} | {c['passed']} | {c['failed']} | {c['error']} | {c['crashed']} "
            f"| {c['timeout']} | {c['pending']} | {_rate(c['pass_rate'])} |"
        )
    return [*lines, ""]


def _markdown(summary: dict[str, Any]) -> str:
    c = summary["counts"]
    lines = [
        "# Batch summary",
        "",
        f"{c['jobs']} jobs: {c['passed']} passed, {c['failed']} failed their checks, {c['done']} done "
        f"without checks, {c['error']} errors, {c['crashed']} crashed, {c['timeout']} timed out, "
        f"{c['pending']} pending; pass rate {_rate(c['pass_rate'])}.",
        "",
    ]
    for key in ("scene", "robot", "family"):
        lines += _table(key, summary[f"by_{key}"])
    bad = [r for r in summary["jobs"] if r["status"] not in ("passed", "done")]
    if bad:
        lines += [
            "## Jobs that did not pass",
            "",
            "| id | status | failure kinds or error |",
            "|---|---|---|",
        ]
        for row in bad[:MD_FAILURES]:
            why = _cell("failure_kinds", row["failure_kinds"]) or (row["error"] or "").replace("|", "/")
            lines.append(f"| {row['id']} | {row['status']} | {why[:200]} |")
        if len(bad) > MD_FAILURES:
            lines.append(f"\n... and {len(bad) - MD_FAILURES} more (see summary.csv)")
        lines.append("")
    return "\n".join(lines)
