"""Text-motion quality metrics on evaluator embeddings (Guo et al. 2022, as MoMask and MaskControl).

Pure NumPy/SciPy functions of embedding arrays; the evaluator that produces the embeddings and
the evaluation passes that feed them live in :mod:`controlmm.eval.quality`.

- **R-precision top-k**: within each group of ``group`` (32) pairs, the Euclidean distances
  text x motion (32 x 32); a text scores a hit at k when its own motion is among the k nearest;
  hits summed over groups / number of pairs. A final incomplete group is dropped.
- **MM-Dist** (matching score): mean distance between each text and its own motion.
- **FID**: Frechet distance between Gaussian fits (mean, covariance) of two embedding sets.
- **Diversity**: mean distance over ``times`` (300) random pairs (two independent draws without
  replacement).
- **Multimodality**: for embeddings (texts, repeats, D) of several generations per text, the mean
  distance over ``times`` (10) random pairs of generations of the same text.
- Repeated runs are summarised by the mean and the 95 % confidence interval 1.96 std / sqrt(n)
  (:func:`mean_ci`; std with ``ddof=0``, as the official scripts).
"""

from __future__ import annotations

import warnings
from collections.abc import Iterable
from dataclasses import dataclass

import numpy as np
from scipy import linalg

from controlmm.errors import ControlMMError

R_PRECISION_GROUP = 32
DIVERSITY_TIMES = 300
MULTIMODALITY_TIMES = 10


def _matrix(x: np.ndarray, name: str) -> np.ndarray:
    x = np.asarray(x, dtype=np.float64)
    if x.ndim != 2:
        raise ControlMMError(f"{name} must be a 2-D array (N, D); got shape {x.shape}")
    if not np.all(np.isfinite(x)):
        raise ControlMMError(f"{name} holds NaN/inf values")
    return x


def euclidean_distance_matrix(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(N, D), (M, D) -> (N, M) Euclidean distances."""
    a, b = _matrix(a, "a"), _matrix(b, "b")
    d2 = (a * a).sum(1)[:, None] + (b * b).sum(1)[None, :] - 2.0 * a @ b.T
    return np.sqrt(np.maximum(d2, 0.0))


def top_k_hits(dist: np.ndarray, top_k: int = 3) -> np.ndarray:
    """(N, N) text x motion distances -> (N, top_k) bool: row i's motion i is within its k nearest.

    Ties are broken by index order (a stable sort), as ``np.argsort`` in the official code. With fewer
    than ``top_k`` motions, every k >= N is a hit.
    """
    order = np.argsort(dist, axis=1, kind="stable")[:, :top_k]
    hits = np.cumsum(order == np.arange(len(dist))[:, None], axis=1) > 0
    if hits.shape[1] < top_k:
        hits = np.concatenate([hits, np.ones((len(dist), top_k - hits.shape[1]), dtype=bool)], axis=1)
    return hits


@dataclass(frozen=True)
class Matching:
    """R-precision top-1..k and MM-Dist of a set of (text, motion) pairs."""

    r_precision: tuple[float, ...]  # top-1, top-2, top-3
    mm_dist: float
    pairs: int  # pairs used (a multiple of the group size)


def matching_metrics(
    text_emb: np.ndarray, motion_emb: np.ndarray, group: int = R_PRECISION_GROUP, top_k: int = 3
) -> Matching:
    """R-precision and MM-Dist of pairs (text_emb[i], motion_emb[i]) in consecutive groups of ``group``.

    Callers shuffle the pairs first (the official loader draws random batches of 32).
    """
    t, m = _matrix(text_emb, "text embeddings"), _matrix(motion_emb, "motion embeddings")
    if t.shape != m.shape:
        raise ControlMMError(f"text and motion embeddings differ in shape: {t.shape} vs {m.shape}")
    n = len(t) // group * group
    if n == 0:
        raise ControlMMError(f"R-precision needs at least {group} pairs; got {len(t)}")
    hits = np.zeros(top_k)
    dist_sum = 0.0
    for start in range(0, n, group):
        dist = euclidean_distance_matrix(t[start : start + group], m[start : start + group])
        dist_sum += float(np.trace(dist))
        hits += top_k_hits(dist, top_k).sum(axis=0)
    return Matching(tuple(float(h / n) for h in hits), dist_sum / n, n)


def activation_statistics(emb: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Mean (D,) and covariance (D, D) of embeddings (N, D) (``np.cov``, N - 1 normalisation)."""
    emb = _matrix(emb, "embeddings")
    if len(emb) < 2:
        raise ControlMMError(f"a covariance needs at least 2 embeddings; got {len(emb)}")
    return emb.mean(axis=0), np.cov(emb, rowvar=False)


def frechet_distance(
    mu1: np.ndarray, sigma1: np.ndarray, mu2: np.ndarray, sigma2: np.ndarray, eps: float = 1e-6
) -> float:
    """||mu1 - mu2||^2 + tr(S1 + S2 - 2 (S1 S2)^(1/2)) of two Gaussians.

    When the product of the covariances is singular, ``eps`` is added to both diagonals (as the
    official code); a tiny imaginary part of the matrix square root from round-off is dropped.
    """
    mu1, mu2 = np.atleast_1d(mu1), np.atleast_1d(mu2)
    sigma1, sigma2 = np.atleast_2d(sigma1), np.atleast_2d(sigma2)
    if mu1.shape != mu2.shape or sigma1.shape != sigma2.shape:
        raise ControlMMError(f"Gaussians of different sizes: {mu1.shape} vs {mu2.shape}")
    diff = mu1 - mu2
    with warnings.catch_warnings():  # a singular product is handled below, not worth a warning
        warnings.simplefilter("ignore", linalg.LinAlgWarning)
        covmean = linalg.sqrtm(sigma1 @ sigma2)
        if not np.all(np.isfinite(covmean)):
            offset = np.eye(len(sigma1)) * eps
            covmean = linalg.sqrtm((sigma1 + offset) @ (sigma2 + offset))
    if np.iscomplexobj(covmean):
        if not np.allclose(np.diagonal(covmean).imag, 0.0, atol=1e-3):
            raise ControlMMError(
                f"FID: the covariance square root has an imaginary part {np.max(np.abs(covmean.imag)):.3g}"
            )
        covmean = covmean.real
    traces = float(np.trace(sigma1) + np.trace(sigma2))
    value = float(diff @ diff + traces - 2.0 * np.trace(covmean))
    # Round-off of the matrix square root (large for rank-deficient covariances, N <= D) can push the
    # distance of identical sets slightly below zero.
    return 0.0 if -1e-6 * max(traces, 1.0) < value < 0.0 else value


def fid(reference: np.ndarray, generated: np.ndarray) -> float:
    """Frechet distance between Gaussian fits of two embedding sets (N1, D) and (N2, D)."""
    return frechet_distance(*activation_statistics(reference), *activation_statistics(generated))


def diversity(emb: np.ndarray, times: int = DIVERSITY_TIMES, rng: np.random.Generator | None = None) -> float:
    """Mean distance over ``times`` random pairs of embeddings (N > times required)."""
    emb = _matrix(emb, "embeddings")
    if len(emb) <= times:
        raise ControlMMError(f"diversity over {times} pairs needs more than {times} motions; got {len(emb)}")
    rng = rng or np.random.default_rng()
    first = rng.choice(len(emb), times, replace=False)
    second = rng.choice(len(emb), times, replace=False)
    return float(np.linalg.norm(emb[first] - emb[second], axis=1).mean())


def multimodality(
    emb: np.ndarray, times: int = MULTIMODALITY_TIMES, rng: np.random.Generator | None = None
) -> float:
    """Embeddings (texts, repeats, D) of several generations per text -> mean distance over ``times``
    random pairs of generations (the same pair indices for every text; repeats > times required)."""
    emb = np.asarray(emb, dtype=np.float64)
    if emb.ndim != 3:
        raise ControlMMError(f"multimodality needs embeddings (texts, repeats, D); got shape {emb.shape}")
    if emb.shape[1] <= times:
        raise ControlMMError(
            f"multimodality over {times} pairs needs more than {times} generations per text; "
            f"got {emb.shape[1]}"
        )
    rng = rng or np.random.default_rng()
    first = rng.choice(emb.shape[1], times, replace=False)
    second = rng.choice(emb.shape[1], times, replace=False)
    return float(np.linalg.norm(emb[:, first] - emb[:, second], axis=2).mean())


def mean_ci(values: Iterable[float]) -> tuple[float, float]:
    """Mean and 95 % confidence half-width 1.96 std / sqrt(n) of repeated runs (std with ddof 0)."""
    v = np.asarray(list(values), dtype=np.float64)
    if v.size == 0:
        return float("nan"), float("nan")
    return float(v.mean()), float(1.96 * v.std() / np.sqrt(v.size))
