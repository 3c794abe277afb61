"""``controlmm eval probes --data DIR``: text-adherence probes per motion family."""

from __future__ import annotations

import argparse

HELP = """Check that motions do what their captions say, family by family, with simple geometry
in the person's frame (e.g. "walks backwards": the pelvis moves against the facing
direction; "waves right hand": the right wrist is above the head and swings side to side;
"circle counter-clockwise": the heading turns >= 300 degrees to the left; "jumps twice":
two flight phases). Every caption's claims (direction, speed, hand, count, angle...) come
from the corpus' meta/<id>.json. Prints the pass rate per family.

--data DIR checks the corpus' own motions (ground truth: 100% expected).

examples:
  controlmm eval probes --data corpus
  controlmm eval probes --data corpus --split all --json probes.json"""


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("probes", help="text-adherence probes per motion family",
                       description=HELP, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--data", required=True, help="corpus directory (HumanML3D format with meta/)")
    p.add_argument("--split", default="test", choices=("train", "val", "test", "all"),
                   help="which split's captions to check (default test)")
    p.add_argument("--json", default=None, help="also write the report (with failed checks) to this JSON file")
    p.add_argument("--show-failures", type=int, default=10, help="print up to N failed captions (default 10)")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    import json

    from controlmm.atomic import write_text
    from controlmm.errors import ControlMMError
    from controlmm.eval.probes import evaluate, ground_truth, list_cases

    cases = list_cases(args.data, args.split)
    if not cases:
        raise ControlMMError(f"the {args.split} split of '{args.data}' has no captions to check")
    report = evaluate(cases, ground_truth(args.data), split=args.split, per_clip=True, progress=not args.quiet)
    print(f"probes on {args.data} ({args.split} split, ground truth)")
    print(report.table())
    for case, result in report.failures[: max(args.show_failures, 0)]:
        print(f"FAIL {case.clip_id} {case.family}: \"{case.caption}\" -> {result.describe()}")
    if args.json:
        write_text(args.json, json.dumps(report.to_json(), indent=1) + "\n")
        print(f"wrote {args.json}")
    return 0
