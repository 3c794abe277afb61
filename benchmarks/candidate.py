"""Evaluate a retrained candidate of the default model: every figure its model card records, in one run.

    python benchmarks/candidate.py --model data/models/r33 --out data/eval/r33
    python benchmarks/candidate.py --model data/models/r33 --steps size,training,probes-test,probes-val
    python benchmarks/candidate.py --model data/models/r33 --dry-run        # the commands, nothing run

Runs the steps below one after the other (each command's output in OUT/<step>.log, its JSON where
it writes one), then prints a summary against the targets: text-adherence probes per family on the
test split (held-out phrasings; >= 80 % overall, >= 60 % on every robot-task family, also on the
held-out templates alone) and on the validation split (training phrasings), tokenizer MPJPE and
generation latency, user-worded robot-task prompts, gait of generated and timeline walks (peak joint
speed of a ~1 m/s walk < 6 m/s), spatial control, plans in the bundled scenes (pass rate must not
drop below the shipped default's), timeline, and the size with the evaluator (<= 25 MiB).
Each step is a plain command (``--dry-run`` prints them): run one alone to repeat a figure.
``evaluator`` and ``quality`` (train an evaluator on the corpus, then the quality table with it) are
not in the default steps: ``--steps evaluator,quality``.

Timing figures need a quiet machine: run it when nothing else does (about 60-75 min on 2 cores
without the optional steps).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path

from data_dirs import ROOT, corpus_dir

from controlmm.corpus import family_names, get_family
from controlmm.eval.cases import list_cases

ROBOT_TASK_GROUPS = ("postures", "actions", "terrain", "sequences")
"""The groups of the robot-task families (their probes must pass >= 60 % each)."""
SIZE_BUDGET = 25 * 2**20
"""Bytes the shipped model and evaluator may take together."""
SHIPPED = ROOT / "controlmm" / "checkpoints"


def commands(model: str, data: str, out: Path, evaluator: str) -> dict[str, list[str]]:
    """Each step's command (run from the repository root)."""
    probes = [
        "controlmm",
        "eval",
        "probes",
        "--data",
        data,
        "--model",
        model,
        "--quiet",
        "--show-failures",
        "0",
    ]
    py = [sys.executable]
    return {
        "probes-test": [*probes, "--split", "test", "--json", str(out / "probes_test.json"), "--force"],
        "probes-val": [*probes, "--split", "val", "--json", str(out / "probes_val.json"), "--force"],
        "probes-tokenizer": [
            *probes,
            "--split",
            "test",
            "--tokenizer-only",
            "--json",
            str(out / "probes_tokenizer.json"),
            "--force",
        ],
        "model": [
            *py,
            "benchmarks/model.py",
            "--threads",
            "2",
            "--model",
            model,
            "--data",
            data,
            "--skip-training",
        ],
        "user-prompts": [
            *py,
            "benchmarks/user_prompts.py",
            "--model",
            model,
            "--seeds",
            "3",
            "--corpus",
            data,
            "--json",
            str(out / "user_prompts.json"),
        ],
        "gait": [*py, "benchmarks/gait.py", "--model", model, "--corpus", data],
        "control": [
            *py,
            "benchmarks/control.py",
            "--model",
            model,
            "--data",
            data,
            "--samples",
            "15",
            "--speed-samples",
            "10",
            "--threads",
            "1",
            "--json",
            str(out / "control.json"),
        ],
        "plan": [*py, "benchmarks/plan.py", "--model", model, "--workers", "2"],
        "timeline": [*py, "benchmarks/timeline.py", "--model", model, "--corpus", data],
        "evaluator": [
            "controlmm",
            "train",
            "evaluator",
            "--data",
            data,
            "--out",
            str(out / "evaluator"),
            "--threads",
            "2",
            "--no-progress",
        ],
        "quality": [
            *py,
            "benchmarks/quality.py",
            "--part",
            "table1",
            "--model",
            model,
            "--evaluator",
            evaluator,
            "--data",
            data,
            "--samples",
            "32",
            "--repeats",
            "3",
            "--json",
            str(out / "quality.json"),
        ],
    }


IN_PROCESS = ("size", "training")
DEFAULT_STEPS = (
    "size",
    "training",
    "probes-test",
    "probes-val",
    "probes-tokenizer",
    "model",
    "user-prompts",
    "gait",
    "control",
    "plan",
    "timeline",
)
KEY_LINES = {
    "model": ("generation 196 frames", "MPJPE", "load average"),
    "gait": ("generated:", "timeline:", "corpus:"),
    "control": ("  accurate", "  foot skating", "  editing cuts"),
    "plan": ("plan benchmark", "| all |"),
    "timeline": ("| ", "probe pass rate per track"),
    "user-prompts": ("| ", "model "),
    "quality": ("R@3", "FID"),
}
"""Lines of a step's output repeated in the summary (the full output is in its log)."""


def shipped_files(directory: Path) -> list[Path]:
    """The files a model or evaluator directory ships (not its checkpoints/ or cache/)."""
    return [p for p in directory.iterdir() if p.is_file()]


def size_report(model: Path, evaluator: Path) -> str:
    m = sum(p.stat().st_size for p in shipped_files(model))
    e = sum(p.stat().st_size for p in shipped_files(evaluator))
    verdict = "within" if m + e <= SIZE_BUDGET else "OVER"
    return (
        f"size: model {m:,} B + evaluator {e:,} B = {(m + e) / 2**20:.1f} MiB ({verdict} the 25 MiB budget)"
    )


def training_report(model: Path) -> str:
    """Per stage: iterations, wall time, throughput and the exported checkpoint's validation figures."""
    manifest = json.loads((model / "model.json").read_text())
    lines, total = [], 0.0
    for stage, rec in manifest.get("training", {}).items():
        total += rec.get("wall_time_s", 0.0)
        best = {k: round(v, 4) if isinstance(v, float) else v for k, v in rec.get("best", {}).items()}
        lines.append(
            f"  {stage}: {rec.get('iterations')} it, {rec.get('wall_time_s', 0) / 60:.1f} min "
            f"({rec.get('throughput_it_s')} it/s, {rec.get('threads')} threads, {rec.get('device')}), "
            f"exported {rec.get('exported')}: {best}"
        )
    return "\n".join([f"training: {total / 60:.0f} min in all", *lines])


def probes_report(path: Path, data: Path, split: str) -> str:
    """Overall and per-family pass rates; for the test split also the robot-task families against
    their 60 % target and the held-out templates alone."""
    report = json.loads(path.read_text())
    lines = [f"probes ({split}): {100 * report['rate']:.1f} % ({report['passed']} / {report['total']})"]
    rows = []
    order = {name: k for k, name in enumerate(family_names())}
    for family, c in sorted(report["families"].items(), key=lambda item: order.get(item[0], len(order))):
        robot = get_family(family).group in ROBOT_TASK_GROUPS
        rate = c["passed"] / max(c["total"], 1)
        flag = " BELOW 60 %" if robot and rate < 0.6 else ""
        rows.append(f"{family}{' *' if robot else ''} {100 * rate:.0f} %{flag}")
    lines.append("  " + "; ".join(rows) + "  (* robot-task family)")
    if split == "test":
        failed = {(f["clip"], f["caption"]) for f in report["failures"]}
        held = {True: [0, 0], False: [0, 0]}
        robot = [0, 0]
        for case in list_cases(data, split):
            meta = json.loads((data / "meta" / f"{case.clip_id}.json").read_text())
            template = next(c["template"] for c in meta["captions"] if c["text"] == case.caption)
            family = get_family(case.family)
            in_held = family.templates[int(template.split("/")[1])].held
            ok = (case.clip_id, case.caption) not in failed
            held[in_held][0] += ok
            held[in_held][1] += 1
            if family.group in ROBOT_TASK_GROUPS:
                robot[0] += ok
                robot[1] += 1
        for name, (ok, n) in (("held-out templates", held[True]), ("held-out words only", held[False])):
            lines.append(f"  {name}: {100 * ok / max(n, 1):.1f} % ({ok} / {n})")
        lines.append(
            f"  robot-task families together: {100 * robot[0] / max(robot[1], 1):.1f} % "
            f"({robot[0]} / {robot[1]})"
        )
    return "\n".join(lines)


def main() -> int:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--model", required=True, help="candidate model directory")
    parser.add_argument("--data", default=None, help="corpus (default data/corpus-default)")
    parser.add_argument("--out", default=None, help="where logs and JSON go (default data/eval/<model name>)")
    parser.add_argument(
        "--steps",
        default=",".join(DEFAULT_STEPS),
        help=f"comma-separated steps (default {','.join(DEFAULT_STEPS)})",
    )
    parser.add_argument(
        "--evaluator",
        default=None,
        help="evaluator for 'quality' (default: OUT/evaluator if trained, else the shipped one)",
    )
    parser.add_argument("--dry-run", action="store_true", help="print the commands and exit")
    args = parser.parse_args()
    model = Path(args.model)
    if not (model / "model.json").is_file():
        sys.exit(f"--model {model}: no model.json there (a trained model directory is needed)")
    data = corpus_dir(args.data)
    out = Path(args.out) if args.out else ROOT / "data" / "eval" / model.name
    steps = [s.strip() for s in args.steps.split(",") if s.strip()]
    trained = "evaluator" in steps or (out / "evaluator" / "evaluator.json").is_file()
    evaluator = SHIPPED / "evaluator" if not trained else out / "evaluator"
    evaluator = Path(args.evaluator) if args.evaluator else evaluator
    cmds = commands(str(model), str(data), out, str(evaluator))
    unknown = [s for s in steps if s not in cmds and s not in IN_PROCESS]
    if unknown:
        sys.exit(f"unknown steps {unknown}; known: {', '.join([*IN_PROCESS, *cmds])}")
    if args.dry_run:
        for step in steps:
            shown = " ".join("python" if a == sys.executable else a for a in cmds.get(step, []))
            print(f"# {step}\n{shown or f'(in process: reads {model})'}")
        return 0
    out.mkdir(parents=True, exist_ok=True)
    env = {**os.environ, "HF_HUB_OFFLINE": "1", "OMP_NUM_THREADS": os.environ.get("OMP_NUM_THREADS", "2")}
    summary: list[str] = []
    for step in steps:
        if step == "size":
            summary.append(size_report(model, evaluator if evaluator.is_dir() else SHIPPED / "evaluator"))
            continue
        if step == "training":
            summary.append(training_report(model))
            continue
        log = out / f"{step}.log"
        print(f"[{time.strftime('%H:%M:%S')}] {step}: {' '.join(cmds[step])}", flush=True)
        t0 = time.perf_counter()
        with log.open("w") as f:
            rc = subprocess.run(cmds[step], cwd=ROOT, env=env, stdout=f, stderr=subprocess.STDOUT).returncode
        wall = time.perf_counter() - t0
        head = f"{step}: exit {rc}, {wall / 60:.1f} min, log {log}"
        if rc == 0 and step.startswith("probes-"):
            split = "test" if step != "probes-val" else "val"
            head += "\n" + probes_report(out / f"probes_{step.split('-')[1]}.json", data, split)
        lines = log.read_text().splitlines()
        keys = KEY_LINES.get(step, ())
        head += "".join(f"\n  {line}" for line in lines if any(k in line for k in keys))
        summary.append(head)
        print(head, flush=True)
    print("\n== summary ==\n" + "\n".join(summary))
    (out / "summary.txt").write_text("\n".join(summary) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
