"""``controlmm batch JOBS --out DIR``: many plan / retarget / validate jobs, resumable, local or on Ray."""

from __future__ import annotations

import argparse
import signal
import sys
from types import FrameType

from controlmm.atomic import check_output_dir
from controlmm.cli.args import add_force, integer, positive, threads

HELP = """Run many jobs: plans, retargets and validations, on a local process pool or on Ray.

JOBS is a JSONL file, one job per line, with the arguments of the command of that name:

  {"kind": "plan", "scene": "pillars", "seed": 3, "rounds": 1}
  {"kind": "retarget", "motion": "walk.npz", "robot": "h1", "scene": "table"}
  {"kind": "validate", "trajectory": "robot.csv", "fps": 30, "scene": "empty"}
  {"kind": "variations", "scene": "table", "count": 20, "jitter_m": 0.1, "variation_seed": 0}

('variations' stands for COUNT plan jobs in copies of the scene whose obstacles are moved up to
jitter_m in x and y; any line may give an "id" and a "family"; relative paths are relative to
the JSONL file), or a folder of motions (.npz, .npy, .bvh, .csv; a HumanML3D folder's
new_joint_vecs) retargeted to every --robot and validated in --scene.

Every job is written to DIR/jobs/<id>/ in one piece (result.json with the verdict and figures,
robot.csv/.npz/.json, report.json; plans: motion.npz and plan.json too) and the batch goes on
when a job fails its checks, raises, crashes its worker or runs past --timeout: each is recorded
with its error. Run the same command again to resume a stopped (Ctrl-C) or killed batch: finished
jobs are skipped. DIR/summary.csv and summary.json list every job (id, input, robot, scene, family,
status, failure kinds, penetration, sliding, constraint errors, seconds); summary.md gives the
pass rates per scene, robot and family. DIR may be new, empty or a previous batch; anything else
needs --force (which also starts a previous batch over).

Workers load the models once and keep them warm. The local pool is the default (--workers N
processes, one per CPU core by default); --ray auto starts a local Ray, --ray HOST:PORT or
ray://HOST:PORT uses a running cluster (pip install -e ".[ray]"; input motions travel with the
jobs, results come back to this machine). The results are the same on either backend.

Exit status: 0 every job passed (or ran without checks), 1 some job failed, errored, crashed
or timed out, 2 bad input (nothing run), 130 stopped by Ctrl-C (rerun to resume)."""

EPILOG = """examples:
  controlmm batch motions/ --robot g1 --robot h1 --out out/library --workers 2
  controlmm batch plans.jsonl --out out/plans --timeout 600
  controlmm batch plans.jsonl --out out/plans --ray auto
  controlmm batch plans.jsonl --out out/plans --ray ray://head-node:10001 --workers 64"""


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "batch",
        help="run many plan/retarget/validate jobs (JSONL or a folder of motions), resumable, local or Ray",
        description=HELP,
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("jobs", metavar="JOBS", help="a JSONL file of jobs, or a folder of motions")
    p.add_argument("--out", required=True, help="batch folder: new, empty or a previous batch (resumed)")
    p.add_argument(
        "--robot",
        action="append",
        default=None,
        help="a folder's motions go to this robot (g1, h1 or a mapping .json); repeat for several "
        "(default: g1)",
    )
    p.add_argument(
        "--scene", default=None, help="a folder's motions are validated in this scene (default: empty)"
    )
    p.add_argument(
        "--fps", type=positive, default=None, help="a folder's robot trajectory rate in Hz (default 50)"
    )
    p.add_argument(
        "--csv-fps",
        type=positive,
        default=30.0,
        help="frame rate of a folder's .csv motions (66 joint columns or a robot trajectory; default 30)",
    )
    p.add_argument(
        "--workers",
        type=integer(1),
        default=None,
        help="worker processes (local) or actors (Ray) (default: one per CPU core, or per cluster CPU)",
    )
    p.add_argument(
        "--ray",
        metavar="auto|ADDRESS",
        default=None,
        help="run on Ray: 'auto' starts a local Ray, HOST:PORT or ray://HOST:PORT joins a cluster "
        "(default: the local process pool)",
    )
    p.add_argument(
        "--timeout",
        type=positive,
        default=None,
        help="stop a job after this many seconds (default: no limit)",
    )
    p.add_argument("--threads", type=threads, default=1, help="torch CPU threads per worker (default 1)")
    p.add_argument(
        "--retry-errors", action="store_true", help="run again the jobs recorded as error, crashed or timeout"
    )
    p.add_argument(
        "--strict",
        action="store_true",
        help="a malformed JSONL line stops the batch before any work (exit 2)",
    )
    add_force(p, "DIR whatever it holds, a previous batch too (start over)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.set_defaults(func=run)


def _stop(signum: int, frame: FrameType | None) -> None:
    raise KeyboardInterrupt  # `kill PID` stops the batch as Ctrl-C does: cleanly, resumable


def run(args: argparse.Namespace) -> int:
    check_output_dir(args.out, kind="batch", force=args.force, make_parents=True)  # before any work
    # heavy (the runner and tqdm; workers import torch and MuJoCo): imported when the command runs, so
    # that --help stays fast
    from controlmm.batch import BatchConfig, load_jobs, run_batch

    jobs = load_jobs(
        args.jobs, args.robot, scene=args.scene, fps=args.fps, csv_fps=args.csv_fps, strict=args.strict
    )
    config = BatchConfig(
        workers=args.workers,
        ray=args.ray,
        timeout_s=args.timeout,
        threads=args.threads,
        retry_errors=args.retry_errors,
        force=args.force,
        progress=not args.no_progress,
    )
    previous = signal.signal(signal.SIGTERM, _stop)
    try:
        result = run_batch(jobs, args.out, config)
    except KeyboardInterrupt:
        print(
            f"batch: stopped; finished jobs are kept in {args.out}/ (summary.md): run the same command again "
            "to resume",
            file=sys.stderr,
        )
        return 130
    finally:
        signal.signal(signal.SIGTERM, previous)
    c = result.counts
    print(
        f"batch: {c['jobs']} jobs: {c['passed']} passed, {c['failed']} failed their checks, {c['done']} done "
        f"without checks, {c['error']} errors, {c['crashed']} crashed, {c['timeout']} timed out "
        f"({result.ran} run, {result.skipped} already finished) in {result.seconds:.1f} s"
        f"{' on ' + result.backend + f' with {result.workers} workers' if result.backend else ''}"
    )
    print(f"wrote {args.out}/summary.md, summary.csv, summary.json and jobs/<id>/")
    return 0 if result.all_passed else 1
