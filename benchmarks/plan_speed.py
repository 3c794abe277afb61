"""Plan speed: where a plan's wall time goes, stage by stage, for every bundled scene.

    python benchmarks/plan_speed.py                          # every bundled scene, seed 0, model loaded once
    python benchmarks/plan_speed.py --scenes table --repeats 3 --json speed.json

The model is loaded once and one warm-up plan (the README example: ``PlanConfig()``, the ``table``
scene) runs first; every scene is then planned in this process (the warm case of a studio or a batch
worker: imports done, model loaded, caches filled) with ``render=False`` and no files written.
Prints one row per scene: the wall seconds of each stage of ``result.timing``
(:mod:`controlmm.pipeline.timing`: start-up here is the plan's own set-up, inputs, scene SDF and
robot world), the total, the CPU seconds, the verdict, the rounds used and the worst constraint
error. With ``--repeats N`` each scene is planned N times and the row is the run with the median
total. The machine's load average is printed: the wall time grows with it, the CPU time much less.

Side by side with another checkout (an older release): ``PYTHONPATH=OTHER_CHECKOUT python
benchmarks/plan_speed.py ...`` plans with that checkout's code (the packages on ``PYTHONPATH`` come
before this checkout's); code without stage timing shows the total only.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
# This folder holds benchmarks/retarget.py, which would shadow the retarget package; this checkout
# comes after PYTHONPATH (see the module docstring).
sys.path[:] = [p for p in sys.path if Path(p or ".").resolve() != ROOT / "benchmarks"] + [str(ROOT)]

import torch  # noqa: E402 - after the path fix above

from controlmm.generate import MotionModel, load_model  # noqa: E402
from controlmm.pipeline import PlanConfig, plan  # noqa: E402
from scenes import list_scenes  # noqa: E402

try:
    from controlmm.pipeline.timing import LABELS, STAGES
except ImportError:  # an older checkout on PYTHONPATH: no stage timing, totals only
    LABELS, STAGES = {}, ()


def _one(scene: str, seed: int, preset: str, model_dir: str | None, model: MotionModel) -> dict:
    """Plan ``scene`` once in this process; its stage seconds, total, CPU seconds and verdict."""
    c0, t0 = time.process_time(), time.perf_counter()
    result = plan(
        PlanConfig(scene=scene, seed=seed, preset=preset, model=model_dir, render=False, plots=False),
        model=model,
        progress=False,
    )
    cpu, wall = time.process_time() - c0, time.perf_counter() - t0
    timing = getattr(result, "timing", None)
    return {
        "scene": scene,
        "stages_s": timing.ordered() if timing is not None else {},
        "total_s": wall,
        "cpu_s": cpu,
        "passed": result.passed,
        "passed_round0": result.rounds[0].passed,
        "rounds": len(result.rounds) - 1,
        "constraint_cm": 100 * max(result.final.constraint_errors_m, default=0.0),
    }


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument(
        "--scenes", nargs="*", default=None, help="scene names (default: every bundled scene)"
    )
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--preset", default="accurate")
    parser.add_argument("--model", default=None, help="model directory (default: the embedded default)")
    parser.add_argument("--threads", type=int, default=1, help="torch threads (default 1, as controlmm plan)")
    parser.add_argument("--repeats", type=int, default=1, help="plans per scene; the median row is shown")
    parser.add_argument("--json", default=None, help="also write every run's figures to this JSON file")
    args = parser.parse_args()
    os.environ.setdefault("HF_HUB_OFFLINE", "1")
    torch.set_num_threads(args.threads)
    scenes = args.scenes or [s if isinstance(s, str) else s.name for s in list_scenes()]

    t0 = time.perf_counter()
    model = load_model(args.model)
    load_s = time.perf_counter() - t0
    t0 = time.perf_counter()
    plan(PlanConfig(render=False, plots=False, model=args.model), model=model, progress=False)  # warm-up
    warm_s = time.perf_counter() - t0

    runs: list[dict] = []
    rows: list[dict] = []
    for scene in scenes:
        tries = [_one(scene, args.seed, args.preset, args.model, model) for _ in range(max(1, args.repeats))]
        runs.extend(tries)
        median = statistics.median_low([r["total_s"] for r in tries])
        rows.append(next(r for r in tries if r["total_s"] == median))

    used = [s for s in (*STAGES, "other") if any(r["stages_s"].get(s, 0.0) > 0 for r in rows)]
    load = ", ".join(f"{x:.2f}" for x in os.getloadavg())
    code = Path(sys.modules["controlmm"].__file__ or "").resolve().parents[1]
    print(
        f"plan speed ({code}): {len(scenes)} scenes, seed {args.seed}, preset {args.preset}, "
        f"{args.threads} torch thread(s), {args.repeats} plan(s) per scene (median shown); "
        f"model load {load_s:.1f} s, warm-up plan {warm_s:.1f} s; load average {load}\n"
    )
    head = [
        "scene",
        *(LABELS.get(s, s) for s in used),
        "plan s",
        "CPU s",
        "passed",
        "rounds",
        "constraint cm",
    ]
    print("| " + " | ".join(head) + " |")
    print("|" + "---|" * len(head))
    for r in rows:
        cells = [r["scene"], *(f"{r['stages_s'].get(s, 0.0):.2f}" for s in used)]
        verdict = ("yes" if r["passed"] else "no") + ("" if r["passed_round0"] else " (after feedback)")
        cells += [
            f"{r['total_s']:.2f}",
            f"{r['cpu_s']:.2f}",
            verdict,
            str(r["rounds"]),
            f"{r['constraint_cm']:.2f}",
        ]
        print("| " + " | ".join(cells) + " |")
    totals = [r["total_s"] for r in rows]
    print(f"\nmean {statistics.mean(totals):.2f} s, max {max(totals):.2f} s per plan")
    if args.json:
        Path(args.json).write_text(json.dumps({"runs": runs, "load_s": load_s, "warmup_s": warm_s}, indent=1))


if __name__ == "__main__":
    main()
