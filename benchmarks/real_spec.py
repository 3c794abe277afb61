"""A multi-joint spec taken from the real HumanML3D clip 012314, met by a model with editing.

    python benchmarks/real_spec.py                          # embedded default, preset accurate, seed 0
    python benchmarks/real_spec.py --model MODEL_DIR --preset medium --seeds 3

The spec (85 constraints on 5 joints of the clip's own joints, 170 frames): a 60-frame pelvis trajectory
(frames 0-59), a 20-frame left-wrist range (frames 120-139) and sparse keyframes of the right wrist
(frames 80, 150), the left foot (frames 100, 160) and the head (frame 169, the last). The sample ships
without its captions, so the prompt is ``--text``. Prints, per seed, the error of the constraints
(max / mean, cm), how many are within 1 cm, the editing steps and the seconds.
"""

from __future__ import annotations

import argparse
import sys
import time

import numpy as np
from data_dirs import REAL_CLIP, real_clip


def real_spec(joints: np.ndarray) -> dict:
    """The spec of this benchmark from the clip's joints (T >= 170, 22, 3), human frame, metres."""

    def key(name: str, index: int, frame: int) -> dict:
        return {"joint": name, "frame": frame, "position": joints[frame, index].tolist()}

    return {
        "coords": "human",
        "constraints": [
            {"joint": "pelvis", "frame_range": [0, 59], "positions": joints[0:60, 0].tolist()},
            {"joint": "left_wrist", "frame_range": [120, 139], "positions": joints[120:140, 20].tolist()},
            key("right_wrist", 21, 80),
            key("right_wrist", 21, 150),
            key("left_foot", 10, 100),
            key("left_foot", 10, 160),
            key("head", 15, 169),
        ],
    }


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--model", default=None, help="model directory (default: the embedded default)")
    parser.add_argument("--preset", default="accurate")
    parser.add_argument("--text", default="a person walks forward and turns around")
    parser.add_argument("--seeds", type=int, default=1, help="seeds 0..N-1 (default 1)")
    parser.add_argument("--threads", type=int, default=1)
    args = parser.parse_args(argv)

    import torch

    from controlmm.control import ControlSpec
    from controlmm.generate import generate_controlled, load_model
    from controlmm.motion.recover import features_to_joints_np

    torch.set_num_threads(args.threads)
    joints = features_to_joints_np(np.load(real_clip()))
    text = args.text
    spec = ControlSpec.from_dict(real_spec(joints))
    model = load_model(args.model)
    print(
        f"real spec: clip {REAL_CLIP}, {len(joints)} frames, prompt '{text}', preset {args.preset}, "
        f"{args.threads} thread(s)"
    )
    print(
        "| seed | constraints | max err (cm) | mean err (cm) | within 1 cm | logits steps "
        "| codebook steps | s |"
    )
    print("|---|---|---|---|---|---|---|---|")
    for seed in range(args.seeds):
        start = time.perf_counter()
        out = generate_controlled(
            model, text, control=spec, frames=len(joints), preset=args.preset, seed=seed
        )
        seconds = time.perf_counter() - start
        err = np.asarray(out.errors[0]) * 100
        rec = out.records[0]
        print(
            f"| {seed} | {len(err)} | {err.max():.2f} | {err.mean():.2f} | "
            f"{int((err <= 1.0 + 1e-6).sum())} | "
            f"{sum(rec.logits_steps)} | {rec.codebook_steps} | {seconds:.1f} |"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
