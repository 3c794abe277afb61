"""Gait timing of generated walks: do a model's walks move their feet like people?

    python benchmarks/gait.py --model controlmm/checkpoints/default --seeds 5
    python benchmarks/gait.py --model MODEL_DIR --corpus data/corpus-default   # + the corpus' walks

For every walking prompt and seed: ``generate(model, prompt, frames=160, seed=s)`` (text only) and
the legs track of the timeline benchmark's walk + wave spec (``benchmarks/timeline.py``, seed s; its
own legs prompt and a slow walk's), measured with the corpus statistics' ``timing`` (pelvis cruise
speed, cadence, fastest toe joint, 20 fps frame differences) and the fastest joint of all. The summary
keeps the walks of about 1 m/s (cruise speed 0.8-1.25 m/s), where gait data put the swing foot's peak
at about 3.5-4 m/s (docs/corpus.md, "Timing and balance"); the target for generated and timeline walks
there is a peak joint speed below 6 m/s.
Runs single-threaded (torch and BLAS) so figures are stable on a shared machine.
"""

from __future__ import annotations

import argparse
import os
import sys

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("HF_HUB_OFFLINE", "1")

import copy  # noqa: E402
import json  # noqa: E402

import numpy as np  # noqa: E402
import torch  # noqa: E402
from corpus_stats import timing  # noqa: E402
from data_dirs import corpus_dir  # noqa: E402
from timeline import SPECS  # noqa: E402

from controlmm.motion.skeleton import FPS  # noqa: E402

PROMPTS = (
    "a person walks forward",
    "a person walks forward at a normal pace",
    "someone walks straight ahead slowly",
    "a man is walking forward",
    "the person strolls ahead",
)
"""Walking prompts: the corpus' wording and paraphrases of it."""

TIMELINE_LEGS = ("a person walks forward", "a person walks forward slowly")
"""Legs-track prompts of the timeline walks: the timeline benchmark's own (the 32-family default walks it
at 1.4-1.5 m/s) and a slow walk, so that a walk of about 1 m/s is among them."""

ONE_MPS = (0.8, 1.25)
"""Cruise speeds (m/s) counted as a walk of about 1 m/s."""


def peak_joint_speed(joints: np.ndarray) -> float:
    """The fastest frame-to-frame speed (m/s) of any joint."""
    return float((np.linalg.norm(np.diff(joints, axis=0), axis=-1) * FPS).max())


def measure(joints: np.ndarray) -> dict[str, float]:
    """Timing figures of one walk (joints (T, 22, 3)) plus its fastest joint."""
    j = np.asarray(joints, dtype=np.float64)
    return {**timing(j), "joint_peak": peak_joint_speed(j)}


def corpus_walks(corpus: str | None) -> list[dict[str, float]]:
    """The same figures for the ``walk`` clips of a corpus' test split."""
    root = corpus_dir(corpus, "--corpus")
    out = []
    for clip_id in (root / "test.txt").read_text().split():
        meta = json.loads((root / "meta" / f"{clip_id}.json").read_text())
        if meta["family"] == "walk":
            out.append(measure(np.load(root / "new_joints" / f"{clip_id}.npy")))
    return out


def summary(rows: list[dict[str, float]]) -> str:
    near = [r for r in rows if ONE_MPS[0] <= r["speed"] <= ONE_MPS[1]]
    if not near:
        speed = np.array([r["speed"] for r in rows])
        joint = np.array([r["joint_peak"] for r in rows])
        return (
            f"no walk of about 1 m/s ({len(rows)} walks at {speed.min():.2f}-{speed.max():.2f} m/s: "
            f"peak joint speed mean {joint.mean():.2f}, max {joint.max():.2f} m/s)"
            if rows
            else "no walk"
        )
    joint = np.array([r["joint_peak"] for r in near])
    toe = np.array([r["foot_peak"] for r in near])
    cad = np.array([r["cadence"] for r in near])
    below = int((joint < 6.0).sum())
    head = f"{len(near)} of {len(rows)} walks at {ONE_MPS[0]}-{ONE_MPS[1]} m/s"
    peaks = f"peak joint speed mean {joint.mean():.2f}, max {joint.max():.2f} m/s ({below} below 6 m/s)"
    feet = f"swing-foot peak mean {toe.mean():.2f} m/s; cadence median {np.nanmedian(cad):.0f} steps/min"
    return f"{head}: {peaks}; {feet}"


def main() -> int:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--model", required=True, help="trained model directory")
    parser.add_argument("--seeds", type=int, default=5, help="seeds 0..N-1 per prompt (default 5)")
    parser.add_argument("--frames", type=int, default=160, help="frames per generated walk (default 160)")
    parser.add_argument("--corpus", default=None, help="also measure this corpus' test-split walks")
    parser.add_argument("--no-timeline", action="store_true", help="skip the timeline walks")
    args = parser.parse_args()
    torch.set_num_threads(1)
    from controlmm.generate import generate, load_model
    from controlmm.timeline import generate_timeline

    model = load_model(args.model)
    print(f"model {args.model}, {args.frames} frames, seeds 0-{args.seeds - 1}, torch threads 1")
    print(
        "| source | prompt | seed | cruise (m/s) | cadence (steps/min) | swing-foot peak (m/s) "
        "| peak joint (m/s) |"
    )
    print("|---|---|---|---|---|---|---|")
    generated, timeline_rows = [], []
    for prompt in PROMPTS:
        for seed in range(args.seeds):
            r = measure(generate(model, prompt, frames=args.frames, seed=seed).motion.joints)
            generated.append(r)
            print(
                f"| generate | {prompt} | {seed} | {r['speed']:.2f} | {r['cadence']:.0f} | "
                f"{r['foot_peak']:.2f} | {r['joint_peak']:.2f} |"
            )
    for prompt in () if args.no_timeline else TIMELINE_LEGS:
        spec = copy.deepcopy(SPECS["walk+wave"])
        legs = spec["tracks"][0]
        legs["prompt"] = prompt
        for seed in range(args.seeds):
            motion, _ = generate_timeline(model, spec, seed=seed)
            span = motion.joints[int(legs["start"] * FPS) : int(legs["end"] * FPS)]
            r = measure(span)
            timeline_rows.append(r)
            print(
                f"| timeline walk+wave legs | {prompt} | {seed} | {r['speed']:.2f} | "
                f"{r['cadence']:.0f} | {r['foot_peak']:.2f} | {r['joint_peak']:.2f} |"
            )
    print(f"\ngenerated: {summary(generated)}")
    if timeline_rows:
        print(f"timeline:  {summary(timeline_rows)}")
    if args.corpus is not None:
        print(f"corpus:    {summary(corpus_walks(args.corpus))}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
