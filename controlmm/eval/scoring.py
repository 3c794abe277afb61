"""Scoring generated motions against real ones with a text-motion evaluator: the paper's columns.

One function serves every table that has text-motion columns (``controlmm eval quality`` and
``controlmm eval control``): :func:`score_motions` takes one :class:`MotionSet` per run (repeat) and
returns, per column, the per-run values with their mean and 95 % confidence interval.

Columns of one run (:func:`columns_from_embeddings`):

- **R-precision top-1/2/3** and **MM-Dist** of (caption, motion) pairs in random groups of 32;
- **FID** of the motions against the run's real motions (for generated motions, the ground truth of
  the same samples; for the "Real" row, an independent draw of real motions);
- **Diversity** of the motions over 300 random pairs.

Sets smaller than a group use one group of all pairs (recorded as ``r_precision_group``); sets of
at most 300 motions use N - 1 Diversity pairs (``diversity_pairs``).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from controlmm.errors import ControlMMError
from controlmm.eval import metrics as M
from controlmm.eval.evaluator.base import Evaluator, MotionLike, TextLike

SCORE_COLUMNS = ("r_precision_top1", "r_precision_top2", "r_precision_top3", "fid", "mm_dist", "diversity")


def columns_from_embeddings(
    text_emb: np.ndarray,
    motion_emb: np.ndarray,
    reference_emb: np.ndarray,
    group: int = M.R_PRECISION_GROUP,
    diversity_times: int = M.DIVERSITY_TIMES,
    seed: int = 0,
    shuffle: bool = True,
) -> dict[str, float]:
    """R-precision top-1/2/3, MM-Dist, FID and Diversity from embeddings.

    Args:
        text_emb / motion_emb: (N, D) embeddings of captions and of the motions made from them (pairs).
        reference_emb: (N', D) embeddings of real motions (the FID reference).
        group: R-precision group size (32; smaller when N < 32, recorded as ``r_precision_group``).
        diversity_times: pairs for Diversity (300; N - 1 when N <= 300, recorded as ``diversity_pairs``).
        seed: random grouping (``shuffle``) and Diversity pairs.
    """
    rng = np.random.default_rng(seed)
    n = len(text_emb)
    if n < 2:
        raise ControlMMError(f"quality columns need at least 2 motions; got {n}")
    order = rng.permutation(n) if shuffle else np.arange(n)
    group = min(group, n)
    match = M.matching_metrics(np.asarray(text_emb)[order], np.asarray(motion_emb)[order], group=group)
    times = min(diversity_times, n - 1)
    return {
        "r_precision_top1": match.r_precision[0],
        "r_precision_top2": match.r_precision[1],
        "r_precision_top3": match.r_precision[2],
        "fid": M.fid(reference_emb, motion_emb),
        "mm_dist": match.mm_dist,
        "diversity": M.diversity(motion_emb, times, rng),
        "r_precision_group": group,
        "diversity_pairs": times,
        "samples": n,
    }


def quality_columns(
    evaluator: Evaluator,
    generated: Sequence[MotionLike],
    texts: Sequence[TextLike],
    ground_truth: Sequence[MotionLike],
    group: int = M.R_PRECISION_GROUP,
    diversity_times: int = M.DIVERSITY_TIMES,
    seed: int = 0,
) -> dict[str, float]:
    """The paper's text-motion columns for one run of generated motions.

    Args:
        evaluator: from :func:`controlmm.eval.evaluator.load_evaluator` (None there = the shipped one).
        generated: motions made from ``texts`` (Motion objects or raw (T, 263) features, <= 196 frames).
        texts: their captions (strings, or HumanML3D :class:`~controlmm.data.humanml3d.Caption` objects,
            whose ``word/POS`` tokens the official evaluator reads).
        ground_truth: real motions (the FID reference; the ground truth of the same samples).
        group, diversity_times, seed: see :func:`columns_from_embeddings`.

    Returns:
        ``r_precision_top1/2/3``, ``fid``, ``mm_dist``, ``diversity`` (+ ``samples``,
        ``r_precision_group``, ``diversity_pairs``).
    """
    if len(generated) != len(texts):
        raise ControlMMError(f"{len(generated)} generated motions for {len(texts)} captions")
    if len(generated) < 2:
        raise ControlMMError(f"quality columns need at least 2 motions; got {len(generated)}")
    if len(ground_truth) < 2:
        raise ControlMMError(f"FID needs at least 2 real motions; got {len(ground_truth)}")
    return columns_from_embeddings(
        evaluator.embed_texts(texts),
        evaluator.embed_motions(generated),
        evaluator.embed_motions(ground_truth),
        group,
        diversity_times,
        seed,
    )


@dataclass(frozen=True)
class MotionSet:
    """One run of a table row: motions, the captions they were made from, the real motions to compare with.

    Attributes:
        motions: Motion objects or raw (T, 263) features (<= 196 frames), one per caption.
        texts: captions (strings or HumanML3D Caption objects).
        real: real motions, the FID reference (the ground truth of the same samples for generated
            motions; an independent draw for the ground truth itself).
    """

    motions: Sequence[MotionLike]
    texts: Sequence[TextLike]
    real: Sequence[MotionLike]


@dataclass
class Scores:
    """Per-run values of each column; :meth:`summary` gives mean and 95 % CI (1.96 std / sqrt(runs))."""

    values: dict[str, list[float]] = field(default_factory=dict)

    def add(self, run_values: dict[str, float], columns: Sequence[str] = SCORE_COLUMNS) -> None:
        for key in columns:
            if key in run_values:
                self.values.setdefault(key, []).append(float(run_values[key]))

    @property
    def runs(self) -> int:
        return max((len(v) for v in self.values.values()), default=0)

    def summary(self) -> dict[str, tuple[float, float]]:
        """Column -> (mean, 95 % CI half-width)."""
        return {k: M.mean_ci(v) for k, v in self.values.items()}

    def to_json(self) -> dict[str, dict[str, Any]]:
        return {
            k: {"mean": m, "ci95": c, "values": list(self.values[k])} for k, (m, c) in self.summary().items()
        }


def score_motions(
    evaluator: Evaluator,
    runs: MotionSet | Sequence[MotionSet],
    seed: int = 0,
    group: int = M.R_PRECISION_GROUP,
    diversity_times: int = M.DIVERSITY_TIMES,
) -> Scores:
    """R-precision top-1/2/3, FID, MM-Dist and Diversity of each run, with mean and 95 % CI over runs.

    Args:
        evaluator: the text-motion evaluator (:func:`controlmm.eval.evaluator.load_evaluator`).
        runs: one :class:`MotionSet` per repeat (or a single set: one run, CI 0).
        seed: run r groups its pairs and draws its Diversity pairs with seed ``seed + r``.
        group, diversity_times: see :func:`columns_from_embeddings`.

    Returns:
        :class:`Scores` (``summary()``: column -> (mean, ci95)).
    """
    runs = [runs] if isinstance(runs, MotionSet) else list(runs)
    if not runs:
        raise ControlMMError("nothing to score: no runs")
    scores = Scores()
    for r, run in enumerate(runs):
        scores.add(
            quality_columns(evaluator, run.motions, run.texts, run.real, group, diversity_times, seed + r)
        )
    return scores
