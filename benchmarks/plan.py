"""Plan benchmark: every bundled scene with its suggested prompt and constraints, several seeds.

    python benchmarks/plan.py                      # 9 scenes x 5 seeds, the embedded default model
    python benchmarks/plan.py --scenes table pillars --seeds 2 --model DIR --workers 2

Prints, per scene and overall: pass rate before feedback (round 0) and after at most --rounds
feedback rounds, rounds used, the worst obstacle and floor penetration of the chosen rounds, the
worst constraint error, the wall time of a plan (generate + retarget + check per round, no
files or video) and how many rounds kept a retargeting fallback (the retargeter's fallback
settings, tried where a round fails on torque or a slide alone). Each run is also verified
independently: the exported qpos is replayed with a fresh MuJoCo model of the scene, and every
reported pass must have obstacle and floor penetration <= 1 cm and no joint outside its range
(column ``verified``).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
# This folder holds benchmarks/retarget.py, which would shadow the retarget package.
sys.path[:] = [str(ROOT)] + [p for p in sys.path if Path(p or ".").resolve() != ROOT / "benchmarks"]


def _independent_check(scene_name: str, robot: str, qpos: np.ndarray, fps: float) -> tuple[float, float, int]:
    """Worst obstacle / floor penetration (m) and joint-limit violations of qpos, with MuJoCo alone.

    A fresh scene model; ``mj_geomDistance`` between every robot collision geom and every obstacle
    or floor geom at every frame (independent of the checker's own contact filtering).
    """
    import mujoco

    from scenes import load_scene

    scene = load_scene(scene_name, robot=robot)
    m = scene.model
    d = mujoco.MjData(m)
    robot_geoms = [g for g in scene.robot_geom_ids if m.geom_contype[g] or m.geom_conaffinity[g]]
    fromto = np.zeros(6)
    worst = {"obstacle": 0.0, "floor": 0.0}
    limits = 0
    hinge = [j for j in range(m.njnt) if m.jnt_type[j] == mujoco.mjtJoint.mjJNT_HINGE and m.jnt_limited[j]]
    for t, q in enumerate(qpos):
        d.qpos[:] = q
        scene.set_time(d, t / fps)
        mujoco.mj_kinematics(m, d)
        for kind, geoms in (("obstacle", scene.obstacle_geom_ids), ("floor", scene.floor_geom_ids)):
            for g in geoms:
                for r in robot_geoms:
                    dist = mujoco.mj_geomDistance(m, d, r, g, 0.05, fromto)
                    worst[kind] = max(worst[kind], -dist)
        for j in hinge:
            lo, hi = m.jnt_range[j]
            v = q[m.jnt_qposadr[j]]
            limits += int(v < lo - 1e-6 or v > hi + 1e-6)
    return worst["obstacle"], worst["floor"], limits


def _run(args: tuple[str, int, int, str | None, str, str]) -> dict:
    scene, seed, rounds, model_dir, preset, robot = args
    import torch

    torch.set_num_threads(1)
    from controlmm.generate import load_model
    from controlmm.pipeline import PlanConfig, plan

    model = _MODELS.get(model_dir)
    if model is None:
        model = _MODELS[model_dir] = load_model(model_dir)
    t0, c0 = time.perf_counter(), time.process_time()
    result = plan(
        PlanConfig(
            scene=scene, seed=seed, rounds=rounds, preset=preset, model=model_dir, robot=robot, render=False
        ),
        model=model,
        progress=False,
    )
    seconds, cpu = time.perf_counter() - t0, time.process_time() - c0
    report = result.report
    obstacle, floor, limits = _independent_check(scene, robot, result.trajectory.qpos, result.trajectory.fps)
    return {
        "scene": scene,
        "seed": seed,
        "before": result.rounds[0].passed,
        "after": result.passed,
        "rounds": len(result.rounds) - 1,
        "penetration": report.max_penetration_m,
        "floor": report.floor_penetration_m,
        "constraint": max(result.final.constraint_errors_m, default=0.0),
        "seconds": seconds,
        "cpu_s": cpu,
        "gen_s": [r.seconds["generate"] for r in result.rounds],
        "fallbacks": [r.fallback for r in result.rounds],
        "constraints": list(result.final.constraint_errors_m),
        "verified": (not result.passed) or (obstacle <= 0.01 and floor <= 0.01 and limits == 0),
        "indep_obstacle": obstacle,
        "indep_floor": floor,
    }


_MODELS: dict = {}


def main() -> None:
    from scenes import list_scenes

    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument(
        "--scenes", nargs="*", default=None, help="scene names (default: every bundled scene)"
    )
    parser.add_argument("--seeds", type=int, default=5, help="seeds 0..N-1 per scene (default 5)")
    parser.add_argument("--rounds", type=int, default=3, help="feedback rounds allowed (default 3)")
    parser.add_argument("--model", default=None, help="model directory (default: the embedded default)")
    parser.add_argument("--preset", default="accurate")
    parser.add_argument("--robot", default="g1")
    parser.add_argument("--workers", type=int, default=2, help="processes (default 2, one torch thread each)")
    parser.add_argument("--json", default=None, help="also write every run's figures to this JSON file")
    args = parser.parse_args()
    os.environ.setdefault("HF_HUB_OFFLINE", "1")
    scenes = args.scenes or [s if isinstance(s, str) else s.name for s in list_scenes()]
    jobs = [
        (s, seed, args.rounds, args.model, args.preset, args.robot)
        for s in scenes
        for seed in range(args.seeds)
    ]
    t0 = time.perf_counter()
    rows = []
    with ProcessPoolExecutor(max_workers=args.workers) as pool:
        for row in pool.map(_run, jobs):
            rows.append(row)
            print(
                f"  {row['scene']:16s} seed {row['seed']}: {'pass' if row['after'] else 'FAIL'} "
                f"(round 0 {'pass' if row['before'] else 'fail'}, {row['rounds']} feedback rounds) "
                f"{row['seconds']:.1f} s",
                file=sys.stderr,
                flush=True,
            )
    wall = time.perf_counter() - t0
    print(
        f"\nplan benchmark: {len(rows)} runs, {args.rounds} feedback rounds allowed, preset {args.preset}, "
        f"robot {args.robot}, {args.workers} workers, {wall:.0f} s wall\n"
    )
    header = (
        "| scene | runs | pass before feedback | pass after | mean feedback rounds | max penetration (mm) | "
        "max floor pen. (mm) | worst constraint (cm) | plan s (mean / max) | verified |"
    )
    print(header)
    print("|---" * (header.count("|") - 1) + "|")
    groups = {s: [r for r in rows if r["scene"] == s] for s in scenes}
    groups["all"] = rows
    for name, rs in groups.items():
        if not rs:
            continue
        n = len(rs)
        print(
            f"| {name} | {n} | {sum(r['before'] for r in rs) / n:.0%} | "
            f"{sum(r['after'] for r in rs) / n:.0%} | "
            f"{np.mean([r['rounds'] for r in rs]):.1f} | {max(r['penetration'] for r in rs) * 1000:.1f} | "
            f"{max(r['floor'] for r in rs) * 1000:.1f} | {max(r['constraint'] for r in rs) * 100:.1f} | "
            f"{np.mean([r['seconds'] for r in rs]):.1f} / {max(r['seconds'] for r in rs):.1f} | "
            f"{sum(r['verified'] for r in rs)}/{n} |"
        )
    one = [r for r in rows if r["rounds"] == 1]
    if one:
        print(
            f"\nruns with exactly one feedback round: {len(one)}, "
            f"plan time mean {np.mean([r['seconds'] for r in one]):.1f} s, "
            f"max {max(r['seconds'] for r in one):.1f} s"
        )
    kept = [f for r in rows for f in r["fallbacks"] if f]
    print(
        f"rounds that kept a retargeting fallback (controlmm.pipeline.retarget_checked): {len(kept)} "
        f"in {sum(any(r['fallbacks']) for r in rows)} runs"
    )
    gen0 = [r["gen_s"][0] for r in rows]
    fb = [g for r in rows for g in r["gen_s"][1:]]
    print(
        f"generation: round 0 mean {np.mean(gen0):.1f} s; feedback rounds (codebook editing) "
        f"mean {np.mean(fb) if fb else float('nan'):.1f} s over {len(fb)}"
    )
    print(
        f"CPU s per plan: mean {np.mean([r['cpu_s'] for r in rows]):.1f} "
        f"(load average {os.getloadavg()[0]:.1f})"
    )
    if args.json:
        Path(args.json).write_text(json.dumps(rows, indent=1, default=float) + "\n")


if __name__ == "__main__":
    main()
