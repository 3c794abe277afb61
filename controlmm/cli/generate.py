"""``controlmm generate --text ... --out out.npz``: text to motion with a trained model."""

from __future__ import annotations

import argparse

HELP = """Generate motion from text with the masked motion model (MoMask base: iterative masked decoding
of the base token layer, residual layers, RVQ-VAE decoder).

The output is a Motion .npz: joints (T, 22, 3) metres Y up, features (T, 263), fps (20), text and the
generation settings (seed...). With several --text, outputs are numbered: out_0.npz, out_1.npz, ...

examples:
  controlmm generate --text "a person walks forward and waves" --seconds 6 --seed 0 --out walk.npz
  controlmm generate --text "someone jumps twice" --frames 120 --out jump.npz --plot jump.mp4 --model MODEL_DIR"""


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("generate", help="generate motion from text", description=HELP,
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--text", action="append", required=True, help="prompt (repeat for a batch)")
    length = p.add_mutually_exclusive_group()
    length.add_argument("--seconds", type=float, default=None, help="length in seconds, 2.0..9.8 (default 6)")
    length.add_argument("--frames", type=int, default=None, help="length in frames at 20 fps, 40..196")
    p.add_argument("--seed", type=int, default=None, help="random seed (default: random, stored in the output)")
    p.add_argument("--out", required=True, help="output .npz")
    p.add_argument("--plot", default=None, help="also write a plot/animation (.png, .gif or .mp4)")
    p.add_argument("--model", default=None, help="model directory (default: the embedded default model)")
    p.add_argument("--device", default="cpu", help="cpu, cuda or auto (default cpu)")
    p.add_argument("--cfg-scale", type=float, default=4.0, help="classifier-free guidance, base layer (default 4)")
    p.add_argument("--residual-cfg-scale", type=float, default=5.0, help="guidance of the residual layers (default 5)")
    p.add_argument("--temperature", type=float, default=1.0, help="sampling temperature; 0 = greedy (default 1)")
    p.add_argument("--topk", type=float, default=0.9,
                   help="top-k filter threshold: keep ceil((1 - topk) x 512) logits (default 0.9)")
    p.add_argument("--iterations", type=int, default=10, help="masked-decoding iterations (default 10)")
    p.add_argument("--no-residual", action="store_true", help="decode the base layer only")
    p.add_argument("--residual-layers", type=int, default=None, metavar="N",
                   help="predict only the first N residual layers (default: all)")
    p.add_argument("--clip-weights", default=None, metavar="PATH", help="CLIP weights for CLIP-conditioned models")
    p.add_argument("--threads", type=int, default=None, help="torch CPU threads (default: torch's choice)")
    p.set_defaults(func=run)


def output_paths(out: str, count: int, suffixes: tuple[str, ...]) -> list[str]:
    """``out`` for one prompt; ``stem_i.suffix`` for several."""
    from pathlib import Path

    from controlmm.errors import ControlMMError

    path = Path(out)
    if path.suffix.lower() not in suffixes:
        raise ControlMMError(f"unknown output format '{path.suffix or out}'; allowed: {', '.join(suffixes)}")
    if count == 1:
        return [out]
    return [str(path.with_name(f"{path.stem}_{i}{path.suffix}")) for i in range(count)]


def run(args: argparse.Namespace) -> int:
    from pathlib import Path

    from controlmm.errors import ControlMMError
    from controlmm.generate import DecodeOptions, generate, load_model
    from controlmm.motion import save_motion
    from controlmm.text.base import check_texts

    texts = check_texts(args.text)
    outs = output_paths(args.out, len(texts), (".npz",))
    plots = output_paths(args.plot, len(texts), (".png", ".gif", ".mp4")) if args.plot else []
    for path in outs + plots:
        if not Path(path).parent.is_dir():
            raise ControlMMError(f"cannot write '{path}': directory '{Path(path).parent}' does not exist")
    if args.threads is not None:
        if args.threads < 1:
            raise ControlMMError(f"--threads must be at least 1; got {args.threads}")
        import torch

        torch.set_num_threads(args.threads)
    if args.topk is not None and not 0.0 <= args.topk < 1.0:
        raise ControlMMError(f"--topk must be in [0, 1); got {args.topk}")
    model = load_model(args.model, device=args.device, clip_weights=args.clip_weights)
    options = DecodeOptions(iterations=args.iterations, cfg_scale=args.cfg_scale, temperature=args.temperature,
                            topk=args.topk)
    result = generate(model, texts, seconds=args.seconds, frames=args.frames, seed=args.seed, options=options,
                      use_residual=not args.no_residual, residual_cfg_scale=args.residual_cfg_scale,
                      residual_layers=args.residual_layers)
    for i, motion in enumerate(result.motions):
        save_motion(motion, outs[i])
        print(f"wrote {outs[i]} ({motion.num_frames} frames, {motion.seconds:.1f} s, seed {result.seed}): "
              f"'{motion.text}'")
        if plots:
            from controlmm.motion.plot import plot_or_animate

            plot_or_animate(motion, plots[i])
            print(f"wrote {plots[i]}")
    return 0
