"""``controlmm generate --text ... --out out.npz``: text to motion with a trained model."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import TYPE_CHECKING

from controlmm.atomic import check_output_file
from controlmm.cli.args import add_force, add_threads, integer, number, positive, seed
from controlmm.errors import ControlMMError

if TYPE_CHECKING:
    from controlmm.control import ControlSpec
    from controlmm.generate import DecodeOptions, MotionModel

HELP = """Generate motion from text with the masked motion model (MoMask base: iterative masked decoding
of the base token layer, residual layers, RVQ-VAE decoder), optionally under spatial control
(ControlMM: any joint at any frame; see the README's "Spatial control" for the spec format).

The output is a Motion .npz: joints (T, 22, 3) metres Y up, features (T, 263), fps (20), text and the
generation settings (seed...). With several --text, outputs are numbered: out_0.npz, out_1.npz, ...

With --control SPEC.json the motion control model and inference-time editing meet the constraints;
the error of every constraint is printed (cm) and stored in the .npz (metadata "control": spec,
per-constraint errors, editing steps; arrays control_mask, control_targets, control_errors).
Presets (--preset): fast = control model + up to 100 codebook-editing steps; medium = up to 600;
accurate (default) = also up to 100 logits-editing steps in each of the 10 decoding iterations.
Editing stops as soon as every constraint is within --tolerance (1 cm).

examples:
  controlmm generate --text "a person walks forward and waves" --seconds 6 --seed 0 --out walk.npz
  controlmm generate --text "someone jumps twice" --frames 120 --out jump.npz --plot jump.mp4 \
      --model MODEL_DIR
  controlmm generate --text "a person walks forward" --control spec.json --preset accurate --out walk.npz"""


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "generate",
        help="generate motion from text",
        description=HELP,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("--text", action="append", required=True, help="prompt (repeat for a batch)")
    length = p.add_mutually_exclusive_group()
    length.add_argument("--seconds", type=float, default=None, help="length in seconds, 2.0..9.8 (default 6)")
    length.add_argument("--frames", type=int, default=None, help="length in frames at 20 fps, 40..196")
    p.add_argument(
        "--seed",
        type=seed,
        default=None,
        help="random seed, 0 to 2^63 - 1 (default: random, stored in the output)",
    )
    p.add_argument("--out", required=True, help="output .npz")
    add_force(p, "--out and --plot files")
    p.add_argument("--plot", default=None, help="also write a plot/animation (.png, .gif or .mp4)")
    p.add_argument("--model", default=None, help="model directory (default: the embedded default model)")
    p.add_argument("--device", default="cpu", help="cpu, cuda or auto (default cpu)")
    p.add_argument(
        "--cfg-scale", type=float, default=4.0, help="classifier-free guidance, base layer (default 4)"
    )
    p.add_argument(
        "--residual-cfg-scale", type=float, default=5.0, help="guidance of the residual layers (default 5)"
    )
    p.add_argument(
        "--temperature", type=float, default=1.0, help="sampling temperature; 0 = greedy (default 1)"
    )
    p.add_argument(
        "--topk",
        type=number(0.0, below=1.0),
        default=0.9,
        help="top-k filter threshold: keep ceil((1 - topk) x 512) logits (default 0.9)",
    )
    p.add_argument(
        "--iterations", type=integer(1), default=10, help="masked-decoding iterations (default 10)"
    )
    p.add_argument("--no-residual", action="store_true", help="decode the base layer only")
    p.add_argument(
        "--residual-layers",
        type=int,
        default=None,
        metavar="N",
        help="predict only the first N residual layers (default: all)",
    )
    p.add_argument(
        "--no-token-view",
        action="store_true",
        help="decode with the sentence-vector transformer alone (default: when the model has a "
        "token-state transformer, both text views are mixed; not used with --control)",
    )
    p.add_argument(
        "--clip-weights", default=None, metavar="PATH", help="CLIP weights for CLIP-conditioned models"
    )
    ctrl = p.add_argument_group("spatial control")
    ctrl.add_argument(
        "--control",
        default=None,
        metavar="SPEC.json",
        help="control spec: joints at frames at positions (JSON; see README 'Spatial control')",
    )
    ctrl.add_argument(
        "--preset",
        default=None,
        choices=("fast", "medium", "accurate"),
        help="control/editing preset (default accurate)",
    )
    ctrl.add_argument(
        "--tolerance",
        type=positive,
        default=None,
        metavar="CM",
        help="stop editing when every constraint is this close, in cm (default 1)",
    )
    ctrl.add_argument(
        "--logits-steps",
        type=int,
        default=None,
        metavar="N",
        help="logits-editing steps per decoding iteration (default: the preset's)",
    )
    ctrl.add_argument(
        "--codebook-steps",
        type=int,
        default=None,
        metavar="N",
        help="codebook-editing steps (default: the preset's)",
    )
    ctrl.add_argument(
        "--contact-steps",
        type=int,
        default=None,
        metavar="N",
        help="after codebook editing, up to N more steps that stop planted feet sliding, kept only "
        "where every constraint stays met (default: the preset's, 200 for accurate, else 0)",
    )
    ctrl.add_argument(
        "--no-control-model", action="store_true", help="do not use the motion control model (editing only)"
    )
    add_threads(p, None)
    p.set_defaults(func=run)


def output_paths(out: str, count: int, suffixes: tuple[str, ...], force: bool) -> list[str]:
    """``out`` for one prompt; ``stem_i.suffix`` for several; each checked writable (and new
    unless ``force``)."""
    path = Path(out)
    if path.suffix.lower() not in suffixes:
        raise ControlMMError(f"unknown output format '{path.suffix or out}'; allowed: {', '.join(suffixes)}")
    outs = (
        [out] if count == 1 else [str(path.with_name(f"{path.stem}_{i}{path.suffix}")) for i in range(count)]
    )
    for name in outs:
        check_output_file(name, force=force)
    return outs


def run(args: argparse.Namespace) -> int:
    # heavy (torch, the models): imported when the command runs, so that --help stays fast
    import torch

    from controlmm import control, generate as generation, motion, text

    texts = text.check_texts(args.text)
    outs = output_paths(args.out, len(texts), (".npz",), args.force)
    plots = output_paths(args.plot, len(texts), (".png", ".gif", ".mp4"), args.force) if args.plot else []
    if args.threads is not None:
        torch.set_num_threads(args.threads)
    spec = None
    if args.control is not None:
        spec = control.ControlSpec.load(args.control)
        if not spec.constraints:
            raise ControlMMError(f"control spec '{args.control}' has no constraints")
        for warning in spec.pinned_frame0_warnings() + sum(control.reach_warnings(spec), []):
            print(f"controlmm: warning: {warning}", file=sys.stderr)
    else:
        for flag, value in (
            ("--preset", args.preset),
            ("--tolerance", args.tolerance),
            ("--logits-steps", args.logits_steps),
            ("--codebook-steps", args.codebook_steps),
            ("--contact-steps", args.contact_steps),
        ):
            if value is not None:
                raise ControlMMError(f"{flag} needs --control SPEC.json")
    model = generation.load_model(args.model, device=args.device, clip_weights=args.clip_weights)
    options = generation.DecodeOptions(
        iterations=args.iterations, cfg_scale=args.cfg_scale, temperature=args.temperature, topk=args.topk
    )
    if spec is not None:
        return _run_controlled(args, model, texts, spec, options, outs, plots)
    result = generation.generate(
        model,
        texts,
        seconds=args.seconds,
        frames=args.frames,
        seed=args.seed,
        options=options,
        use_residual=not args.no_residual,
        residual_cfg_scale=args.residual_cfg_scale,
        residual_layers=args.residual_layers,
        token_view=not args.no_token_view,
    )
    for i, clip in enumerate(result.motions):
        motion.save_motion(clip, outs[i])
        print(
            f"wrote {outs[i]} ({clip.num_frames} frames, {clip.seconds:.1f} s, seed {result.seed}): "
            f"'{clip.text}'"
        )
        if plots:
            motion.plot_or_animate(clip, plots[i])
            print(f"wrote {plots[i]}")
    return 0


def _run_controlled(
    args: argparse.Namespace,
    model: MotionModel,
    texts: list[str],
    spec: ControlSpec,
    options: DecodeOptions,
    outs: list[str],
    plots: list[str],
) -> int:
    """``generate --control``: ControlMM generation, per-constraint errors printed and stored."""
    # heavy (torch): imported when the command runs, so that --help stays fast
    from controlmm import editing, generate as generation, motion

    preset = args.preset or "accurate"
    config = editing.editing_preset(preset).with_overrides(
        tolerance=None if args.tolerance is None else args.tolerance / 100.0,
        logits_steps=args.logits_steps,
        codebook_steps=args.codebook_steps,
        contact_steps=args.contact_steps,
        control_model=False if args.no_control_model else None,
    )
    if config.control_model and "control" not in model.parts:
        print(
            f"controlmm: warning: model '{model.directory}' has no motion control model (control.pt); "
            "using inference-time editing only",
            file=sys.stderr,
        )
    result = generation.generate_controlled(
        model,
        texts,
        control=spec,
        preset=config,
        seconds=args.seconds,
        frames=args.frames,
        seed=args.seed,
        options=options,
        residual_cfg_scale=args.residual_cfg_scale,
    )
    tolerance_cm = 100.0 * config.tolerance
    for i, clip in enumerate(result.motions):
        record = result.records[i]
        motion.save_motion(clip, outs[i])
        errors = 100.0 * result.errors[i]
        print(
            f"wrote {outs[i]} ({clip.num_frames} frames, {clip.seconds:.1f} s, seed {result.seed}): "
            f"'{clip.text}'"
        )
        steps = (
            f"logits editing {sum(record.logits_steps)} steps" if record.logits_steps else "no logits editing"
        )
        print(
            f"control ({preset}{', control model' if record.control_model else ', no control model'}): "
            f"{steps}, codebook editing {record.codebook_steps} steps, {record.seconds:.1f} s"
        )
        width = max(len(spec.constraints[k].joint_name) for k in range(len(errors)))
        for c, e in zip(spec.constraints, errors, strict=True):
            flag = "" if e <= tolerance_cm else f"  (over {tolerance_cm:g} cm)"
            print(f"  {c.joint_name:<{width}}  frame {c.frame:>3}  error {e:6.2f} cm{flag}")
        over = int((errors > tolerance_cm).sum())
        print(
            f"  max {errors.max():.2f} cm, mean {errors.mean():.2f} cm; "
            + (
                f"all {len(errors)} constraints within {tolerance_cm:g} cm"
                if not over
                else f"{over} of {len(errors)} constraints over {tolerance_cm:g} cm"
            )
        )
        if plots:
            motion.plot_or_animate(clip, plots[i])
            print(f"wrote {plots[i]}")
    return 0
