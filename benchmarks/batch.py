"""Throughput of `controlmm batch`: jobs per minute on the local pool (1 and 2 workers) and on Ray.

    python benchmarks/batch.py [--jobs 96] [--frames 120] [--repeat 3] [--no-ray]

The jobs are retarget + validate jobs (G1, the empty scene) of ``--jobs`` clips of ``--frames``
frames cut from the HumanML3D sample 012314 (``$CONTROLMM_SHARED/data/humanml3d``), the job a
folder of motions gives. Each backend runs the same jobs into a fresh batch folder with
:func:`controlmm.batch.run_batch`:

* local pool, 1 worker; local pool, 2 workers; a local Ray started with 2 CPUs, 2 actors;
* start-up: from the call to the first job handed to a worker (processes started, torch and
  MuJoCo imported); run: from there to the last job written;
* jobs/min = jobs / run x 60 (every worker's first, colder job included); scaling = 2 workers'
  jobs/min over 1 worker's (goal >= 1.8x); job s and job CPU s: a job's wall and CPU time in its
  worker (CPU time that stays while wall time grows means the cores were busy with other work);
* overhead per job = (workers x run - the jobs' own seconds, as the workers timed them) / jobs:
  the time a worker slot spends on a job outside its task (sending, scheduling, writing the
  results, idling while the driver catches up). Ray minus pool is Ray's extra cost per job.

With ``--repeat N`` each backend runs N times (a fresh folder each time) and the run with the most
jobs per minute is shown: on a shared machine the best run is the one least disturbed.

Wall time depends on what else runs on the machine (the load average is printed before and after).
"""

from __future__ import annotations

import argparse
import os
import platform
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

from controlmm.batch import BatchConfig, Job, load_jobs, run_batch  # noqa: E402
from controlmm.motion import Motion, load_motion, save_motion  # noqa: E402

SHARED = Path(os.environ.get("CONTROLMM_SHARED", Path(__file__).resolve().parents[2] / "shared"))
SAMPLE = SHARED / "data" / "humanml3d" / "new_joints" / "012314.npy"


def make_motions(folder: Path, count: int, frames: int) -> None:
    """``count`` clips of ``frames`` frames from the sample, at evenly spread offsets."""
    if not SAMPLE.is_file():
        sys.exit(f"benchmarks/batch.py: the HumanML3D sample is not at {SAMPLE} (set CONTROLMM_SHARED)")
    joints = load_motion(SAMPLE).joints
    span = len(joints) - frames
    for i in range(count):
        start = round(i * span / max(1, count - 1))
        save_motion(Motion(joints=joints[start : start + frames], fps=20), folder / f"clip{i:03d}.npz")


def measure(jobs: list[Job], out: Path, config: BatchConfig) -> dict[str, float]:
    """Start-up, run time, jobs/min and per-job overhead of one batch."""
    marks: dict[str, float] = {}

    def on_event(event: str, job: Job, info: dict) -> None:
        marks.setdefault(f"first_{event}", time.perf_counter())
        marks[f"last_{event}"] = time.perf_counter()

    start = time.perf_counter()
    result = run_batch(jobs, out, config, on_event=on_event)
    run_s = marks["last_finished"] - marks["first_started"]
    job_s = sum(float(r.get("seconds") or 0.0) for r in result.records.values())
    cpu_s = sum(float(r.get("cpu_seconds") or 0.0) for r in result.records.values())
    workers = result.workers
    return {
        "workers": workers,
        "jobs": len(jobs),
        "passed": result.counts["passed"],
        "startup_s": marks["first_started"] - start,
        "run_s": run_s,
        "jobs_per_min": len(jobs) / run_s * 60,
        "job_s": job_s / len(jobs),
        "job_cpu_s": cpu_s / len(jobs),
        "overhead_ms": (workers * run_s - job_s) / len(jobs) * 1000,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--jobs", type=int, default=96, help="retarget + validate jobs (default 96)")
    parser.add_argument("--frames", type=int, default=120, help="frames per clip at 20 fps (default 120)")
    parser.add_argument("--repeat", type=int, default=3, help="runs per backend, the best shown (default 3)")
    parser.add_argument("--no-ray", action="store_true", help="skip the Ray row")
    args = parser.parse_args()
    print(f"machine: {platform.machine()}, {os.cpu_count()} CPUs, load average {os.getloadavg()[0]:.1f}")
    rows = []
    with tempfile.TemporaryDirectory(prefix="controlmm-bench-batch-") as tmp:
        folder = Path(tmp) / "motions"
        folder.mkdir()
        make_motions(folder, args.jobs, args.frames)
        jobs = load_jobs(folder)
        runs = [
            ("local", BatchConfig(workers=1, progress=False)),
            ("local", BatchConfig(workers=2, progress=False)),
        ]
        if not args.no_ray:
            runs.append(("ray (local, 2 CPUs)", BatchConfig(workers=2, ray="auto", progress=False)))
        for i, (name, config) in enumerate(runs):
            tries = [measure(jobs, Path(tmp) / f"out{i}-{k}", config) for k in range(args.repeat)]
            rows.append((name, max(tries, key=lambda r: r["jobs_per_min"])))
    print(f"\n{args.jobs} retarget + validate jobs (G1, empty scene), {args.frames} frames at 20 fps each\n")
    head = "backend | workers | passed | start-up s | run s | jobs/min | job s | job CPU s | overhead ms/job"
    print(f"| {head} |")
    print("|---" * len(head.split("|")) + "|")
    for name, r in rows:
        cells = [
            name,
            r["workers"],
            f"{r['passed']}/{r['jobs']}",
            f"{r['startup_s']:.1f}",
            f"{r['run_s']:.1f}",
        ]
        cells += [
            f"{r['jobs_per_min']:.1f}",
            f"{r['job_s']:.2f}",
            f"{r['job_cpu_s']:.2f}",
            f"{r['overhead_ms']:.0f}",
        ]
        print("| " + " | ".join(map(str, cells)) + " |")
    one, two = rows[0][1], rows[1][1]
    print(f"\nscaling 1 -> 2 local workers: {two['jobs_per_min'] / one['jobs_per_min']:.2f}x (goal >= 1.8x)")
    if len(rows) > 2:
        ray = rows[2][1]
        extra = ray["overhead_ms"] - two["overhead_ms"]
        ratio = ray["jobs_per_min"] / two["jobs_per_min"]
        print(f"Ray vs local pool (2 workers): {ratio:.2f}x the jobs/min, {extra:+.0f} ms overhead per job")
    print(f"load average after: {os.getloadavg()[0]:.1f}")


if __name__ == "__main__":
    main()
