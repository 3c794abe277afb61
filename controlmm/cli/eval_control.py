"""``controlmm eval control``: the spatial-control evaluation protocol (OmniControl / ControlMM)."""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import TYPE_CHECKING

from controlmm.atomic import check_output_file, write_text
from controlmm.cli.args import add_force, add_threads, integer, positive, seed
from controlmm.errors import ControlMMError

HELP = """Evaluate spatial control the way OmniControl and ControlMM do: targets taken from held-out motions
(the test split of --data, default the data the model was trained on), controlled joints at 1, 2 or 5
frames or 25 % / 100 % of the frames (--density 1, 2, 5, 49, 196; default: the five in turn), one
motion per case generated from the clip's caption and length under the control, then:

  Traj. err  fraction of motions with any keyframe off by more than 50 cm
  Loc. err   fraction of keyframes off by more than 50 cm
  Avg. err   mean keyframe error (cm)
  max        worst controlled-joint error over all cases (cm)
  skate      foot-skating ratio (feet below 5 cm moving faster than 0.5 m/s)
  steps      editing steps used (logits + codebook), s/motion wall time

Text-motion quality of the generated motions, scored by the text-motion evaluator (--evaluator,
default the shipped one; --no-quality to skip) against the ground truth of the same cases:
R-precision top-1/2/3 (groups of 32), FID, Diversity, MM-Dist. --repeats N draws the cases N times
(seed + r) and reports every column as mean +- 95% CI (1.96 std / sqrt(N)); --real adds the ground
truth row, --uncontrolled a row generated without control model or editing (the paper's Table 1:
--joints pelvis,each --real --uncontrolled).

--joints: pelvis, left_foot, right_foot, head, left_wrist, right_wrist (one joint), cross (the 63
combinations of the six, in turn), all (the six at once), random (one of the six per case), each (the
six in turn, one per case: the paper's all-joints average); several separated by commas.

examples:
  controlmm eval control --preset accurate --joints pelvis --samples 50
  controlmm eval control --model MODEL_DIR --preset fast --joints cross --density 196 --json out.json
  controlmm eval control --joints pelvis,each --real --uncontrolled --samples 64 --repeats 3 \
      --batch-size 32"""


if TYPE_CHECKING:
    from controlmm.generate import MotionModel


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "control",
        help="spatial-control metrics (Traj./Loc./Avg. err, foot skating)",
        description=HELP,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("--model", default=None, help="model directory (default: the embedded default model)")
    p.add_argument(
        "--data",
        default=None,
        help="HumanML3D-format directory whose test split gives the targets "
        "(default: the data the model was trained on)",
    )
    p.add_argument(
        "--preset",
        default="accurate",
        choices=("fast", "medium", "accurate"),
        help="control/editing preset (default accurate)",
    )
    p.add_argument("--joints", default="pelvis", help="joint mode(s), comma-separated (default pelvis)")
    p.add_argument(
        "--density",
        default="all",
        help="controlled frames: 1, 2, 5, 49 (25%%), 196 (100%%) or all (the five in turn; default)",
    )
    p.add_argument("--samples", type=integer(1), default=50, help="cases per joint mode (default 50)")
    p.add_argument("--seed", type=seed, default=0, help="seed of the cases and of generation (default 0)")
    p.add_argument(
        "--batch-size",
        type=integer(1),
        default=1,
        help="cases generated together (default 1: per-motion timings)",
    )
    p.add_argument(
        "--tolerance", type=positive, default=None, metavar="CM", help="editing tolerance in cm (default 1)"
    )
    p.add_argument("--no-control-model", action="store_true", help="editing only, without the control model")
    p.add_argument(
        "--logits-steps", type=int, default=None, metavar="N", help="override the preset's logits steps"
    )
    p.add_argument(
        "--codebook-steps", type=int, default=None, metavar="N", help="override the preset's codebook steps"
    )
    p.add_argument(
        "--contact-steps",
        type=int,
        default=None,
        metavar="N",
        help="override the preset's foot-contact steps after codebook editing (accurate: 200)",
    )
    p.add_argument(
        "--repeats",
        type=integer(1),
        default=1,
        help="draws of the cases (seed + r), for mean and 95%% CI of every column (default 1)",
    )
    p.add_argument(
        "--evaluator",
        default=None,
        metavar="E",
        help="text-motion evaluator directory for the quality columns (default: the shipped one)",
    )
    p.add_argument(
        "--no-quality", action="store_true", help="skip the text-motion columns (R-precision, FID, ...)"
    )
    p.add_argument("--real", action="store_true", help="add the Real row (the ground truth of the cases)")
    p.add_argument(
        "--uncontrolled",
        action="store_true",
        help="add a row generated without control model or editing (errors against the first mode's targets)",
    )
    p.add_argument("--json", default=None, help="also write the per-case results to this JSON file")
    add_force(p, "--json")
    add_threads(p, None)
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=run)


def parse_modes(text: str, allowed: tuple[str, ...]) -> list[str]:
    """``--joints``: comma-separated joint modes, each one of ``allowed``."""
    modes = [m.strip() for m in text.split(",") if m.strip()]
    for m in modes:
        if m not in allowed:
            raise ControlMMError(f"unknown --joints '{m}'; allowed: {', '.join(allowed)}")
    if not modes:
        raise ControlMMError("--joints is empty")
    return modes


def parse_densities(text: str, allowed: tuple[int, ...]) -> tuple[int, ...]:
    """``--density``: ``all`` or comma-separated frame counts, each one of ``allowed``."""
    if text == "all":
        return allowed
    try:
        values = tuple(int(x) for x in text.split(","))
    except ValueError:
        values = ()
    if not values or any(v not in allowed for v in values):
        raise ControlMMError(f"unknown --density '{text}'; allowed: {', '.join(map(str, allowed))} or all")
    return values


def default_data(model: MotionModel) -> str:
    """The data directory recorded in the model's training record (control stage first)."""
    training = model.manifest.get("training", {})
    for stage in ("control", "transformer", "tokenizer"):
        data = training.get(stage, {}).get("data")
        if data and Path(data).is_dir():
            return data
    raise ControlMMError(
        "the model's training data is not on this machine; pass --data DIR "
        "(a HumanML3D-format directory with a test split)"
    )


def run(args: argparse.Namespace) -> int:
    # heavy (torch, the models): imported when the command runs, so that --help stays fast
    import torch

    from controlmm import editing, generate as generation
    from controlmm.eval import control, control_table, evaluator

    modes = parse_modes(args.joints, control.JOINT_MODES)
    densities = parse_densities(args.density, control.DENSITIES)
    if args.samples < 2 and not args.no_quality:
        raise ControlMMError("the quality columns need --samples 2 or more (or pass --no-quality)")
    if args.json:
        check_output_file(args.json, force=args.force)
    if args.threads is not None:
        torch.set_num_threads(args.threads)
    model = generation.load_model(args.model)
    data = args.data or default_data(model)
    config = editing.editing_preset(args.preset).with_overrides(
        tolerance=None if args.tolerance is None else args.tolerance / 100.0,
        control_model=False if args.no_control_model else None,
        logits_steps=args.logits_steps,
        codebook_steps=args.codebook_steps,
        contact_steps=args.contact_steps,
    )
    judge = None
    if not args.no_quality:
        # Default: the evaluator the model directory carries (import-official --evaluator), else the
        # shipped one.
        judge = evaluator.load_evaluator(args.evaluator or evaluator.model_evaluator(args.model))
    TableRow = control_table.TableRow
    rows = [TableRow("uncontrolled", modes[0], control_table.UNCONTROLLED)] if args.uncontrolled else []
    rows += [TableRow(mode, mode, config) for mode in dict.fromkeys(modes)]
    table = control_table.evaluate_control_table(
        model,
        data,
        rows,
        evaluator=judge,
        densities=densities,
        samples=args.samples,
        repeats=args.repeats,
        seed=args.seed,
        batch_size=args.batch_size,
        real=args.real,
        progress=not args.quiet,
    )
    unknown = getattr(judge, "unknown_word_share", None)
    if judge is not None and unknown is not None:
        share = unknown([c.text for c in table.evaluations[rows[0].name][0].cases])
        if share > 0.5:
            print(
                f"warning: {100 * share:.0f}% of the caption words are unknown to the evaluator "
                f"({judge.name}); train one on this data: controlmm train evaluator --data {data}"
            )
    reports = []
    for mode in dict.fromkeys(modes):
        results = table.evaluations[mode]
        print(results[0].table())
        report = results[0].to_json() | {
            "data": str(data),
            "model": str(model.directory),
            "table_row": table.rows[mode].to_json(),
        }
        if args.repeats > 1:
            report["repeats"] = [r.by_density()["all"] for r in results]
        reports.append(report)
    reports += [
        {"joints": name, "table_row": table.rows[name].to_json()}
        for name in ("Real", "uncontrolled")
        if name in table.rows
    ]
    print(
        f"\n{len(table.rows)} rows, {args.samples} cases x {args.repeats} repeat(s) each, mean ± 95% CI"
        + (f"; quality by {judge.name}" if judge is not None else "")
    )
    print(table.table())
    if args.json:
        write_text(args.json, json.dumps(reports if len(reports) > 1 else reports[0], indent=1) + "\n")
        print(f"wrote {args.json}")
    return 0
