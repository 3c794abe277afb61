"""``controlmm eval probes --data DIR [--model M]``: text-adherence probes per motion family."""

from __future__ import annotations

import argparse
import json

from controlmm.atomic import check_output_file, write_text
from controlmm.cli.args import add_force, integer, seed
from controlmm.errors import ControlMMError

HELP = """Check that motions do what their captions say, family by family, with simple geometry
in the person's frame (e.g. "walks backwards": the pelvis moves against the facing
direction; "waves right hand": the right wrist is above the head and swings side to side;
"circle counter-clockwise": the heading turns >= 300 degrees to the left; "jumps twice":
two flight phases). Every caption's claims (direction, speed, hand, count, angle...) come
from the corpus' meta/<id>.json. Prints the pass rate per family.

--data DIR alone checks the corpus' own motions (ground truth: 100% expected).
--model M generates a motion from every caption of the split (the clip's length, seeds
SEED, SEED+1, ... per batch) and checks it: the model's text adherence on captions it has
not seen (the test split's wording is held out from training). --samples and --families
keep it quick. --model M --tokenizer-only passes each ground-truth clip through the model's
tokenizer instead (encode, decode; --layers keeps the first quantizer layers): what the token
space can represent, the ceiling of the generator.

examples:
  controlmm eval probes --data corpus
  controlmm eval probes --data corpus --split all --json probes.json
  controlmm eval probes --data corpus --model MODEL_DIR --samples 20
  controlmm eval probes --data corpus --model MODEL_DIR --families wave_left,wave_right
  controlmm eval probes --data corpus --model MODEL_DIR --tokenizer-only --layers 1"""


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "probes",
        help="text-adherence probes per motion family (ground truth or a model)",
        description=HELP,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("--data", required=True, help="corpus directory (HumanML3D format with meta/)")
    p.add_argument(
        "--split",
        default="test",
        choices=("train", "val", "test", "all"),
        help="which split's captions to check (default test)",
    )
    p.add_argument(
        "--model",
        default=None,
        metavar="MODEL_DIR",
        help="generate from each caption with this model directory ('default': the embedded model)",
    )
    p.add_argument(
        "--samples",
        type=integer(1),
        default=None,
        metavar="N",
        help="at most N captions per family (a seeded random choice; default all)",
    )
    p.add_argument("--families", default=None, help="comma-separated families to check (default all)")
    p.add_argument(
        "--seed", type=seed, default=0, help="seed of the caption choice and the generation (default 0)"
    )
    p.add_argument(
        "--batch-size", type=integer(1), default=32, help="captions generated together (default 32)"
    )
    p.add_argument("--device", default="cpu", help="cpu or cuda, for --model (default cpu)")
    p.add_argument(
        "--tokenizer-only",
        action="store_true",
        help="with --model: probe the ground truth reconstructed by the model's tokenizer",
    )
    p.add_argument(
        "--layers",
        type=integer(1),
        default=None,
        help="with --tokenizer-only: quantizer layers kept (default all)",
    )
    p.add_argument(
        "--json", default=None, help="also write the report (with failed checks) to this JSON file"
    )
    add_force(p, "--json")
    p.add_argument(
        "--show-failures", type=integer(0), default=10, help="print up to N failed captions (default 10)"
    )
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    # heavy (torch, the models): imported when the command runs, so that --help stays fast
    from controlmm import generate as generation
    from controlmm.eval import cases as probe_cases, model_probes

    if args.json:
        check_output_file(args.json, force=args.force)
    if (args.tokenizer_only or args.layers is not None) and args.model is None:
        raise ControlMMError("--tokenizer-only and --layers need --model")
    if args.layers is not None and not args.tokenizer_only:
        raise ControlMMError("--layers goes with --tokenizer-only")
    cases = probe_cases.list_cases(args.data, args.split)
    families = [f.strip() for f in args.families.split(",") if f.strip()] if args.families else None
    if args.families is not None and not families:
        raise ControlMMError("--families is empty; give comma-separated family names")
    cases = model_probes.select_cases(cases, families, args.samples, args.seed)
    if not cases:
        raise ControlMMError(f"the {args.split} split of '{args.data}' has no captions to check")
    if args.model is None:
        source, what = probe_cases.ground_truth(args.data), "ground truth"
        report = probe_cases.evaluate(cases, source, split=args.split, per_clip=True, progress=not args.quiet)
    else:
        # generation without control: every listed part but the motion control model
        model = generation.load_model(
            None if args.model == "default" else args.model, device=args.device, skip=("control",)
        )
        if args.tokenizer_only:
            source = model_probes.tokenized_motions(model, args.data, args.layers)
            what = f"ground truth through the tokenizer of {model.directory}, {args.layers or 'all'} layer(s)"
        else:
            source = model_probes.generated_motions(
                model, cases, seed=args.seed, batch_size=args.batch_size, progress=not args.quiet
            )
            what = f"model {model.directory}, seed {args.seed}"
        report = probe_cases.evaluate(cases, source, split=args.split, progress=not args.quiet)
    print(f"probes on {args.data} ({args.split} split, {what})")
    print(report.table())
    for case, result in report.failures[: max(args.show_failures, 0)]:
        print(f'FAIL {case.clip_id} {case.family}: "{case.caption}" -> {result.describe()}')
    if args.json:
        data = report.to_json()
        data["source"] = what
        write_text(args.json, json.dumps(data, indent=1) + "\n")
        print(f"wrote {args.json}")
    return 0
