"""``controlmm eval quality``: the paper's text-to-motion quality table (FID, R-precision, ...)."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from controlmm.atomic import check_output_file, write_text
from controlmm.cli.args import add_force, add_threads, integer, seed
from controlmm.errors import ControlMMError

HELP = """Evaluate text-to-motion quality as the paper does: R-precision top-1/2/3 (groups of 32), FID,
MM-Dist, Diversity (300 pairs) and Multimodality, measured by a text-motion evaluator, over REPEATS
evaluation passes of a split (random caption, length and crop per sample), reported as mean and 95%
confidence interval (1.96 std / sqrt(REPEATS)). The "Real" row measures the ground truth itself (its
FID is between two independent passes).

--evaluator: the shipped evaluator (trained on the default corpus) by default; a directory written by
'controlmm train evaluator'; or the official HumanML3D evaluator (a MoMask checkout, its checkpoints/
or checkpoints/t2m folder with text_mot_match/, Comp_v6_KLD005/meta/ and glove/ beside it).

examples:
  controlmm eval quality --data data/corpus-default --repeats 10
  controlmm eval quality --model MODEL_DIR --data DIR --split test --repeats 3 --json quality.json
  controlmm eval quality --model A --model B --data DIR          (one row per model)
  controlmm eval quality --real-only --data HumanML3D/ --evaluator momask-codes/"""


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "quality",
        help="FID, R-precision, MM-Dist, Diversity, Multimodality with CIs",
        description=HELP,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument(
        "--model",
        action="append",
        default=None,
        metavar="MODEL_DIR",
        help="model directory to evaluate (repeatable: one row each; default: the embedded model)",
    )
    p.add_argument(
        "--data", required=True, help="HumanML3D-format directory (the real dataset or the corpus)"
    )
    p.add_argument(
        "--split", default="test", choices=("train", "val", "test"), help="split to evaluate (default test)"
    )
    p.add_argument(
        "--repeats", type=integer(1), default=10, help="evaluation passes (default 10, as the paper)"
    )
    p.add_argument(
        "--evaluator", default=None, metavar="E", help="evaluator directory (default: the shipped one)"
    )
    p.add_argument(
        "--limit",
        type=integer(2),
        default=None,
        metavar="N",
        help="at most N samples per pass, whole groups of 32 (default: the whole split)",
    )
    p.add_argument(
        "--mm-texts",
        type=integer(0),
        default=32,
        help="captions for Multimodality per pass (default 32; paper 100; 0 = skip)",
    )
    p.add_argument(
        "--mm-repeats",
        type=integer(1),
        default=12,
        help="generations per caption for Multimodality (default 12; paper 30)",
    )
    p.add_argument(
        "--mm-pairs", type=integer(1), default=10, help="pairs per caption for Multimodality (default 10)"
    )
    p.add_argument("--real-only", action="store_true", help="only the Real row (no model needed)")
    p.add_argument("--seed", type=seed, default=0, help="seed of pass r is SEED + r (default 0)")
    p.add_argument(
        "--batch-size", type=integer(1), default=64, help="prompts generated together (default 64)"
    )
    p.add_argument("--device", default="cpu", help="cpu or cuda (default cpu)")
    add_threads(p, None)
    p.add_argument("--json", default=None, help="also write every per-pass value to this JSON file")
    add_force(p, "--json")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    # heavy (torch, the models): imported when the command runs, so that --help stays fast
    import torch

    from controlmm import generate as generation
    from controlmm.eval import evaluator as evaluators, quality

    if args.json:
        check_output_file(args.json, force=args.force)
    if args.threads is not None:
        torch.set_num_threads(args.threads)
    if args.real_only and args.model:
        raise ControlMMError("--real-only evaluates no model; drop --model or --real-only")
    carried = evaluators.model_evaluator(args.model)
    if args.evaluator is None and carried:  # e.g. the official one, from import-official
        args.evaluator = carried
        print(f"evaluator: {args.evaluator} (carried by the model directory)", file=sys.stderr)
    evaluator = evaluators.load_evaluator(args.evaluator, device=args.device)
    evalset = quality.EvalSet.load(args.data, args.split, progress=not args.quiet)
    generators = {}
    if not args.real_only:
        for path in args.model or [None]:
            model = generation.load_model(path, device=args.device)
            name = Path(model.directory).name if model.directory else "model"
            while name in generators or name == "Real":
                name += "'"
            generators[name] = quality.model_generator(model, batch_size=args.batch_size)
    unknown = getattr(evaluator, "unknown_word_share", None)
    if unknown is not None:
        share = unknown([c.text for caps in evalset.captions for c in caps])
        if share > 0.5:
            print(
                f"warning: {100 * share:.0f}% of the caption words are unknown to the evaluator "
                f"({evaluator.name}); train one on this data: controlmm train evaluator --data {args.data}"
            )
    report = quality.evaluate_quality(
        evaluator,
        evalset,
        generators,
        repeats=args.repeats,
        seed=args.seed,
        limit=args.limit,
        mm_texts=args.mm_texts,
        mm_repeats=args.mm_repeats,
        mm_times=args.mm_pairs,
        progress=not args.quiet,
    )
    print(
        f"quality on {args.data} ({args.split} split, {report.samples} samples per pass, "
        f"{args.repeats} passes; "
        f"evaluator: {evaluator.name}; mean ± 95% CI)"
    )
    print(report.table())
    if args.json:
        write_text(args.json, json.dumps(report.to_json(), indent=1) + "\n")
        print(f"wrote {args.json}")
    return 0
