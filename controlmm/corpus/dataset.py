"""Write the procedural corpus as a HumanML3D dataset directory.

Layout (exactly HumanML3D's, plus ``meta/`` and ``corpus.json``)::

    DIR/new_joint_vecs/<id>.npy   (T, 263) float32 features (joints_to_features)
    DIR/new_joints/<id>.npy       (T, 22, 3) float32 joints = features_to_joints(features)
    DIR/texts/<id>.txt            lines "caption#lemma/POS ...#0.0#0.0"
    DIR/train.txt, val.txt, test.txt, all.txt   clip ids, one per line
    DIR/Mean.npy, Std.npy         train-split mean and HumanML3D group std (263,)
    DIR/meta/<id>.json            family, parameters, captions (template, held-out flag, claims)
    DIR/corpus.json               how the corpus was made (command config, counts, timing)

Every clip is drawn from its own seed sequence (corpus seed, clip index), so the corpus is
the same for any number of worker processes.
"""

from __future__ import annotations

import json
import multiprocessing as mp
import os
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import torch
from tqdm import tqdm

from controlmm.atomic import atomic_dir, check_output_dir
from controlmm.corpus.family import Built
from controlmm.corpus.probes import probe
from controlmm.corpus.processing import process
from controlmm.corpus.registry import family_names, get_family
from controlmm.corpus.text.templates import Caption
from controlmm.errors import ControlMMError
from controlmm.motion.geometry import foot_skating_ratio
from controlmm.motion.normalization import FEATURE_GROUPS
from controlmm.motion.skeleton import BONE_LENGTHS, FPS, MAX_FRAMES, MIN_FRAMES, PARENTS

FORMAT_VERSION = 1
SPLITS = ("train", "val", "test")
MAX_ATTEMPTS = 8
MAX_CLIP_SKATING = 0.1


@dataclass(frozen=True)
class CorpusConfig:
    """What to generate.

    Attributes:
        clips: number of clips (>= 1).
        seed: corpus seed.
        families: family names to draw from (None: all), used round-robin.
        fractions: train/val/test fractions, applied per family.
        captions: captions per clip (>= 3).
    """

    clips: int
    seed: int = 0
    families: tuple[str, ...] | None = None
    fractions: tuple[float, float, float] = (0.8, 0.05, 0.15)
    captions: int = 3

    def validate(self) -> None:
        if not isinstance(self.clips, (int, np.integer)) or self.clips < 1:
            raise ControlMMError(f"--clips must be an integer >= 1; got {self.clips}")
        if self.captions < 3:
            raise ControlMMError(f"captions per clip must be >= 3; got {self.captions}")
        for name in self.families or ():
            get_family(name)


@dataclass(frozen=True)
class ClipSpec:
    """One clip to make: id, family, split and the seed sequence entropy."""

    index: int
    clip_id: str
    family: str
    split: str
    seed: int


@dataclass
class ClipResult:
    clip_id: str
    family: str
    split: str
    frames: int
    attempt: int
    retry_reasons: list[str]
    feature_sum: np.ndarray = field(repr=False)
    feature_sq: np.ndarray = field(repr=False)


def plan_clips(config: CorpusConfig) -> list[ClipSpec]:
    """Assign families (round-robin over a seeded shuffle) and splits (per family) to clips."""
    names = list(config.families or family_names())
    rng = np.random.default_rng(np.random.SeedSequence([config.seed, 0x5EED]))
    order = [names[i % len(names)] for i in range(config.clips)]
    order = [order[i] for i in rng.permutation(config.clips)]
    # Stratified split with exact global fractions: rank clips within their family, sort
    # all clips by relative rank, then cut the sorted list at the train/val fractions.
    key = np.zeros(config.clips)
    for name in names:
        members = [i for i, f in enumerate(order) if f == name]
        for k, i in enumerate(rng.permutation(len(members))):
            key[members[i]] = (k + 0.5) / len(members)
    ranked = np.lexsort((rng.random(config.clips), key))
    n_train = int(round(config.fractions[0] * config.clips))
    n_val = int(round(config.fractions[1] * config.clips))
    split_of = {}
    for pos, i in enumerate(ranked):
        split_of[int(i)] = "train" if pos < n_train else ("val" if pos < n_train + n_val else "test")
    width = max(6, len(str(config.clips - 1)))
    return [ClipSpec(i, f"{i:0{width}d}", order[i], split_of[i], config.seed) for i in range(config.clips)]


def make_clip(spec: ClipSpec, captions: int = 3) -> tuple[np.ndarray, np.ndarray, list, dict]:
    """Generate one clip: features (T, 263), joints (T, 22, 3), captions and metadata.

    The motion is retried with a new seed (attempt 1, 2, ...) when a sanity check fails
    (floor penetration by a non-foot joint, foot skating above 0.1, wrong length, a caption
    that its probe finds untrue); ``meta["seed"][2]`` records the attempt used.
    """
    family = get_family(spec.family)
    reasons: list[str] = []
    for attempt in range(MAX_ATTEMPTS):
        rng = np.random.default_rng(np.random.SeedSequence([spec.seed, spec.index, attempt]))
        params = family.sample(rng)
        built = family.build(params, rng)
        raw, scene = (built.joints, built.scene) if isinstance(built, Built) else (built, None)
        features, joints, positions = process(raw)
        text_rng = np.random.default_rng(np.random.SeedSequence([spec.seed, spec.index, attempt, 7]))
        caps = family.captions(params, text_rng, held_out=spec.split == "test", count=captions)
        problem = check_clip(raw, joints, positions) or check_captions(spec.family, joints, caps)
        if problem is None:
            break
        reasons.append(problem)
    else:
        raise RuntimeError(f"clip {spec.clip_id} ({spec.family}) failed {MAX_ATTEMPTS} attempts: {problem}")
    meta = {
        "version": FORMAT_VERSION,
        "id": spec.clip_id,
        "family": spec.family,
        "group": family.group,
        "split": spec.split,
        "frames": int(len(features)),
        "fps": FPS,
        "seed": [spec.seed, spec.index, attempt],
        "held_out": spec.split == "test",
        "params": params,
        "captions": [c.to_json() for c in caps],
        "retry_reasons": reasons,
    }
    if scene is not None:
        meta["scene"] = scene.to_clip_frame(raw[0], positions[0])
    return features, joints, caps, meta


def check_captions(family: str, joints: np.ndarray, captions: list[Caption]) -> str | None:
    """A caption the motion does not satisfy (by its probe), or None: a last guard so that no
    untrue caption is ever written."""
    for cap in captions:
        result = probe(joints, family, cap.claims)
        if not result.passed:
            return f"caption '{cap.text}' fails its probe: {result.describe()}"
    return None


def check_clip(raw: np.ndarray, joints: np.ndarray, positions: np.ndarray) -> str | None:
    """Why a generated clip is unusable, or None. ``raw`` are the generator's joints (metres,
    floor at y = 0), ``joints`` those recovered from the features, ``positions`` the
    canonical positions the features were computed from."""
    if not np.all(np.isfinite(joints)):
        return "non-finite joints"
    if not MIN_FRAMES <= len(joints) <= MAX_FRAMES:
        return f"{len(joints)} frames"
    drift = float(np.abs(joints - positions[:-1]).max())
    if drift > 1e-3:
        return f"features do not reproduce the joints ({drift:.4f} m)"
    bones = np.linalg.norm(raw[:, 1:] - raw[:, list(PARENTS[1:])], axis=-1)
    if np.abs(bones - BONE_LENGTHS[1:]).max() > 1e-5:
        return "bone length changed"
    if raw[..., 1].min() < -1e-6:
        return f"joint below the floor ({raw[..., 1].min():.3f} m)"
    body = np.delete(raw, [7, 8, 10, 11], axis=1)
    if body[..., 1].min() < 0.04:
        return f"a non-foot joint touches the floor ({body[..., 1].min():.3f} m)"
    skate = foot_skating_ratio(joints)
    if skate > MAX_CLIP_SKATING:
        return f"foot skating {skate:.3f}"
    return None


def _work(args: tuple[ClipSpec, str, int]) -> ClipResult:
    spec, root, captions = args
    features, joints, caps, meta = make_clip(spec, captions)
    out = Path(root)
    np.save(out / "new_joint_vecs" / f"{spec.clip_id}.npy", features)
    np.save(out / "new_joints" / f"{spec.clip_id}.npy", joints)
    (out / "texts" / f"{spec.clip_id}.txt").write_text(
        "\n".join(c.line() for c in caps) + "\n", encoding="utf-8"
    )
    (out / "meta" / f"{spec.clip_id}.json").write_text(json.dumps(meta, indent=1) + "\n", encoding="utf-8")
    f64 = features.astype(np.float64)
    return ClipResult(
        spec.clip_id,
        spec.family,
        spec.split,
        len(features),
        meta["seed"][2],
        meta["retry_reasons"],
        f64.sum(0),
        (f64 * f64).sum(0),
    )


def _init_worker() -> None:
    torch.set_num_threads(1)


CORPUS_OUTPUT = "corpus"
"""The output kind of a corpus directory (:data:`controlmm.atomic.OUTPUT_MARKER`)."""


def write_corpus(
    out: str | Path, config: CorpusConfig, workers: int = 0, progress: bool = True, force: bool = False
) -> dict[str, Any]:
    """Generate the corpus into ``out`` atomically (the directory appears complete or not at all).

    Args:
        out: target directory: new, empty or a previous corpus; anything else needs ``force``.
        config: what to generate.
        workers: processes (0: all CPU cores; 1: in this process).
        progress: show a tqdm progress bar.
        force: replace ``out`` whatever it holds (never a regular file).

    Returns:
        The summary also written to ``corpus.json``.
    """
    config.validate()
    out = Path(out)
    check_output_dir(out, kind=CORPUS_OUTPUT, force=force)
    workers = workers or os.cpu_count() or 1
    if workers < 1:
        raise ControlMMError(f"--workers must be >= 1; got {workers}")
    specs = plan_clips(config)
    start = time.perf_counter()
    with atomic_dir(out, kind=CORPUS_OUTPUT, force=force) as tmp:
        for sub in ("new_joint_vecs", "new_joints", "texts", "meta"):
            (tmp / sub).mkdir()
        jobs = [(spec, str(tmp), config.captions) for spec in specs]
        bar = tqdm(total=len(jobs), desc="corpus", unit="clip", disable=not progress)
        results: list[ClipResult] = []
        if workers == 1:
            for job in jobs:
                results.append(_work(job))
                bar.update()
        else:
            ctx = mp.get_context("fork" if "fork" in mp.get_all_start_methods() else "spawn")
            with ctx.Pool(min(workers, len(jobs)), initializer=_init_worker) as pool:
                for res in pool.imap(_work, jobs, chunksize=4):
                    results.append(res)
                    bar.update()
        bar.close()
        summary = _finish(tmp, config, results, time.perf_counter() - start, workers)
    return summary


def _finish(
    root: Path, config: CorpusConfig, results: list[ClipResult], seconds: float, workers: int
) -> dict:
    for split in SPLITS:
        ids = sorted(r.clip_id for r in results if r.split == split)
        (root / f"{split}.txt").write_text("".join(f"{i}\n" for i in ids), encoding="utf-8")
    (root / "all.txt").write_text(
        "".join(f"{r.clip_id}\n" for r in sorted(results, key=lambda r: r.clip_id)), encoding="utf-8"
    )
    train = [r for r in results if r.split == "train"] or results
    count = sum(r.frames for r in train)
    total = np.sum([r.feature_sum for r in train], axis=0)
    squares = np.sum([r.feature_sq for r in train], axis=0)
    mean = total / count
    std = np.sqrt(np.maximum(squares / count - mean * mean, 0.0))
    for sl in FEATURE_GROUPS.values():
        std[sl] = std[sl].mean()
    np.save(root / "Mean.npy", mean.astype(np.float32))
    np.save(root / "Std.npy", np.maximum(std, 1e-8).astype(np.float32))
    families = {name: n for name in family_names() if (n := sum(r.family == name for r in results))}
    summary = {
        "format": "humanml3d",
        "version": FORMAT_VERSION,
        "generator": "controlmm.corpus",
        "config": {**asdict(config), "families": list(config.families) if config.families else None},
        "clips": len(results),
        "frames": int(sum(r.frames for r in results)),
        "splits": {s: sum(r.split == s for r in results) for s in SPLITS},
        "families": families,
        "retries": int(sum(r.attempt for r in results)),
        "retried": {r.clip_id: r.retry_reasons for r in results if r.retry_reasons},
    }
    # corpus.json is part of the deterministic output: no timings in it.
    (root / "corpus.json").write_text(json.dumps(summary, indent=1) + "\n", encoding="utf-8")
    return {**summary, "seconds": round(seconds, 2), "workers": workers}
