"""Spatial-control benchmark: the paper's Table 3 (ablation) and Table 5 (speed vs precision) on CPU.

    python benchmarks/control.py                               # both tables, embedded default model
    python benchmarks/control.py --table ablation --samples 15  # 8 rows: logits x codebook x control model
    python benchmarks/control.py --table speed --samples 10     # fast / medium / accurate, 196 frames
    python benchmarks/control.py --model MODEL_DIR --data DATA_DIR --threads 2 --json out.json

Protocol (``controlmm.eval.control``, OmniControl's): targets from held-out clips of the test
split, pelvis control, the five densities (1, 2, 5 frames, 25 %, 100 % of the frames) in turn, one
motion per case, batch 1, after one warm-up generation. The ablation generates each clip at its own
length; the speed table generates every motion with 196 frames (the clip's targets in its first
frames), the unit of the paper's Table 5. Both tables also report the foot-skating ratio of the same
prompts and lengths generated without control, and the project's control targets (accurate: Avg. err
<= 1 cm, Traj. = Loc. = 0, <= 10 s per motion; editing cuts Avg. err >= 10x; skating <= uncontrolled
+ 0.01; docs/BENCHMARKS.md, "Control").

Times: wall seconds per motion and CPU seconds per motion (this process, all threads); on a shared
machine the wall time grows with the load (printed), the CPU time much less.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import time
from dataclasses import replace

import numpy as np
import torch
from data_dirs import model_data

ROWS = [  # (logits editing, codebook editing, motion control model): the paper's Table 3 order
    (False, False, False),
    (True, False, False),
    (False, True, False),
    (True, True, False),
    (False, False, True),
    (True, False, True),
    (False, True, True),
    (True, True, True),
]


def load_avg() -> str:
    try:
        return ", ".join(f"{x:.1f}" for x in os.getloadavg())
    except OSError:
        return "n/a"


def uncontrolled_skate(model, cases, frames: list[int], seed: int) -> float:
    """Mean foot-skating ratio of the same prompts generated without control by the generator the
    controlled rows extend: the sentence-vector transformer (``token_view=False``; the text-view
    ensemble is a different generator, which ``generate_controlled`` does not use)."""
    from controlmm.generate import generate
    from controlmm.motion.geometry import foot_skating_ratio

    values = []
    for i, (case, f) in enumerate(zip(cases, frames, strict=True)):
        motion = generate(model, case.text, frames=f, seed=seed + i, token_view=False).motion
        values.append(foot_skating_ratio(motion.joints))
    return float(np.mean(values))


def run_rows(model, cases, configs: list[tuple[str, object]], seed: int) -> list[dict]:
    from controlmm.eval.control import evaluate_control

    out = []
    for label, config in configs:
        started = time.perf_counter()
        result = evaluate_control(model, cases, preset=config, seed=seed, batch_size=1, progress=False)
        s = result.by_density()["all"]
        s["wall_s"] = time.perf_counter() - started
        s["label"] = label
        s["seconds_max"] = float(max(r["seconds"] for r in result.rows))
        s["cpu_seconds"] = float(np.mean([r["cpu_seconds"] for r in result.rows]))
        s["within_1cm"] = float(np.mean([r["max"] <= 0.01 + 1e-6 for r in result.rows]))
        s["within_2cm"] = float(np.mean([r["max"] <= 0.02 for r in result.rows]))
        s["load"] = load_avg()
        out.append(s)
        print(
            f"  {label}: Traj {s['traj']:.4f} Loc {s['loc']:.4f} Avg {100 * s['avg']:.3f} cm, "
            f"max {100 * s['max']:.2f} cm, skate {s['skate']:.4f}, {s['seconds']:.2f} s/motion wall, "
            f"{s['cpu_seconds']:.2f} s CPU (load {s['load']})",
            flush=True,
        )
    return out


def print_table(title: str, rows: list[dict], skate_base: float, columns: list[str]) -> None:
    print(f"\n{title}")
    print(
        "| "
        + " | ".join(columns)
        + " | Traj. err | Loc. err | Avg. err (cm) | max err (cm) | all within 1 cm "
        "| all within 2 cm | foot skating | steps | s / motion wall (mean, max) | CPU s / motion |"
    )
    print("|" + "---|" * (len(columns) + 10))
    for r in rows:
        print(
            "| "
            + " | ".join(r["label"].split("|"))
            + f" | {r['traj']:.4f} | {r['loc']:.4f} | {100 * r['avg']:.3f} "
            f"| {100 * r['max']:.2f} | {100 * r['within_1cm']:.0f} % | {100 * r['within_2cm']:.0f} % "
            f"| {r['skate']:.4f} | {r['steps']:.0f} | {r['seconds']:.2f}, {r['seconds_max']:.2f} "
            f"| {r['cpu_seconds']:.2f} |"
        )
    print(
        f"uncontrolled generation of the same prompts and lengths (sentence-vector transformer): "
        f"foot skating {skate_base:.4f}"
    )


def check_targets(accurate: dict, unedited: list[tuple[str, dict]], skate_base: float) -> None:
    """Print the control targets (module docstring) against the measured figures."""
    print("\ntargets (issue 5):")
    ok = accurate["avg"] <= 0.01 and accurate["traj"] == 0 and accurate["loc"] == 0
    print(
        f"  accurate Avg. err {100 * accurate['avg']:.3f} cm <= 1.0, Traj. {accurate['traj']:.4f} = 0, "
        f"Loc. {accurate['loc']:.4f} = 0: {'met' if ok else 'MISSED'}"
    )
    fast = accurate["seconds"] <= 10.0
    print(
        f"  accurate {accurate['seconds']:.2f} s per motion wall ({accurate['cpu_seconds']:.2f} s CPU) "
        "<= 10 s: "
        f"{'met' if fast else 'MISSED'} (load {accurate['load']})"
    )
    for label, row in unedited:
        ratio = row["avg"] / max(accurate["avg"], 1e-9)
        print(
            f"  editing cuts Avg. err {100 * row['avg']:.2f} cm ({label}) -> {100 * accurate['avg']:.3f} cm: "
            f"{ratio:.0f}x >= 10x: {'met' if ratio >= 10 else 'MISSED'}"
        )
    skate = accurate["skate"] <= skate_base + 0.01
    print(
        f"  foot skating {accurate['skate']:.4f} <= uncontrolled {skate_base:.4f} + 0.01: "
        f"{'met' if skate else 'MISSED'}"
    )


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--table", default="both", choices=("ablation", "speed", "both"))
    parser.add_argument("--model", default=None, help="model directory (default: the embedded default)")
    parser.add_argument(
        "--data",
        default=None,
        help="HumanML3D-format directory (default: the model's recorded training data when it is on this "
        "machine, else data/corpus-default)",
    )
    parser.add_argument("--samples", type=int, default=15, help="cases per row (default 15: 3 per density)")
    parser.add_argument(
        "--speed-samples", type=int, default=None, help="cases of the speed table (default --samples)"
    )
    parser.add_argument("--joints", default="pelvis")
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--rows", default=None, help="ablation rows to run, e.g. 1,7,8 (default all)")
    parser.add_argument("--json", default=None, help="write the figures to this JSON file")
    args = parser.parse_args(argv)
    torch.set_num_threads(args.threads)
    os.environ.setdefault("HF_HUB_OFFLINE", "1")
    from controlmm.editing import PRESETS
    from controlmm.eval.control import build_cases
    from controlmm.generate import generate_controlled, load_model

    model = load_model(args.model)
    data = model_data(model, args.data)
    print(
        f"machine: {platform.machine()}, {os.cpu_count()} CPUs, torch {torch.__version__}, "
        f"{args.threads} threads, load average at start {load_avg()}; model {model.directory}; data {data}"
    )
    report: dict = {
        "threads": args.threads,
        "samples": args.samples,
        "joints": args.joints,
        "data": str(data),
        "model": str(model.directory),
        "command": "python benchmarks/control.py " + " ".join(sys.argv[1:]),
    }
    cases = build_cases(data, args.joints, samples=args.samples, seed=args.seed)
    warm = cases[0]
    generate_controlled(model, warm.text, targets=warm.targets, mask=warm.mask, preset="fast", seed=args.seed)
    ablation: dict[int, dict] = {}
    skate_base = None
    if args.table in ("ablation", "both"):
        chosen = [int(x) for x in args.rows.split(",")] if args.rows else list(range(1, 9))
        configs = []
        for k in chosen:
            logits, codebook, control = ROWS[k - 1]
            config = replace(
                PRESETS["accurate"],
                name=f"row{k}",
                control_model=control,
                logits_steps=100 if logits else 0,
                codebook_steps=600 if codebook else 0,
            )
            mark = lambda flag: "x" if flag else "-"  # noqa: E731
            configs.append((f"{k}|{mark(logits)}|{mark(codebook)}|{mark(control)}", config))
        print(f"ablation ({len(cases)} cases x {len(configs)} rows)")
        rows = run_rows(model, cases, configs, args.seed)
        ablation = dict(zip(chosen, rows, strict=True))
        skate_base = uncontrolled_skate(model, cases, [c.frames for c in cases], args.seed)
        print_table(
            "Table 3 analogue (L = logits editing, E = codebook editing, M = motion control model)",
            rows,
            skate_base,
            ["#", "L", "E", "M"],
        )
        report["ablation"] = {"rows": rows, "uncontrolled_skate": skate_base}
        if 8 in ablation:
            check_targets(
                ablation[8], [(f"row {k}", ablation[k]) for k in (1, 5) if k in ablation], skate_base
            )
    if args.table in ("speed", "both"):
        speed_cases = cases[: args.speed_samples] if args.speed_samples else cases
        long_cases = [
            replace(
                c,
                frames=196,
                targets=np.concatenate([c.targets, np.zeros((196 - c.frames, 22, 3), np.float32)]),
                mask=np.concatenate([c.mask, np.zeros((196 - c.frames, 22), bool)]),
            )
            for c in speed_cases
        ]
        configs = [(name, PRESETS[name]) for name in ("fast", "medium", "accurate")]
        print(f"speed ({len(long_cases)} cases of 196 frames x {len(configs)} presets)")
        rows = run_rows(model, long_cases, configs, args.seed)
        base = uncontrolled_skate(model, long_cases, [196] * len(long_cases), args.seed)
        print_table("Table 5 analogue (196-frame motions, batch 1)", rows, base, ["preset"])
        report["speed"] = {"rows": rows, "uncontrolled_skate": base}
        accurate = rows[-1]
        print(
            f"\naccurate on 196-frame motions: {accurate['seconds']:.2f} s per motion wall, "
            f"{accurate['cpu_seconds']:.2f} s CPU: "
            f"{'met' if accurate['seconds'] <= 10 else 'MISSED'} (<= 10 s)"
        )
        print("real-time target (issue 38): every motion within 1 cm in <= 1 s per 196-frame motion")
        for r in rows:
            ok = r["within_1cm"] == 1.0 and r["seconds"] <= 1.0
            print(
                f"  {r['label']}: {100 * r['within_1cm']:.0f} % of motions within 1 cm (worst keyframe "
                f"{100 * r['max']:.2f} cm), {r['seconds']:.2f} s per motion (max {r['seconds_max']:.2f}): "
                f"{'met' if ok else 'missed'}"
            )
    print(f"load average at the end {load_avg()}")
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(report, fh, indent=1)
    return 0


if __name__ == "__main__":
    sys.exit(main())
