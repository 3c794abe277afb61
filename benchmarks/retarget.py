"""Retargeting benchmark: quality and speed, batched solver vs mink per-frame IK, on real data.

    python benchmarks/retarget.py                      # g1 + h1, real clip + synthetic variants
    python benchmarks/retarget.py --robots g1 --repeats 10 --json out/retarget_bench.json

Motions: the real HumanML3D clip 012314 (``$CONTROLMM_SHARED/data/humanml3d``, default ``../shared``
beside the repository root) and variants built from it: mirrored (left/right swapped), cropped (frames
40-120), time-reversed, 1.5x faster, 0.5x slower and with 1 cm Gaussian noise on every joint; plus the
first 20 ``*.npz``/``*.npy`` motions (sorted by path) under ``--corpus`` when given. For each motion
and robot: keypoint error after scaling (mm; mean/max per group), joint-limit violations,
floor penetration (max, mm), stance-foot sliding (mm per stance; mean/max), joint jerk RMS,
and speed in input frames per second (best of ``--repeats`` wall-clock runs of
``retarget_motion(..., metrics=False)`` and its CPU time), batched and mink side by side.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import time
from functools import partial
from pathlib import Path

import numpy as np
from data_dirs import ROOT, real_clip

sys.path.insert(0, str(ROOT))

from controlmm.motion import Motion, load_motion, resample  # noqa: E402
from controlmm.motion.skeleton import LEFT_RIGHT_MIRROR  # noqa: E402
from retarget import SolverConfig, retarget_motion  # noqa: E402


def motions(corpus: Path | None) -> dict[str, Motion]:
    real = load_motion(real_clip())
    j = real.joints
    rng = np.random.default_rng(0)
    mirrored = j[:, list(LEFT_RIGHT_MIRROR)] * np.array([-1.0, 1.0, 1.0], dtype=np.float32)
    out = {
        "real 012314": real,
        "mirrored": Motion(joints=mirrored, fps=20.0),
        "cropped 40-120": Motion(joints=j[40:120], fps=20.0),
        "reversed": Motion(joints=j[::-1].copy(), fps=20.0),
        "1.5x faster": Motion(joints=resample(j, 30.0, 20.0).astype(np.float32), fps=20.0),
        "0.5x slower": Motion(joints=resample(j, 10.0, 20.0).astype(np.float32), fps=20.0),
        "noisy 1 cm": Motion(joints=j + rng.normal(0, 0.01, j.shape).astype(np.float32), fps=20.0),
    }
    if corpus is not None:
        for path in sorted(corpus.rglob("*.np[yz]"))[:20]:
            try:
                out[f"corpus {path.stem}"] = load_motion(path)
            except Exception as exc:  # noqa: BLE001 - report and go on
                print(f"skipping {path}: {exc}", file=sys.stderr)
    return out


def timed(fn, repeats: int) -> tuple[float, float]:
    """Best wall-clock and best CPU seconds over ``repeats`` calls."""
    wall = cpu = float("inf")
    for _ in range(repeats):
        w, c = time.perf_counter(), time.process_time()
        fn()
        wall, cpu = min(wall, time.perf_counter() - w), min(cpu, time.process_time() - c)
    return wall, cpu


def row(name: str, robot: str, solver: str, n: int, wall: float, cpu: float, m: dict) -> dict:
    ke = m["keypoint_error_mm"]
    return {
        "motion": name,
        "robot": robot,
        "solver": solver,
        "frames": n,
        "fps_wall": n / wall,
        "fps_cpu": n / cpu,
        **{f"{g}_mean": ke[g]["mean"] for g in ("feet", "hands", "pelvis", "head", "all") if g in ke},
        **{f"{g}_max": ke[g]["max"] for g in ("feet", "hands", "pelvis", "head", "all") if g in ke},
        "limit_violations": m["joint_limit_violations"],
        "penetration_mm": m["floor_penetration_max_mm"],
        "slide_mean": m["foot_sliding_mm_per_stance"]["mean"],
        "slide_max": m["foot_sliding_mm_per_stance"]["max"],
        "stances": m["stances"],
        "jerk": m.get("joint_jerk_rms_rad_s3", float("nan")),
    }


def _pair(r: dict, group: str) -> str:
    """``mean/max`` of a keypoint group's error (mm) in a result row."""
    return f"{r.get(group + '_mean', float('nan')):5.0f}/{r.get(group + '_max', float('nan')):<5.0f}"


def print_table(rows: list[dict]) -> None:
    head = (
        f"{'motion':<15} {'robot':<5} {'solver':<7} {'frames':>6} {'fps wall':>9} {'fps cpu':>8} "
        f"{'feet':>11} {'hands':>11} {'pelvis':>11} {'head':>11} {'lim':>4} {'pen mm':>6} "
        f"{'slide mm':>11} {'jerk':>7}"
    )
    print(head)
    print("-" * len(head))
    for r in rows:
        pair = partial(_pair, r)
        print(
            f"{r['motion']:<15} {r['robot']:<5} {r['solver']:<7} {r['frames']:>6} {r['fps_wall']:>9.0f} "
            f"{r['fps_cpu']:>8.0f} {pair('feet'):>11} {pair('hands'):>11} {pair('pelvis'):>11} "
            f"{pair('head'):>11} {r['limit_violations']:>4} {r['penetration_mm']:>6.2f} "
            f"{r['slide_mean']:>5.1f}/{r['slide_max']:<5.1f} {r['jerk']:>7.0f}"
        )


ABLATION = {
    "default (mapping's schedule)": None,
    "levels (2,5),(1,2)": {"levels": ((2, 5), (1, 2))},
    "levels (3,5),(1,2)": {"levels": ((3, 5), (1, 2))},
    "levels (3,5),(1,4)": {"levels": ((3, 5), (1, 4))},
    "exact acceleration band": {"exact_acceleration": True},
    "one level, 25 iterations": {"levels": (), "tolerance": 1e-4},
    "converged (60 it, tol 1e-8)": {"levels": (), "max_iterations": 60, "tolerance": 1e-8},
    "no stance pinning": {"pin_iterations": 0},
}


def ablation(motion: Motion, robot: str, repeats: int) -> None:
    """Solver design choices on one motion: speed, final cost and quality."""
    print(f"\nsolver settings, {robot}, real clip ({motion.num_frames} frames):")
    print(f"{'setting':<28} {'fps cpu':>8} {'cost':>8} {'all mm':>7} {'slide mm':>11} {'jerk':>6}")
    from retarget import load_robot

    base = load_robot(robot).mapping.solver
    for name, change in ABLATION.items():
        cfg = SolverConfig(**{**base, **(change or {})})
        _, cpu = timed(partial(retarget_motion, motion, robot, config=cfg, metrics=False), repeats)
        traj = retarget_motion(motion, robot, config=cfg)
        m = traj.metrics
        print(
            f"{name:<28} {motion.num_frames / cpu:>8.0f} {traj.solver['cost']:>8.3f} "
            f"{m['keypoint_error_mm']['all']['mean']:>7.1f} {m['foot_sliding_mm_per_stance']['mean']:>5.1f}/"
            f"{m['foot_sliding_mm_per_stance']['max']:<5.1f} {m['joint_jerk_rms_rad_s3']:>6.0f}"
        )


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--robots", nargs="+", default=["g1", "h1"])
    ap.add_argument("--repeats", type=int, default=5, help="timed runs per motion (best is kept)")
    ap.add_argument("--no-mink", action="store_true", help="skip the mink per-frame IK baseline")
    ap.add_argument("--corpus", type=Path, help="folder of extra motions (.npz/.npy)")
    ap.add_argument("--json", type=Path, help="also write the rows as JSON")
    ap.add_argument("--no-ablation", action="store_true", help="skip the solver-settings table")
    args = ap.parse_args()
    try:
        import mink  # noqa: F401

        have_mink = not args.no_mink
    except ImportError:
        have_mink = False
        print("mink not installed (pip install -e '.[bench]'): baseline skipped", file=sys.stderr)
    print(
        f"machine: {platform.processor() or platform.machine()}, {os.cpu_count()} CPU cores, "
        f"python {platform.python_version()}, load average at start {os.getloadavg()[0]:.2f}"
    )
    print(
        "keypoint errors: mean/max mm against the uniformly scaled human; speed: input frames (20 fps) "
        "per second, best of the timed runs, output 50 Hz, metrics excluded\n"
    )
    rows = []
    all_motions = motions(args.corpus)
    for name, motion in all_motions.items():
        for robot in args.robots:
            retarget_motion(motion, robot, metrics=False)  # warm caches (model loading)
            wall, cpu = timed(partial(retarget_motion, motion, robot, metrics=False), args.repeats)
            m = retarget_motion(motion, robot).metrics
            rows.append(row(name, robot, "batched", motion.num_frames, wall, cpu, m))
            if have_mink:
                wall, cpu = timed(partial(retarget_motion, motion, robot, solver="mink", metrics=False), 1)
                m = retarget_motion(motion, robot, solver="mink").metrics
                rows.append(row(name, robot, "mink", motion.num_frames, wall, cpu, m))
    print_table(rows)
    print()
    for robot in args.robots:
        b = [r for r in rows if r["robot"] == robot and r["solver"] == "batched"]
        line = (
            f"{robot}: batched {np.mean([r['fps_wall'] for r in b]):.0f} frames/s wall "
            f"({np.mean([r['fps_cpu'] for r in b]):.0f} CPU) averaged over {len(b)} motions"
        )
        k = [r for r in rows if r["robot"] == robot and r["solver"] == "mink"]
        if k:
            ratio = np.mean([x["fps_wall"] / y["fps_wall"] for x, y in zip(b, k, strict=True)])
            line += (
                f"; mink {np.mean([r['fps_wall'] for r in k]):.0f} frames/s -> batched is {ratio:.1f}x faster"
            )
        print(line)
    if not args.no_ablation:
        for robot in args.robots:
            ablation(all_motions["real 012314"], robot, args.repeats)
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(rows, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
