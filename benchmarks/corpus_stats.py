"""Corpus statistics: one command prints the table recorded in docs/BENCHMARKS.md (## Corpus).

    python benchmarks/corpus_stats.py --generate 5000 --seed 0 --workers 2 --png docs/corpus_lengths.png
    python benchmarks/corpus_stats.py --data data/corpus-default   # an existing corpus (docs/corpus.md)

With ``--generate N`` it times ``controlmm.corpus.write_corpus`` for N clips (into a temporary
directory unless ``--out`` is given) and then measures the result. Measures, all on the
written ``new_joints`` (the HumanML3D joints the features describe):
clips per family, clip lengths, foot-skating ratio (the ControlMM / OmniControl evaluation's: a foot below
5 cm in two frames that moves faster than 0.5 m/s, also over 5 frames; ``controlmm.motion.geometry``),
floor contact and penetration, joint speeds, bone lengths, knee hyper-extension and the
probe pass rate on the ground truth; and per family the timing and balance figures (travel speed,
cadence, swing-foot peak speed, pelvis and trunk sway; :func:`timing`), with the swing-foot peak of
the ``walk`` clips by speed, to compare with published gait data (docs/corpus.md, "Timing").
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from collections import Counter
from pathlib import Path

import numpy as np
from data_dirs import corpus_dir

from controlmm.corpus import CorpusConfig, family_names, write_corpus
from controlmm.corpus.measures import Measures
from controlmm.eval.cases import evaluate, ground_truth, list_cases
from controlmm.motion.geometry import foot_skating_ratio
from controlmm.motion.skeleton import BONE_LENGTHS, FPS, PARENTS

LENGTH_BINS = (40, 60, 80, 100, 120, 140, 160, 180, 197)


def knee_hyperextension(j: np.ndarray) -> float:
    """Most negative offset (m) of a knee from its hip-ankle line along the foot's forward
    direction (negative = the knee bends backwards)."""
    worst = np.inf
    for hip, knee, ankle, toe in ((1, 4, 7, 10), (2, 5, 8, 11)):
        axis = j[:, ankle] - j[:, hip]
        axis /= np.linalg.norm(axis, axis=-1, keepdims=True)
        rel = j[:, knee] - j[:, hip]
        off = rel - (rel * axis).sum(-1, keepdims=True) * axis
        foot = j[:, toe] - j[:, ankle]
        foot[:, 1] = 0.0
        foot /= np.maximum(np.linalg.norm(foot, axis=-1, keepdims=True), 1e-9)
        worst = min(worst, float((off * foot).sum(-1).min()))
    return worst


def contact_floor_penetration(j: np.ndarray) -> float:
    """How far (m) any joint goes below the floor the feet stand on: the floor is the median
    height of the toe joints while they rest (planar speed < 0.1 m/s and height < 5 cm)."""
    toes = j[:, [10, 11]]
    speed = np.linalg.norm(np.diff(toes[:, :, [0, 2]], axis=0), axis=-1) * FPS
    resting = (speed < 0.1) & (toes[1:, :, 1] < 0.05)
    floor = float(np.median(toes[1:, :, 1][resting])) if resting.any() else 0.0
    return max(0.0, floor - float(j[..., 1].min()))


def swing_onsets(speed: np.ndarray, up: float = 1.0, down: float = 0.3) -> int:
    """Number of swings of a foot: rises of its speed above ``up`` m/s after it fell below ``down``."""
    count, armed = 0, True
    for v in speed:
        if armed and v > up:
            count, armed = count + 1, False
        elif not armed and v < down:
            armed = True
    return count


def timing(j: np.ndarray) -> dict[str, float]:
    """Timing and balance figures of one clip (joints (T, 22, 3), 20 fps).

    speed: cruise speed of the pelvis (m/s, :attr:`Measures.cruise`); foot_peak: the fastest
    toe joint (m/s, 20 fps frame differences, as in docs/corpus.md); cadence: swing onsets of
    both feet per minute while the pelvis moves at >= half its cruise speed (NaN for clips that
    travel less than 1 m or take no step); sway: peak-to-peak lateral offset (m) of the pelvis
    from the ankles' midpoint, along the person's left (the weight shifting over the feet; a foot
    that kicks or steps sideways moves the midpoint too); trunk: peak-to-peak
    side tilt (deg) of the pelvis -> neck line."""
    m = Measures(j, FPS)
    toe = np.linalg.norm(np.diff(j[:, [10, 11]], axis=0), axis=-1) * FPS
    cruise = m.cruise
    cadence = float("nan")
    if cruise >= 0.3 and m.travel[2] >= 1.0:
        moving = m.speed >= 0.5 * cruise
        seconds = moving.sum() / FPS
        steps = sum(swing_onsets(np.where(moving, toe[:, k], 0.0)) for k in range(2))
        cadence = 60.0 * steps / seconds if seconds > 0.5 and steps else float("nan")
    mid = 0.5 * (j[:, 7] + j[:, 8])
    _, left = m.frame
    lateral = ((j[:, 0] - mid) * left).sum(-1)
    neck = j[:, 12] - j[:, 0]
    tilt = np.degrees(np.arctan2((neck * left).sum(-1), neck[:, 1]))
    return {
        "speed": cruise,
        "foot_peak": float(toe.max()),
        "cadence": cadence,
        "sway": float(np.ptp(lateral)),
        "trunk": float(np.ptp(tilt)),
    }


WALK_SPEED_BINS = ((0.55, 0.8), (0.9, 1.1), (1.25, 1.45), (1.6, 1.85))
"""Walking-speed bins (m/s) for the swing-foot peak of the ``walk`` family."""


def measure(root: Path) -> dict:
    ids = (root / "all.txt").read_text().split()
    families: Counter[str] = Counter()
    lengths, skate, pen, lowest_body, hyper, bone_err = [], [], [], [], [], 0.0
    speeds = []
    per_family: dict[str, list[dict[str, float]]] = {}
    for clip_id in ids:
        meta = json.loads((root / "meta" / f"{clip_id}.json").read_text())
        j = np.load(root / "new_joints" / f"{clip_id}.npy").astype(np.float64)
        families[meta["family"]] += 1
        per_family.setdefault(meta["family"], []).append(timing(j))
        lengths.append(len(j))
        skate.append(foot_skating_ratio(j))
        pen.append(contact_floor_penetration(j))
        lowest_body.append(float(np.delete(j, [7, 8, 10, 11], axis=1)[..., 1].min()))
        hyper.append(knee_hyperextension(j))
        bones = np.linalg.norm(j[:, 1:] - j[:, list(PARENTS[1:])], axis=-1)
        bone_err = max(bone_err, float(np.abs(bones - BONE_LENGTHS[1:]).max()))
        speeds.append((np.linalg.norm(np.diff(j, axis=0), axis=-1) * FPS).ravel())
    report = evaluate(list_cases(root, "all"), ground_truth(root), split="all", per_clip=True)
    return {
        "families": families,
        "lengths": np.array(lengths),
        "skate": np.array(skate),
        "pen": np.array(pen),
        "lowest_body": np.array(lowest_body),
        "hyper": np.array(hyper),
        "bone_err": bone_err,
        "speeds": np.concatenate(speeds),
        "probes": report,
        "clips": len(ids),
        "timing": per_family,
    }


def timing_table(per_family: dict[str, list[dict[str, float]]]) -> str:
    """Markdown table of the per-family timing and balance figures (medians over the clips)."""
    lines = [
        "| family | clips | speed (m/s) | cadence (steps/min) | swing-foot peak (m/s, median / p90) "
        "| pelvis sway (cm) | trunk sway (deg) |",
        "|---|---|---|---|---|---|---|",
    ]
    for name in sorted(per_family, key=family_names().index):
        rows = per_family[name]
        col = {k: np.array([r[k] for r in rows]) for k in rows[0]}
        cad = col["cadence"][np.isfinite(col["cadence"])]
        speed = np.median(col["speed"])
        lines.append(
            f"| {name} | {len(rows)} | {speed:.2f} | {np.median(cad):.0f} | "
            if len(cad)
            else f"| {name} | {len(rows)} | {speed:.2f} | - | "
        )
        lines[-1] += (
            f"{np.median(col['foot_peak']):.2f} / {np.percentile(col['foot_peak'], 90):.2f} | "
            f"{100 * np.median(col['sway']):.1f} | {np.median(col['trunk']):.1f} |"
        )
    return "\n".join(lines)


def walk_peaks(per_family: dict[str, list[dict[str, float]]]) -> str:
    """Markdown table: the ``walk`` family's swing-foot peak by walking speed."""
    rows = per_family.get("walk", [])
    lines = [
        "| walk speed (m/s) | clips | cadence (steps/min) | swing-foot peak (m/s, mean / max) |",
        "|---|---|---|---|",
    ]
    for lo, hi in WALK_SPEED_BINS:
        sel = [r for r in rows if lo <= r["speed"] <= hi]
        if not sel:
            continue
        peak = np.array([r["foot_peak"] for r in sel])
        cad = np.array([r["cadence"] for r in sel])
        cells = (f"{lo:.2f}-{hi:.2f}", str(len(sel)), f"{np.nanmedian(cad):.0f}")
        lines.append(f"| {' | '.join(cells)} | {peak.mean():.2f} / {peak.max():.2f} |")
    return "\n".join(lines)


def write_histogram(lengths: np.ndarray, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(5, 2.6), dpi=90)
    ax.hist(lengths, bins=list(range(40, 200, 8)), color="#1f77b4", edgecolor="white")
    ax.set_xlabel("clip length (frames at 20 fps)")
    ax.set_ylabel("clips")
    ax.set_title(f"corpus clip lengths (n={len(lengths)})", fontsize=10)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--data", help="measure an existing corpus directory")
    ap.add_argument("--generate", type=int, help="generate this many clips first (timed)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--workers", type=int, default=0)
    ap.add_argument("--out", help="where to write the generated corpus (default: a temporary directory)")
    ap.add_argument("--png", help="write the clip-length histogram to this PNG")
    args = ap.parse_args(argv)
    if not args.data and not args.generate:
        ap.error("give --data DIR or --generate N")

    with tempfile.TemporaryDirectory() as tmp:
        root = corpus_dir(args.data) if args.data else Path(args.out or Path(tmp) / "corpus")
        if args.generate:
            t0 = time.perf_counter()
            summary = write_corpus(
                root, CorpusConfig(clips=args.generate, seed=args.seed), workers=args.workers, progress=False
            )
            gen = time.perf_counter() - t0
            print(
                f"generation: {args.generate} clips, seed {args.seed}, {summary['workers']} workers: "
                f"{gen:.1f} s "
                f"({args.generate / gen:.1f} clips/s), {summary['retries']} retried clips"
            )
        m = measure(root)
    lengths = m["lengths"]
    print(
        f"\nclips {m['clips']}, frames {lengths.sum()} ({lengths.sum() / FPS / 3600:.2f} h), "
        f"families {len(m['families'])}"
    )
    print("\n| family | clips |\n|---|---|")
    for name in sorted(m["families"], key=lambda f: family_names().index(f)):
        print(f"| {name} | {m['families'][name]} |")
    hist, _ = np.histogram(lengths, bins=LENGTH_BINS)
    print(
        "\n| length (frames) | "
        + " | ".join(f"{a}-{b - 1}" for a, b in zip(LENGTH_BINS[:-1], LENGTH_BINS[1:], strict=True))
        + " |"
    )
    print("|---" * (len(hist) + 1) + "|")
    print("| clips | " + " | ".join(str(h) for h in hist) + " |")
    print(f"\nlength: min {lengths.min()}, median {int(np.median(lengths))}, max {lengths.max()} frames")
    sp = m["speeds"]
    p50, p90, p99 = np.percentile(sp, [50, 90, 99])
    rows = [
        ("foot-skating ratio (mean over clips)", f"{m['skate'].mean():.4f}"),
        ("foot-skating ratio (worst clip)", f"{m['skate'].max():.4f}"),
        ("clips with skating ratio > 0.05", f"{int((m['skate'] > 0.05).sum())}"),
        ("max penetration below the contact floor (m)", f"{m['pen'].max():.4f}"),
        ("lowest non-foot joint over the corpus (m)", f"{m['lowest_body'].min():.3f}"),
        ("joint speed p50 / p90 / p99 (m/s)", f"{p50:.2f} / {p90:.2f} / {p99:.2f}"),
        ("joint speed max (m/s)", f"{sp.max():.2f}"),
        ("max bone-length deviation (m)", f"{m['bone_err']:.2e}"),
        ("worst knee offset along the foot (m, < 0 = hyper-extended)", f"{m['hyper'].min():.3f}"),
        (
            "probe pass rate on ground truth (all splits)",
            f"{100 * m['probes'].rate:.2f}% ({m['probes'].passed}/{m['probes'].total} captions)",
        ),
    ]
    print("\n| measure | value |\n|---|---|")
    for k, v in rows:
        print(f"| {k} | {v} |")
    print("\nTiming and balance per family (medians over clips; see timing()):\n")
    print(timing_table(m["timing"]))
    print("\nSwing-foot peak of the walk family by speed:\n")
    print(walk_peaks(m["timing"]))
    if args.png:
        write_histogram(lengths, Path(args.png))
        print(f"\nwrote {args.png}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
