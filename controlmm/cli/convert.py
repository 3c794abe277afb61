"""``controlmm convert IN OUT``: convert motions between .npz, HumanML3D .npy and .bvh."""

from __future__ import annotations

import argparse
from pathlib import Path

from controlmm.atomic import check_output_file
from controlmm.cli.args import add_force, add_motion_input, motion_options

HELP = """Convert a motion between formats (chosen by file suffix):
  .npz  this project's Motion file (joints, fps, features, text, metadata)
  .npy  HumanML3D array: (T, 263) features or (T, 22, 3) joints, told apart by shape
  .bvh  SMPL-22 skeleton animation (metres, Y up), importable in Blender

Recorded motion is read too and imported into the HumanML3D motion (metres, Y up, 20 fps,
reference skeleton, features): BVH with LAFAN1, CMU, Mixamo or SMPL joint names (any unit),
SMPL (24), SMPL-H (52) or SMPL-X (55) joint positions in .npy/.npz/.pt (Z or Y up), and any
skeleton through --skeleton-map (docs/motion-formats.md).

Writing .npy stores features (computed with the full HumanML3D processing when the input
has joints only) unless --joints is given. Reading joints from .bvh/.npy keeps them as
they are unless --process is given (HumanML3D processing: 20 fps, reference skeleton,
floor, origin, facing +Z; adds features, drops one frame).

examples:
  controlmm convert new_joint_vecs/012314.npy motion.npz
  controlmm convert motion.npz motion.bvh
  controlmm convert mocap.bvh features.npy
  controlmm convert lafan1_walk.bvh walk.npz
  controlmm convert amass_smplh_joints.npy walk.npz --source-fps 60 --up z"""


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "convert",
        help="convert motions between .npz, .npy (HumanML3D) and .bvh",
        description=HELP,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("input", help="input motion (.npz, .npy, .bvh, .pt)")
    p.add_argument("output", help="output motion (.npz, .npy, .bvh)")
    p.add_argument(
        "--joints", action="store_true", help="write joints (T, 22, 3) instead of features to .npy"
    )
    p.add_argument(
        "--process", action="store_true", help="run the HumanML3D processing on joint input (adds features)"
    )
    add_motion_input(p)
    add_force(p, "OUTPUT")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    # heavy (torch): imported when the command runs, so that --help stays fast
    from controlmm import motion as motions

    motions.check_output_format(Path(args.output))
    check_output_file(args.output, force=args.force)
    motion = motions.load_motion(args.input, **motion_options(args))
    if args.process:
        motion = motion.with_features()
    out = Path(args.output)
    npy_kind = "joints" if args.joints else "features"
    if out.suffix.lower() == ".npy" and npy_kind == "features":
        motion = motion.with_features()
    motions.save_motion(motion, out, npy_kind=npy_kind)
    if out.suffix.lower() == ".npy":
        what = f"HumanML3D {npy_kind}"
    elif out.suffix.lower() == ".bvh":
        what = "SMPL-22 BVH"
    else:
        what = "Motion npz with " + ("features and joints" if motion.features is not None else "joints")
    print(f"wrote {out} ({motion.num_frames} frames, {motion.fps:g} fps, {what})")
    return 0
