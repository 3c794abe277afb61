"""``controlmm import-official``: the official MoMask / MaskControl checkpoints as a model directory."""

from __future__ import annotations

import argparse

HELP = """Convert the official pretrained checkpoints (MoMask RVQ-VAE, masked and residual transformers;
a MaskControl motion control model; optionally the HumanML3D text-motion evaluator) into a controlmm
model directory of the 'paper' preset, so that 'controlmm generate --model MODEL_DIR' uses them.
Nothing is downloaded: get the folders with the official repositories' download scripts first (see the
README section "Official pretrained weights").

--momask: the MoMask checkout root, its checkpoints/ or checkpoints/t2m, holding
  rvq_nq6_dc512_nc512_noshare_qdp0.2, t2m_nlayer8_nhead6_ld384_ff1024_cdp0.1_rvq6ns and
  tres_nlayer8_ld384_ff1024_rvq6ns_cdp0.2_sw (model/*.tar, opt.txt, the VQ's meta/mean.npy, std.npy).
--control: one MaskControl run folder (model/latest.tar), e.g.
  z2024-08-27-21-07-55_CtrlNet_randCond1-196_l1.5XEnt.5TTT__cross (all joints) or
  z2024-08-23-01-27-51_CtrlNet_randCond1-196_l1.1XEnt.9TTT__fixRandCond (pelvis only).
  Its embedded RVQ-VAE and base transformer are used, as the official control scripts do.
--evaluator: a folder holding text_mot_match/model/finest.tar, Comp_v6_KLD005/meta and glove/
  (MoMask's download_evaluator.sh + download_glove.sh); the files are copied to MODEL_DIR/evaluator.

Every tensor is loaded strictly (all official tensors used, all of ours filled, equal shapes). Text is
encoded with CLIP ViT-B/32 as the official code does (projected end-of-text token, not normalised,
float16 by default); its weights must be on disk: --clip-weights or the Hugging Face cache.

example:
  controlmm import-official --momask momask-codes/checkpoints/t2m \\
      --control MaskControl/checkpoints/t2m/z2024-08-27-21-07-55_CtrlNet_randCond1-196_l1.5XEnt.5TTT__cross \\
      --evaluator momask-codes/checkpoints/t2m --out models/official"""


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "import-official",
        help="import the official MoMask/MaskControl checkpoints",
        description=HELP,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument(
        "--momask", required=True, metavar="DIR", help="folder with the three MoMask model folders"
    )
    p.add_argument("--control", default=None, metavar="DIR", help="a MaskControl run folder (optional)")
    p.add_argument(
        "--evaluator", default=None, metavar="DIR", help="folder with the HumanML3D evaluator (optional)"
    )
    p.add_argument("--out", required=True, metavar="MODEL_DIR", help="model directory to write")
    p.add_argument(
        "--clip-weights",
        default=None,
        metavar="PATH",
        help="CLIP ViT-B/32 weights recorded in model.json (a transformers save_pretrained folder or a "
        "model id in the local cache; default openai/clip-vit-base-patch32)",
    )
    p.add_argument(
        "--clip-precision",
        default="float16",
        choices=("float16", "float32"),
        help="precision of the CLIP text features (official: float16)",
    )
    p.add_argument("--force", action="store_true", help="replace MODEL_DIR if it exists")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from controlmm.models.official import import_official

    out = import_official(
        args.momask,
        args.out,
        control=args.control,
        evaluator=args.evaluator,
        clip_weights=args.clip_weights,
        clip_precision=args.clip_precision,
        force=args.force,
        log=print,
    )
    print(f"wrote {out} (use it with: controlmm generate --model {out} ...)")
    return 0
