"""Benchmark of body-part timeline control on a few specs with a trained model.

    python benchmarks/timeline.py --model MODEL_DIR [--corpus CORPUS_DIR] [--preset accurate] [--seed 0]

For every spec: wall seconds, the largest drift (cm) of entries held by a later pass from what the
pass that fixed them produced, the fastest joint at any track boundary (m/s) against the 99th
percentile of joint speeds in the corpus' test split, and the text-adherence probe of every track
(``controlmm.corpus.probes``) on its span, beside the pass rate of the same prompt generated alone by the
model over the span's length (3 seeds: what the model can do without the timeline). Runs
single-threaded (torch and BLAS) so figures are stable on a shared machine.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("HF_HUB_OFFLINE", "1")

import numpy as np  # noqa: E402
import torch  # noqa: E402
from data_dirs import corpus_dir  # noqa: E402

SPECS: dict[str, dict] = {
    "walk+wave": {
        "tracks": [
            {
                "part": "legs",
                "prompt": "a person walks forward",
                "start": 0,
                "end": 6,
                "probe": {"family": "walk", "claims": {}},
            },
            {
                "part": "right_arm",
                "prompt": "a human raises their right arm and waves.",
                "start": 2,
                "end": 4.5,
                "probe": {"family": "wave_right", "claims": {"hand": "right"}},
            },
        ]
    },
    "raise-then-reach": {
        "seconds": 6,
        "base": "a person stands still",
        "tracks": [
            {
                "part": "left_arm",
                "prompt": "a person raises their left arm.",
                "start": 0.5,
                "end": 3,
                "probe": {"family": "raise_arm", "claims": {"hand": "left"}},
            },
            {
                "part": "right_arm",
                "prompt": "a person reaches forward with their right hand.",
                "start": 3.5,
                "end": 6,
                "probe": {"family": "reach_forward", "claims": {"hand": "right"}},
            },
        ],
    },
    "jump+wave": {
        "seconds": 6,
        "base": "a person stands still",
        "tracks": [
            {
                "part": "legs",
                "prompt": "a person jumps in place one time.",
                "start": 0.5,
                "end": 3,
                "probe": {"family": "jump_in_place", "claims": {"count": 1}},
            },
            {
                "part": "left_arm",
                "prompt": "a human raises their left arm and waves.",
                "start": 3,
                "end": 5.5,
                "probe": {"family": "wave_left", "claims": {"hand": "left"}},
            },
        ],
    },
    "backward+wave": {
        "tracks": [
            {
                "part": "legs",
                "prompt": "the person walks backward.",
                "start": 0,
                "end": 5,
                "probe": {"family": "walk_backward", "claims": {}},
            },
            {
                "part": "left_arm",
                "prompt": "a human raises their left arm and waves.",
                "start": 1,
                "end": 3.5,
                "probe": {"family": "wave_left", "claims": {"hand": "left"}},
            },
        ]
    },
}


def corpus_speed_percentile(corpus: Path, q: float = 99.0, split: str = "test") -> float:
    """The q-th percentile (m/s) of every joint's frame-to-frame speed over a corpus split."""
    from controlmm.timeline.signals import joint_speeds

    ids = (corpus / f"{split}.txt").read_text().split()
    speeds = [joint_speeds(np.load(corpus / "new_joints" / f"{i}.npy")).ravel() for i in ids]
    return float(np.percentile(np.concatenate(speeds), q))


def _alone(model, track: dict) -> int:
    """How many of 3 seeds of the track's prompt, generated alone over its span, pass its probe."""
    from controlmm.corpus.probes import probe
    from controlmm.generate import generate
    from controlmm.motion.skeleton import MIN_FRAMES

    frames = max(track["frames"][1] - track["frames"][0], MIN_FRAMES)
    family = track["probe"]["family"]
    claims = SPEC_CLAIMS[(track["prompt"], family)]
    return sum(
        probe(generate(model, track["prompt"], frames=frames, seed=s).motion.joints, family, claims).passed
        for s in range(3)
    )


SPEC_CLAIMS = {
    (t["prompt"], t["probe"]["family"]): t["probe"]["claims"]
    for spec in SPECS.values()
    for t in spec["tracks"]
    if "probe" in t
}


def main() -> int:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--model", required=True, help="trained model directory")
    parser.add_argument(
        "--corpus",
        default=None,
        help="corpus (HumanML3D format) for the speed percentile (default: data/corpus-default)",
    )
    parser.add_argument("--preset", default="accurate", choices=("fast", "medium", "accurate"))
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--specs", nargs="*", default=list(SPECS), help=f"subset of {', '.join(SPECS)}")
    args = parser.parse_args()
    torch.set_num_threads(1)
    from controlmm.generate import load_model
    from controlmm.timeline import generate_timeline

    corpus = corpus_dir(args.corpus, "--corpus")
    p99 = corpus_speed_percentile(corpus)
    model = load_model(args.model)
    model.encode_text(["warm-up"])
    rows = []
    for name in args.specs:
        started = time.perf_counter()
        _, report = generate_timeline(model, SPECS[name], seed=args.seed, preset=args.preset)
        seconds = time.perf_counter() - started  # (the probes of the prompts alone below are not timed)
        probes = " ".join(
            f"{t['part']}:{'pass' if t['probe']['passed'] else 'FAIL'} (alone {_alone(model, t)}/3)"
            for t in report["tracks"]
            if "probe" in t
        )
        rows.append(
            (
                name,
                len(report["passes"]),
                seconds,
                report["max_drift_cm"],
                report["max_boundary_speed_mps"],
                probes,
                report["probes_passed"],
            )
        )
    print(
        f"model {args.model}, preset {args.preset}, seed {args.seed}, torch threads 1, "
        f"corpus joint speed p99 {p99:.2f} m/s ({corpus}, test split)"
    )
    print(
        "| spec | passes | seconds | max drift of fixed parts (cm) | max boundary speed (m/s) | "
        "vs corpus p99 | probe per track (prompt alone: passes of 3 seeds) |"
    )
    print("|---|---|---|---|---|---|---|")
    for name, n, sec, drift, speed, probes, _ in rows:
        verdict = "below" if speed < p99 else "ABOVE"
        print(f"| {name} | {n} | {sec:.1f} | {drift:.2f} | {speed:.2f} | {verdict} | {probes} |")
    passed = sum(r[6][0] for r in rows)
    total = sum(r[6][1] for r in rows)
    print(
        f"probe pass rate per track: {passed}/{total}; mean seconds per spec "
        f"{np.mean([r[2] for r in rows]):.1f}"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
