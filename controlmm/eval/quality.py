"""Quality evaluation of text-to-motion: evaluation passes, the paper's columns, repeats, the table.

Protocol (the evaluation scripts of MoMask, https://github.com/EricGuo5513/momask-codes, and MaskControl,
https://github.com/exitudio/MaskControl):

- an **evaluation pass** over a split (:class:`EvalSet.draw`): the captioned samples in a random
  order, a final incomplete group of 32 dropped; per sample a random caption, the length m rounded
  down to a multiple of 4 with one more unit removed with probability 1/3, a random crop of m frames;
- the model generates one motion per (caption, m) of the pass; the columns (:func:`quality_columns`)
  are R-precision top-1/2/3 and MM-Dist of (caption, generated motion) in groups of 32, FID of the
  generated motions against the pass's ground truth, Diversity of the generated motions over 300
  pairs; **Multimodality** from ``mm_repeats`` generations of each of ``mm_texts`` captions;
- the **Real** row measures the ground truth itself: R-precision/MM-Dist/Diversity of the pass's
  ground truth, FID between the pass and an independent pass (other captions and crops);
- everything is repeated ``repeats`` times (10 in the paper) and reported as mean +- 1.96 std / sqrt(n).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from tqdm import tqdm

from controlmm.data.humanml3d import Caption, HumanML3D
from controlmm.errors import ControlMMError
from controlmm.eval import metrics as M
from controlmm.eval.evaluator.base import Evaluator, MotionLike
from controlmm.eval.scoring import MotionSet, columns_from_embeddings, quality_columns, score_motions
from controlmm.generate import MotionModel, generate
from controlmm.motion import Motion
from controlmm.motion.skeleton import MAX_FRAMES, MIN_FRAMES

COLUMNS = (
    "r_precision_top1",
    "r_precision_top2",
    "r_precision_top3",
    "fid",
    "mm_dist",
    "diversity",
    "multimodality",
)
HEADERS = {
    "r_precision_top1": "R@1",
    "r_precision_top2": "R@2",
    "r_precision_top3": "R@3",
    "fid": "FID",
    "mm_dist": "MM-Dist",
    "diversity": "Diversity",
    "multimodality": "MModality",
}
UNIT = 4

__all__ = [
    "COLUMNS",
    "EvalPass",
    "EvalSample",
    "EvalSet",
    "GenerateFn",
    "QualityReport",
    "columns_from_embeddings",
    "evaluate_quality",
    "model_generator",
    "quality_columns",
]

GenerateFn = Callable[[list["EvalSample"], int], list[MotionLike]]
"""(samples, seed) -> one motion per sample, made from ``sample.caption.text`` with ``sample.frames``
frames (raw 263-d features or Motion objects). A controlled generator may take its targets from the
ground truth ``sample.features``."""


# -- evaluation passes ------------------------------------------------------------------------------
@dataclass(frozen=True)
class EvalSample:
    """One sample of a pass: the ground-truth crop and the caption it is generated from."""

    name: str
    caption: Caption
    features: np.ndarray  # (frames, 263) raw ground-truth crop

    @property
    def frames(self) -> int:
        return int(len(self.features))


@dataclass
class EvalPass:
    """The samples of one pass, in evaluation order (a multiple of the group size)."""

    seed: int
    samples: list[EvalSample]

    @property
    def captions(self) -> list[Caption]:
        return [s.caption for s in self.samples]

    @property
    def texts(self) -> list[str]:
        return [s.caption.text for s in self.samples]

    @property
    def motions(self) -> list[np.ndarray]:
        return [s.features for s in self.samples]

    @property
    def frames(self) -> list[int]:
        return [s.frames for s in self.samples]

    def matching(self, evaluator: Evaluator, group: int = M.R_PRECISION_GROUP) -> M.Matching:
        """Ground-truth R-precision and MM-Dist of this pass (its order is already random)."""
        return M.matching_metrics(
            evaluator.embed_texts(self.captions),
            evaluator.embed_motions(self.motions),
            group=min(group, len(self.samples)),
        )


@dataclass
class EvalSet:
    """The captioned samples of a split (official length and span rules, :class:`HumanML3D`)."""

    split: str
    names: list[str]
    motions: list[np.ndarray]
    captions: list[list[Caption]]
    source: str = ""

    @classmethod
    def load(cls, data: HumanML3D | str | Path, split: str = "test", progress: bool = False) -> EvalSet:
        data = data if isinstance(data, HumanML3D) else HumanML3D(data)
        samples = data.text_samples(split, progress=progress)
        by_text: dict[str, dict[str, Caption]] = {}
        captions = []
        for s in samples:
            if s.motion_id not in by_text:
                by_text[s.motion_id] = {c.text: c for c in data.read_captions(s.motion_id)}
            captions.append([by_text[s.motion_id][t] for t in s.captions])
        return cls(split, [s.name for s in samples], [s.motion for s in samples], captions, str(data.root))

    def __len__(self) -> int:
        return len(self.names)

    def draw(self, seed: int, group: int = M.R_PRECISION_GROUP, limit: int | None = None) -> EvalPass:
        """One pass: random order, at most ``limit`` samples, whole groups only (all samples if fewer
        than one group), and per sample a random caption, length rounding and crop."""
        rng = np.random.default_rng([seed, 104729])
        order = rng.permutation(len(self))
        n = len(order) if limit is None else min(limit, len(order))
        if n >= group:
            n = n // group * group
        out = []
        for i in order[:n]:
            motion, caps = self.motions[i], self.captions[i]
            caption = caps[int(rng.integers(len(caps)))]
            units = min(len(motion), MAX_FRAMES) // UNIT
            if rng.integers(3) == 2:  # 'single', 'single', 'double' as the official eval loader
                units -= 1
            m = max(units, 1) * UNIT
            start = int(rng.integers(0, len(motion) - m + 1))
            out.append(EvalSample(self.names[i], caption, motion[start : start + m]))
        return EvalPass(seed, out)


# -- generation ---------------------------------------------------------------------------------------
def model_generator(model: MotionModel, batch_size: int = 64, **generate_kwargs: Any) -> GenerateFn:
    """A :data:`GenerateFn` for a loaded :class:`~controlmm.models.MotionModel` (base model, no control).

    Lengths below the model's 40-frame minimum are generated at 40 frames and cut.
    """

    def run(samples: list[EvalSample], seed: int) -> list[MotionLike]:
        frames = [s.frames for s in samples]
        asked = [min(max(f, MIN_FRAMES), MAX_FRAMES) for f in frames]
        result = generate(
            model,
            [s.caption.text for s in samples],
            frames=asked,
            seed=seed,
            batch_size=batch_size,
            **generate_kwargs,
        )
        return [_first_frames(m, f) for m, f in zip(result.motions, frames, strict=True)]

    return run


def _first_frames(motion: Motion, frames: int) -> np.ndarray:
    """The first ``frames`` feature frames (frames, 263) of a generated motion."""
    if motion.features is None:
        raise ControlMMError("a generated motion has no features")
    return motion.features[:frames]


# -- repeated evaluation ----------------------------------------------------------------------------
@dataclass
class QualityReport:
    """Per-repeat values of every column for each row ("Real", then the model)."""

    evaluator: str
    data: str
    split: str
    repeats: int
    samples: int
    rows: dict[str, dict[str, list[float]]] = field(default_factory=dict)
    settings: dict[str, Any] = field(default_factory=dict)

    def add(self, row: str, values: dict[str, float]) -> None:
        target = self.rows.setdefault(row, {})
        for key in COLUMNS:
            if key in values:
                target.setdefault(key, []).append(float(values[key]))

    def summary(self) -> dict[str, dict[str, tuple[float, float]]]:
        """Row -> column -> (mean, 95 % CI half-width)."""
        return {row: {k: M.mean_ci(v) for k, v in cols.items()} for row, cols in self.rows.items()}

    def table(self) -> str:
        """The paper-style table: one row per method, columns ``mean±ci``."""
        summary = self.summary()
        name_width = max([len("Method")] + [len(r) for r in summary])
        head = f"{'Method':<{name_width}} " + " ".join(f"{HEADERS[c]:>15}" for c in COLUMNS)
        lines = [head, "-" * len(head)]
        for row, cols in summary.items():
            cells = []
            for c in COLUMNS:
                if c in cols:
                    mean, ci = cols[c]
                    cells.append(f"{mean:.3f}±{ci:.3f}".rjust(15))
                else:
                    cells.append("-".rjust(15))
            lines.append(f"{row:<{name_width}} " + " ".join(cells))
        return "\n".join(lines)

    def to_json(self) -> dict[str, Any]:
        return {
            "evaluator": self.evaluator,
            "data": self.data,
            "split": self.split,
            "repeats": self.repeats,
            "samples_per_repeat": self.samples,
            "settings": self.settings,
            "rows": {
                row: {k: {"mean": m, "ci95": c, "values": self.rows[row][k]} for k, (m, c) in cols.items()}
                for row, cols in self.summary().items()
            },
        }


def evaluate_quality(
    evaluator: Evaluator,
    evalset: EvalSet,
    generators: dict[str, GenerateFn] | None = None,
    repeats: int = 10,
    seed: int = 0,
    limit: int | None = None,
    mm_texts: int = 32,
    mm_repeats: int = 12,
    mm_times: int = M.MULTIMODALITY_TIMES,
    real: bool = True,
    progress: bool = False,
) -> QualityReport:
    """The quality table: a "Real" row and one row per generator, ``repeats`` passes each.

    Args:
        evaluator: judges every row.
        evalset: the split's samples (:meth:`EvalSet.load`).
        generators: row name -> :data:`GenerateFn` (e.g. :func:`model_generator`); none = Real only.
        repeats: evaluation passes (the paper: 10).
        seed: pass r uses seed + r (captions, crops, groups); generation uses seed + r too.
        limit: at most this many samples per pass (whole groups of 32).
        mm_texts / mm_repeats / mm_times: Multimodality from ``mm_repeats`` generations of the first
            ``mm_texts`` captions of each pass, ``mm_times`` pairs (paper protocol: 100 / 30 / 10;
            0 texts: not computed).
        real: include the Real row.
    """
    if repeats < 1:
        raise ControlMMError(f"repeats must be at least 1; got {repeats}")
    generators = generators or {}
    if mm_texts and generators and mm_repeats <= mm_times:
        raise ControlMMError(
            f"multimodality needs more generations per caption than pairs: --mm-repeats "
            f"{mm_repeats} <= {mm_times} pairs"
        )
    first = evalset.draw(seed, limit=limit)
    report = QualityReport(
        evaluator=evaluator.name,
        data=evalset.source,
        split=evalset.split,
        repeats=repeats,
        samples=len(first.samples),
        settings={
            "seed": seed,
            "limit": limit,
            "group": M.R_PRECISION_GROUP,
            "diversity_times": M.DIVERSITY_TIMES,
            "mm_texts": mm_texts,
            "mm_repeats": mm_repeats,
            "mm_times": mm_times,
        },
    )
    steps = repeats * (int(real) + len(generators))
    bar = tqdm(total=steps, desc="quality", unit="run", disable=not progress, dynamic_ncols=True)
    sets: dict[str, list[MotionSet]] = {}
    modality: dict[str, list[float]] = {}
    for r in range(repeats):
        run_seed = seed + r
        passed = first if r == 0 else evalset.draw(run_seed, limit=limit)
        if real:
            other = evalset.draw(run_seed + 100_003, limit=limit)
            sets.setdefault("Real", []).append(MotionSet(passed.motions, passed.captions, other.motions))
            bar.update(1)
        for name, generate_fn in generators.items():
            bar.set_postfix_str(f"{name}, pass {r + 1}/{repeats}")
            motions = generate_fn(passed.samples, run_seed)
            sets.setdefault(name, []).append(MotionSet(motions, passed.captions, passed.motions))
            k = min(mm_texts, len(passed.samples))
            if k > 0:
                repeated = [s for s in passed.samples[:k] for _ in range(mm_repeats)]
                emb = evaluator.embed_motions(generate_fn(repeated, run_seed + 7919)).reshape(
                    k, mm_repeats, -1
                )
                modality.setdefault(name, []).append(
                    M.multimodality(emb, mm_times, np.random.default_rng(run_seed))
                )
            bar.update(1)
    bar.close()
    for name, runs in sets.items():
        report.rows[name] = score_motions(evaluator, runs, seed=seed).values
        if name in modality:
            report.rows[name]["multimodality"] = modality[name]
    return report
