"""Calibration of the simulation checks on clean, retargeted human motion.

    python benchmarks/sim_calibration.py                       # g1 + h1, 8 test clips per family
    python benchmarks/sim_calibration.py --robots g1 --per-family 4 --json out/calib.json

Clean motion should pass: every clip here is a real human clip (HumanML3D 012314) or a
procedural corpus clip (``controlmm/corpus``; default ``data/corpus-default``, built by
``controlmm corpus --out data/corpus-default --clips 9800 --seed 0``, docs/corpus.md), from its
``test`` split, the first ``--per-family`` clips of every family in id order. Each is
retargeted with ``retarget_motion(..., fps=50)`` and checked with ``sim.check_trajectory`` in
the ``empty`` scene with the default ``CheckConfig``. Printed:

* per family and robot: clips, pass rate, and the failing kinds (``severity == "error"``,
  what makes ``passed`` false) with their worst value; warnings are listed separately;
* per check: the distribution (median, p90, p95, p99, max over clips) of each clip's worst
  measured value, next to the threshold: the figures the defaults are calibrated from;
* the hard guarantees among passing clips (obstacle/floor penetration over 1 cm, joint-limit
  violations: must be zero) and the speeds (retarget and check frames/s, CPU time).

Clips run in ``--workers`` processes (default: the CPU count); every worker builds one
``CheckWorld`` per robot and reuses it.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import time
from collections import defaultdict
from pathlib import Path

import numpy as np
from data_dirs import DEFAULT_CORPUS, REAL_CLIP, ROOT, corpus_dir, humanml3d_dir

sys.path.insert(0, str(ROOT))

# per check: (label, unit scale for printing, unit, the clip statistic, the CheckConfig threshold name)
MEASURES = [
    ("floor penetration", 1000, "mm", "floor_penetration_m", "floor_penetration_m"),
    ("obstacle penetration", 1000, "mm", "max_penetration_m", "obstacle_penetration_m"),
    ("self-collision depth", 1000, "mm", "max_self_collision_m", "self_collision_m"),
    ("joint-limit overshoot", 1, "rad", "max_joint_limit_violation_rad", "joint_limit_tol_rad"),
    ("joint speed / limit", 1, "", "max_joint_velocity_ratio", None),
    ("stance slide speed", 1, "m/s", "max_foot_slide_speed_mps", "max_foot_slide_speed"),
    ("stance slide total", 1000, "mm", "foot_sliding_m", None),
    ("floating frames", 1, "", "floating_frames", None),
    ("flight frames", 1, "", "flight_frames", None),
    ("residual force p95", 100, "% mg", "residual_force_p95", None),
    ("residual force max", 100, "% mg", "residual_force_max", "max_residual_force_ratio"),
    (
        "residual force sustained",
        100,
        "% mg",
        "residual_force_sustained",
        "max_sustained_residual_force_ratio",
    ),
    ("residual moment max", 1000, "mm", "residual_moment_max", "max_residual_moment_m"),
    ("residual moment sustained", 1000, "mm", "residual_moment_sustained", "max_sustained_residual_moment_m"),
    ("torque / limit max", 1, "", "max_torque_ratio", "max_torque_ratio"),
    ("torque / limit sustained", 1, "", "max_sustained_torque_ratio", "max_sustained_torque_ratio"),
]


def _clip_list(
    corpus: Path, split: str, per_family: int, families: list[str] | None
) -> list[tuple[str, str, Path]]:
    """(family, id, joints path) of the first ``per_family`` clips of each family in ``split``."""
    ids = (corpus / f"{split}.txt").read_text().split()
    chosen: dict[str, list[str]] = defaultdict(list)
    for cid in sorted(ids):
        meta = json.loads((corpus / "meta" / f"{cid}.json").read_text())
        fam = meta["family"]
        if families and fam not in families:
            continue
        if len(chosen[fam]) < per_family:
            chosen[fam].append(cid)
    return [(fam, cid, corpus / "new_joints" / f"{cid}.npy") for fam in sorted(chosen) for cid in chosen[fam]]


_WORLDS: dict = {}


def _world(robot: str):
    from scenes import load_scene
    from sim import make_world

    if robot not in _WORLDS:
        _WORLDS[robot] = make_world(load_scene("empty", robot=robot))
    return _WORLDS[robot]


def _run(job: tuple[str, str, str, str]) -> dict:
    """Retarget one clip to one robot, check it, and keep the figures."""
    from controlmm.motion import Motion, load_motion
    from retarget import retarget_motion
    from sim import check_trajectory

    family, cid, path, robot = job
    world = _world(robot)
    motion = (
        load_motion(path)
        if path.endswith("new_joint_vecs/" + Path(path).name)
        else Motion(joints=np.load(path).astype(np.float32), fps=20.0)
    )
    cpu0 = time.process_time()
    traj = retarget_motion(motion, robot, fps=50.0, metrics=False)
    cpu1 = time.process_time()
    report = check_trajectory(world, traj)
    cpu2 = time.process_time()
    s = report.stats
    rf, rm = s["residual_force"] or {}, s["residual_moment"] or {}
    worst: dict[str, dict] = {}
    for f in report.failures:
        sev = getattr(f, "severity", "error")
        key = f"{f.kind}|{sev}"
        if key not in worst or f.depth > worst[key]["depth"]:
            worst[key] = {
                "depth": f.depth,
                "where": f.joint or f.robot_body or "robot",
                "other": f.obstacle_geom,
                "frames": [f.frame_start, f.frame_end],
            }
    return {
        "family": family,
        "id": cid,
        "robot": robot,
        "passed": bool(report.passed),
        "input_frames": int(len(motion.joints)),
        "frames": int(report.num_frames),
        "retarget_cpu_s": cpu1 - cpu0,
        "check_cpu_s": cpu2 - cpu1,
        "failures": worst,
        "stats": {
            "floor_penetration_m": s["floor_penetration_m"],
            "max_penetration_m": s["max_penetration_m"],
            "max_self_collision_m": s["max_self_collision_m"],
            "max_joint_limit_violation_rad": s["max_joint_limit_violation_rad"],
            "joint_limit_violations": s["joint_limit_violations"],
            "max_joint_velocity_ratio": s["max_joint_velocity_ratio"],
            "max_foot_slide_speed_mps": s["max_foot_slide_speed_mps"],
            "foot_sliding_m": s["foot_sliding_m"],
            "floating_frames": s["floating_frames"],
            "flight_frames": s["flight_frames"],
            "residual_force_p95": rf.get("p95_ratio", 0.0),
            "residual_force_max": rf.get("max_ratio", 0.0),
            "residual_moment_max": rm.get("max_m", 0.0),
            "max_torque_ratio": s["max_torque_ratio"] or 0.0,
            "residual_force_sustained": rf.get("sustained_max_ratio", 0.0),
            "residual_moment_sustained": rm.get("sustained_max_m", 0.0),
            "max_sustained_torque_ratio": s.get("max_sustained_torque_ratio") or 0.0,
        },
    }


def _pct(v: np.ndarray, q: float) -> float:
    return float(np.percentile(v, q)) if v.size else float("nan")


def _fmt(x: float, scale: float) -> str:
    x = x * scale
    return f"{x:.3g}" if abs(x) < 1000 else f"{x:.0f}"


def print_tables(rows: list[dict], robots: list[str]) -> None:
    from sim import CheckConfig

    cfg = CheckConfig()
    fams = sorted({r["family"] for r in rows}, key=lambda f: (f != "real", f))
    print("\n## Pass rate per family (empty scene, default CheckConfig)\n")
    head = (
        "| family | clips | "
        + " | ".join(f"{r} pass" for r in robots)
        + " | failing kinds (worst value) | warnings (worst) |"
    )
    print(head)
    print("|" + "---|" * (head.count("|") - 1))
    for fam in fams + ["ALL"]:
        sel = [r for r in rows if fam == "ALL" or r["family"] == fam]
        n = len({r["id"] for r in sel})
        rates = []
        for rb in robots:
            rs = [r for r in sel if r["robot"] == rb]
            rates.append(
                f"{100 * np.mean([r['passed'] for r in rs]):.0f}% ({sum(r['passed'] for r in rs)}/{len(rs)})"
                if rs
                else "-"
            )
        errs: dict[str, tuple[float, str]] = {}
        warns: dict[str, tuple[float, str]] = {}
        for r in sel:
            for key, f in r["failures"].items():
                kind, sev = key.split("|")
                bucket = errs if sev == "error" else warns
                label = f"{kind}"
                if label not in bucket or f["depth"] > bucket[label][0]:
                    bucket[label] = (f["depth"], f"{r['robot']}")
        fmt = lambda b: ", ".join(f"{k} {v[0]:.3g} ({v[1]})" for k, v in sorted(b.items())) or "-"  # noqa: E731
        print(f"| {fam} | {n} | " + " | ".join(rates) + f" | {fmt(errs)} | {fmt(warns)} |")

    for rb in robots:
        rs = [r for r in rows if r["robot"] == rb]
        if not rs:
            continue
        print(f"\n## Measured values on clean motion ({rb}, {len(rs)} clips; per clip its worst frame)\n")
        print("| check | unit | median | p90 | p95 | p99 | max | threshold |")
        print("|---|---|---|---|---|---|---|---|")
        for label, scale, unit, key, thr in MEASURES:
            v = np.array([r["stats"][key] for r in rs], dtype=float)
            t = getattr(cfg, thr) if thr else None
            t_txt = _fmt(t, scale) if t is not None else "-"
            print(
                f"| {label} | {unit} | "
                + " | ".join(_fmt(_pct(v, q), scale) for q in (50, 90, 95, 99, 100))
                + f" | {t_txt} |"
            )
        passing = [r for r in rs if r["passed"]]
        bad_pen = sum(
            r["stats"]["floor_penetration_m"] > 0.01 or r["stats"]["max_penetration_m"] > 0.01
            for r in passing
        )
        bad_lim = sum(r["stats"]["joint_limit_violations"] > 0 for r in passing)
        frames_in = sum(r["input_frames"] for r in rs)
        frames_out = sum(r["frames"] for r in rs)
        rt = sum(r["retarget_cpu_s"] for r in rs)
        ck = sum(r["check_cpu_s"] for r in rs)
        print(
            f"\n{rb}: passing clips with penetration > 1 cm: {bad_pen}; "
            f"with joint-limit violations: {bad_lim}. "
            f"Retarget {frames_in / rt:,.0f} input frames/s CPU (metrics off); check {frames_out / ck:,.0f} "
            f"frames/s CPU (all checks, 50 fps)."
        )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument(
        "--corpus",
        type=Path,
        default=DEFAULT_CORPUS,
        help="HumanML3D-format corpus directory (default: data/corpus-default)",
    )
    ap.add_argument("--split", default="test")
    ap.add_argument("--per-family", type=int, default=8)
    ap.add_argument("--families", default="", help="comma-separated family names (default: all)")
    ap.add_argument("--robots", default="g1,h1")
    ap.add_argument("--workers", type=int, default=os.cpu_count() or 1)
    ap.add_argument("--json", type=Path, default=None, help="write every clip's figures here")
    args = ap.parse_args()
    robots = [r for r in args.robots.split(",") if r]
    families = [f for f in args.families.split(",") if f] or None
    clips: list[tuple[str, str, Path]] = []
    real = humanml3d_dir() / "new_joint_vecs" / f"{REAL_CLIP}.npy"
    if real.is_file() and (families is None or "real" in families):
        clips.append(("real", REAL_CLIP, real))
    if families != ["real"]:  # --families real runs the real clip alone, without the corpus
        clips += _clip_list(corpus_dir(args.corpus, "--corpus"), args.split, args.per_family, families)
    jobs = [(fam, cid, str(p), rb) for rb in robots for fam, cid, p in clips]
    print(
        f"# sim calibration: {len(clips)} clips x {len(robots)} robots, {platform.machine()}, "
        f"{os.cpu_count()} CPUs, {args.workers} workers"
    )
    start = time.perf_counter()
    if args.workers > 1:
        import multiprocessing as mp

        with mp.get_context("fork").Pool(args.workers) as pool:
            rows = pool.map(_run, jobs, chunksize=4)
    else:
        rows = [_run(j) for j in jobs]
    print(f"done in {time.perf_counter() - start:.1f} s")
    print_tables(rows, robots)
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(rows, indent=1))


if __name__ == "__main__":
    main()
