"""``controlmm timeline spec.json --out out.npz``: body-part timeline control (paper appendix A.9)."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from controlmm.atomic import check_output_file, write_text
from controlmm.cli.args import add_force, add_threads, integer, seed
from controlmm.errors import ControlMMError

HELP = """Generate one motion from a timeline of body-part tracks: each track gives a body part (legs, torso,
head, left_arm, right_arm, whole_body), a prompt and a start and end in seconds; tracks may overlap
(later tracks win). The whole body is generated first (from "base", default the first track's prompt),
then every track regenerates its part over its span while everything else is held as dense spatial
control (codebook editing) and the span edges are blended. See docs/timeline.md.

spec.json:
  {"seconds": 6, "base": "a person stands still",
   "tracks": [{"part": "legs", "prompt": "a person walks forward", "start": 0, "end": 6},
              {"part": "right_arm", "prompt": "a person waves the right hand", "start": 2, "end": 4}]}

Printed and stored (metadata "timeline", and --report JSON): per track the largest drift (cm) of the
entries it fixed, the fastest joint (m/s) at its span edges and, when a track names a "probe"
({"family": ..., "claims": {...}}), whether its span passes it.

examples:
  controlmm timeline spec.json --out out.npz --seed 0
  controlmm timeline spec.json --out out.npz --plot out.mp4 --report out.json --model MODEL_DIR"""


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "timeline",
        help="body-part timeline control: several prompts, each for a part and a span",
        description=HELP,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("spec", help="timeline spec (JSON)")
    p.add_argument("--out", required=True, help="output motion .npz")
    p.add_argument("--plot", default=None, help="also write a plot/animation (.png, .gif or .mp4)")
    p.add_argument("--report", default=None, help="also write the report as JSON")
    p.add_argument("--model", default=None, help="model directory (default: the embedded default model)")
    p.add_argument("--device", default="cpu", help="cpu, cuda or auto (default cpu)")
    p.add_argument(
        "--seed",
        type=seed,
        default=None,
        help="random seed, 0 to 2^63 - 1 (default: random, stored in the output)",
    )
    p.add_argument(
        "--preset",
        default="accurate",
        choices=("fast", "medium", "accurate"),
        help="editing preset; its codebook-editing budget per pass: fast 100 + 200 settle steps per try, "
        "medium and accurate (default) 600 + 1200",
    )
    p.add_argument(
        "--codebook-steps",
        type=integer(0),
        default=None,
        metavar="N",
        help="codebook-editing steps per pass (default: the preset's)",
    )
    p.add_argument(
        "--settle-steps",
        type=integer(0),
        default=None,
        metavar="N",
        help="steps of each pass's second editing run, per try (default 2x codebook steps)",
    )
    p.add_argument(
        "--blend-frames",
        type=integer(0),
        default=10,
        metavar="N",
        help="frames blended at each interior span edge (default 10)",
    )
    add_threads(p, None)
    add_force(p, "--out, --plot and --report files")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    # heavy (torch, the models): imported when the command runs, so that --help stays fast
    import torch

    from controlmm import editing, generate as generation, motion, timeline as timelines

    out = Path(args.out)
    if out.suffix.lower() != ".npz":
        raise ControlMMError(f"--out must be a .npz file; got '{args.out}'")
    if args.plot and Path(args.plot).suffix.lower() not in (".png", ".gif", ".mp4"):
        raise ControlMMError(f"--plot must end in .png, .gif or .mp4; got '{args.plot}'")
    for path in filter(None, (args.out, args.plot, args.report)):
        check_output_file(path, force=args.force)
    timeline = timelines.Timeline.load(args.spec)  # validate before loading the model
    if args.threads is not None:
        torch.set_num_threads(args.threads)

    config = editing.editing_preset(args.preset).with_overrides(codebook_steps=args.codebook_steps)
    model = generation.load_model(args.model, device=args.device)
    clip, report = timelines.generate_timeline(
        model,
        timeline,
        seed=args.seed,
        preset=config,
        blend_frames=args.blend_frames,
        settle_steps=args.settle_steps,
        progress=True,
    )
    motion.save_motion(clip, args.out)
    print(
        f"wrote {args.out} ({clip.num_frames} frames, {clip.seconds:.1f} s, seed {report['seed']}, "
        f"{report['wall_seconds']:.1f} s)"
    )
    for t in report["tracks"]:
        edges = (
            ", ".join(f"{k} {v:.2f} m/s" for k, v in t["boundary_speed_mps"].items()) or "no interior edges"
        )
        probe = ""
        if "probe" in t:
            probe = f"; probe {t['probe']['family']}: {'pass' if t['probe']['passed'] else 'FAIL'}"
        print(
            f"  track {t['track']} {t['part']} {t['frames'][0]}..{t['frames'][1]}: '{t['prompt']}': "
            f"fixed entries drift {t['final_drift_cm']:.2f} cm; edges {edges}{probe}"
        )
    print(
        f"  max drift {report['max_drift_cm']:.2f} cm, "
        f"max boundary speed {report['max_boundary_speed_mps']:.2f} m/s"
    )
    if args.report:
        write_text(args.report, json.dumps(report, indent=2) + "\n")
        print(f"wrote {args.report}")
    if args.plot:
        motion.plot_or_animate(clip, args.plot)
        print(f"wrote {args.plot}")
    return 0
