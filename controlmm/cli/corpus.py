"""``controlmm corpus --out DIR --clips N --seed S``: the procedural motion corpus."""

from __future__ import annotations

import argparse

from controlmm.atomic import check_output_dir
from controlmm.cli.args import add_force, integer, seed
from controlmm.errors import ControlMMError

HELP = """Generate the procedural motion corpus in HumanML3D format: kinematically planned
human motion (foot placement + two-bone IK on the HumanML3D skeleton, 20 fps, 2-9.8 s) of
49 families (walk, jog, run, walk backwards, sidestep, turns, circles, curves, zigzag,
stop and go, walk to a point, jumps, squat, crouch-walk, kneel, waves, raised arms, reaches,
punches, claps; sit down on a seat, lie down, bow, pick up from the floor, kick, stretch the
arms out, push, look around, point, carry; step over an obstacle, step onto or off a
platform, stairs up or down; and compositions with a walk), each clip with >= 3 captions
whose words match it. Families with objects (seat, platform, stairs, obstacle) record them
as boxes in meta/<id>.json ("scene").

Writes DIR/new_joint_vecs, new_joints, texts, train/val/test/all.txt, Mean.npy, Std.npy,
plus meta/<id>.json (family, parameters, captions with their claims) and corpus.json.
Test-split captions use held-out phrasings. The output is the same for a given seed and
clip count, whatever the number of workers; DIR appears only when complete. DIR may be
new, empty or a previous corpus; anything else needs --force.

examples:
  controlmm corpus --out corpus --clips 5000 --seed 0
  controlmm corpus --out waves --clips 100 --families wave_left,wave_right
  controlmm corpus --list"""


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "corpus",
        help="generate the procedural motion corpus (HumanML3D format)",
        description=HELP,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("--out", help="output dataset directory")
    p.add_argument(
        "--clips", type=integer(1), default=9800, help="number of clips (default 9800, the default corpus)"
    )
    p.add_argument("--seed", type=seed, default=0, help="corpus seed (default 0)")
    p.add_argument(
        "--workers", type=integer(0), default=0, help="worker processes (default 0: all CPU cores)"
    )
    p.add_argument("--families", default=None, help="comma-separated family names (default: all; see --list)")
    p.add_argument("--captions", type=int, default=3, help="captions per clip (>= 3, default 3)")
    p.add_argument("--list", action="store_true", help="list the motion families and exit")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    add_force(p, "--out whatever it holds (never a regular file)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    # heavy (torch): imported when the command runs, so that --help stays fast
    from controlmm.corpus import CorpusConfig, family_names, get_family, write_corpus

    if args.list:
        for name in family_names():
            print(f"{name:16s} {get_family(name).group}")
        return 0
    if not args.out:
        raise ControlMMError("--out is required (the dataset directory to write)")
    families = None
    if args.families is not None:
        families = tuple(f.strip() for f in args.families.split(",") if f.strip())
        if not families:
            raise ControlMMError(f"--families names no family; known families: {', '.join(family_names())}")
        for name in families:
            get_family(name)  # an unknown name: one line listing the known ones
    check_output_dir(args.out, kind="corpus", force=args.force)
    config = CorpusConfig(clips=args.clips, seed=args.seed, families=families, captions=args.captions)
    summary = write_corpus(args.out, config, workers=args.workers, progress=not args.quiet, force=args.force)
    splits = ", ".join(f"{k} {v}" for k, v in summary["splits"].items())
    print(
        f"wrote {args.out}: {summary['clips']} clips ({splits}), {summary['frames']} frames, "
        f"{len(summary['families'])} families, {summary['seconds']:.1f} s on {summary['workers']} worker(s)"
    )
    return 0
