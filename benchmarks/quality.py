"""Quality benchmark: the evaluator's own accuracy and the paper's Table 1 / Table 3 analogues.

    python benchmarks/quality.py --part sanity                       # evaluator retrieval + sanity checks
    python benchmarks/quality.py --part table1 --samples 64 --repeats 3
    python benchmarks/quality.py --part table3 --samples 64 --repeats 1
    python benchmarks/quality.py --model MODEL_DIR --data DATA_DIR --json out.json

- **sanity** (no model): the shipped evaluator on the real test split, ``--sanity-repeats`` evaluation
  passes (random caption and crop per clip, groups of 32; chance R-precision 1/32, 2/32, 3/32): the
  ground truth's R-precision and MM-Dist, FID of the pass against itself (0) and against an
  independent pass, and the damaged sets (frames shuffled, Gaussian noise of 1 and 2 feature std,
  captions rotated by one).
- **table1**: rows Real, uncontrolled, pelvis control, all joints (``each``: the six control joints
  in turn, one per case), accurate preset, ``--samples`` test cases per repeat, densities 1, 2, 5,
  25 %, 100 % in turn (``controlmm.eval.control_table``).
- **table3**: the ablation on pelvis control: logits editing (100 steps per iteration) x codebook
  editing (600) x motion control model.

Each part prints a Markdown table (mean ± 95 % CI over the repeats) and the CPU and wall time.
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

ABLATION = [  # (logits editing, codebook editing, motion control model): the paper's Table 3 order
    (False, False, False),
    (True, False, False),
    (False, True, False),
    (True, True, False),
    (False, False, True),
    (True, False, True),
    (False, True, True),
    (True, True, True),
]
QUALITY = ("r_precision_top1", "r_precision_top2", "r_precision_top3", "fid", "diversity", "mm_dist")
CONTROL = ("skate", "traj", "loc", "avg")


def cell(values: dict, key: str) -> str:
    if key not in values:
        return "–"
    mean, ci = values[key]
    if key == "avg":
        return f"{100 * mean:.2f} ± {100 * ci:.2f}"
    digits = 4 if key in CONTROL else 3
    return f"{mean:.{digits}f} ± {ci:.{digits}f}"


def markdown(summary: dict, lead: list[str], labels: dict[str, list[str]]) -> str:
    head = lead + [
        "R@1",
        "R@2",
        "R@3",
        "FID",
        "Diversity",
        "MM-Dist",
        "Foot skating",
        "Traj. err",
        "Loc. err",
        "Avg. err (cm)",
    ]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for name, values in summary.items():
        lines.append(
            "| " + " | ".join(labels.get(name, [name]) + [cell(values, k) for k in QUALITY + CONTROL]) + " |"
        )
    return "\n".join(lines)


def sanity(evaluator, data: str, repeats: int, seed: int) -> dict:
    from controlmm.eval import metrics as M
    from controlmm.eval.quality import EvalSet
    from controlmm.eval.scoring import columns_from_embeddings

    evalset = EvalSet.load(data, "test")
    rows: dict[str, dict[str, list[float]]] = {}

    def add(name, values):
        for k in QUALITY:
            rows.setdefault(name, {}).setdefault(k, []).append(float(values[k]))

    std = evaluator.normalizer.std
    for r in range(repeats):
        rng = np.random.default_rng([seed, r])
        run = evalset.draw(seed + r)
        other = evalset.draw(seed + r + 100_003)
        texts = evaluator.embed_texts(run.captions)
        gt = evaluator.embed_motions(run.motions)
        add("ground truth vs itself", columns_from_embeddings(texts, gt, gt, seed=seed + r))
        add(
            "ground truth vs independent pass",
            columns_from_embeddings(texts, gt, evaluator.embed_motions(other.motions), seed=seed + r),
        )
        shuffled = [m[rng.permutation(len(m))] for m in run.motions]
        add(
            "frames shuffled",
            columns_from_embeddings(texts, evaluator.embed_motions(shuffled), gt, seed=seed + r),
        )
        for sigma in (1.0, 2.0):
            noised = [m + rng.normal(size=m.shape).astype(np.float32) * sigma * std for m in run.motions]
            add(
                f"noise {sigma} std",
                columns_from_embeddings(texts, evaluator.embed_motions(noised), gt, seed=seed + r),
            )
        rotated = np.concatenate([gt[1:], gt[:1]])
        add("captions rotated by one", columns_from_embeddings(texts, rotated, gt, seed=seed + r))
    summary = {name: {k: M.mean_ci(v) for k, v in cols.items()} for name, cols in rows.items()}
    head = ["set", "R@1", "R@2", "R@3", "FID", "Diversity", "MM-Dist"]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for name, values in summary.items():
        lines.append("| " + " | ".join([name] + [cell(values, k) for k in QUALITY]) + " |")
    print(
        f"\nevaluator sanity: {evaluator.name}; test split {len(evalset)} samples, "
        f"passes of {len(run.samples)} "
        f"(groups of 32), {repeats} passes; chance R@1/2/3 = {1 / 32:.3f} / {2 / 32:.3f} / {3 / 32:.3f}"
    )
    print("\n".join(lines), flush=True)
    return {
        "samples_per_pass": len(run.samples),
        "split_samples": len(evalset),
        "repeats": repeats,
        "rows": {n: {k: {"mean": m, "ci95": c} for k, (m, c) in v.items()} for n, v in summary.items()},
    }


def ablation_config(k: int):
    from controlmm.editing import PRESETS

    logits, codebook, control = ABLATION[k - 1]
    return replace(
        PRESETS["accurate"],
        name=f"row{k}",
        control_model=control,
        logits_steps=100 if logits else 0,
        codebook_steps=600 if codebook else 0,
    )


def run_rows(model, evaluator, data, rows, args, real: bool):
    """One row at a time (each printed as soon as it is done); returns row -> Scores and JSON."""
    from controlmm.eval.control_table import evaluate_control_table

    summary, record = {}, {}
    for i, row in enumerate(rows):
        started, cpu = time.perf_counter(), time.process_time()
        table = evaluate_control_table(
            model,
            data,
            [row],
            evaluator=evaluator,
            samples=args.samples,
            repeats=args.repeats,
            seed=args.seed,
            batch_size=args.batch_size,
            real=real and i == 0,
        )
        summary |= table.summary()
        record |= table.to_json()["rows"]
        print(
            f"  {row.name}: {time.perf_counter() - started:.0f} s wall, "
            f"{time.process_time() - cpu:.0f} s CPU",
            flush=True,
        )
        print(table.table(), flush=True)
    return summary, record


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--part", default="all", choices=("sanity", "table1", "table3", "all"))
    parser.add_argument("--model", default=None, help="model directory (default: the embedded default)")
    parser.add_argument(
        "--data",
        default=None,
        help="HumanML3D-format directory (default: the model's recorded training data when it is on this "
        "machine, else data/corpus-default)",
    )
    parser.add_argument("--evaluator", default=None, help="evaluator directory (default: the shipped one)")
    parser.add_argument("--samples", type=int, default=64, help="test cases per repeat (default 64)")
    parser.add_argument("--repeats", type=int, default=3, help="repeats of the tables (default 3)")
    parser.add_argument("--sanity-repeats", type=int, default=10, help="evaluation passes of the sanity part")
    parser.add_argument("--rows", default=None, help="ablation rows to run, e.g. 1,7,8 (default all)")
    parser.add_argument("--batch-size", type=int, default=32)
    parser.add_argument("--threads", type=int, default=1)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--json", default=None, help="write the figures to this JSON file")
    args = parser.parse_args(argv)
    torch.set_num_threads(args.threads)
    os.environ.setdefault("HF_HUB_OFFLINE", "1")
    from controlmm.eval.control_table import UNCONTROLLED, TableRow
    from controlmm.eval.evaluator import load_evaluator

    evaluator = load_evaluator(args.evaluator)
    report: dict = {
        "command": "python benchmarks/quality.py " + " ".join(sys.argv[1:] if argv is None else argv),
        "machine": f"{platform.machine()}, {os.cpu_count()} CPUs, torch {torch.__version__}, "
        f"{args.threads} thread(s)",
        "evaluator": evaluator.name,
    }
    print(report["machine"])
    started, cpu = time.perf_counter(), time.process_time()
    model = data = None
    if args.part != "sanity":
        from controlmm.generate import load_model

        model = load_model(args.model)
        data = model_data(model, args.data)
        report |= {
            "model": str(model.directory),
            "data": str(data),
            "samples": args.samples,
            "repeats": args.repeats,
        }
        print(
            f"model {model.directory}; data {data}; {args.samples} cases x {args.repeats} repeats per row, "
            f"batch {args.batch_size}"
        )
    if args.part in ("sanity", "all"):
        if data is None:
            from controlmm.generate import load_model

            data = model_data(load_model(args.model), args.data)
        report["sanity"] = sanity(evaluator, data, args.sanity_repeats, args.seed)
    if args.part in ("table1", "all"):
        rows = [
            TableRow("uncontrolled", "pelvis", UNCONTROLLED),
            TableRow("pelvis", "pelvis", "accurate"),
            TableRow("all joints (avg)", "each", "accurate"),
        ]
        summary, record = run_rows(model, evaluator, data, rows, args, real=True)
        print("\nTable 1 analogue (accurate preset)")
        print(markdown(summary, ["Method"], {}), flush=True)
        report["table1"] = record
    if args.part in ("table3", "all"):
        chosen = [int(x) for x in args.rows.split(",")] if args.rows else list(range(1, 9))
        rows = [TableRow(f"#{k}", "pelvis", ablation_config(k)) for k in chosen]
        summary, record = run_rows(model, evaluator, data, rows, args, real=False)
        mark = lambda flag: "✓" if flag else "×"  # noqa: E731
        labels = {f"#{k}": [str(k)] + [mark(f) for f in ABLATION[k - 1]] for k in chosen}
        print(
            "\nTable 3 analogue (pelvis control; L = logits editing, E = codebook editing, "
            "M = motion control model)"
        )
        print(markdown(summary, ["#", "L", "E", "M"], labels), flush=True)
        report["table3"] = record
    report["seconds"] = {"wall": time.perf_counter() - started, "cpu": time.process_time() - cpu}
    print(f"\ntotal: {report['seconds']['wall']:.0f} s wall, {report['seconds']['cpu']:.0f} s CPU")
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(report, fh, indent=1)
    return 0


if __name__ == "__main__":
    sys.exit(main())
