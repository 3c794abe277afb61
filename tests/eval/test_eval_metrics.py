"""The quality metrics on hand-made embeddings with known answers."""

from __future__ import annotations

import numpy as np
import pytest

from controlmm.errors import ControlMMError
from controlmm.eval import metrics as M
from controlmm.eval.quality import columns_from_embeddings


def _exact_gaussian(n: int, mean: np.ndarray, cov: np.ndarray, seed: int = 0) -> np.ndarray:
    """Samples whose sample mean and covariance (np.cov) are exactly ``mean`` and ``cov``."""
    d = len(mean)
    x = np.random.default_rng(seed).normal(size=(n, d))
    x -= x.mean(0)
    x = x @ np.linalg.inv(np.linalg.cholesky(np.cov(x, rowvar=False))).T  # whiten: cov = I
    return x @ np.linalg.cholesky(cov).T + mean


def test_fid_is_zero_for_identical_sets_and_known_for_shifted_gaussians():
    x = np.random.default_rng(1).normal(size=(500, 8))
    assert M.fid(x, x) == pytest.approx(0.0, abs=1e-8)
    shift = np.array([3.0, -1.0, 0, 0, 0, 0, 0, 2.0])
    assert M.fid(x, x + shift) == pytest.approx(float(shift @ shift), rel=1e-9)  # 14
    # Different covariances: diag(a) vs diag(b) -> sum((sqrt(a) - sqrt(b))^2) + |dmu|^2
    a, b = np.array([1.0, 4.0, 9.0]), np.array([4.0, 4.0, 1.0])
    p = _exact_gaussian(400, np.zeros(3), np.diag(a), seed=2)
    q = _exact_gaussian(300, np.array([1.0, 0.0, 0.0]), np.diag(b), seed=3)
    assert M.fid(p, q) == pytest.approx(1.0 + 1.0 + 0.0 + 4.0, rel=1e-9)
    assert M.frechet_distance(np.zeros(3), np.diag(a), np.zeros(3), np.diag(a)) == pytest.approx(
        0.0, abs=1e-12
    )


def test_fid_of_singular_covariances_is_finite():
    x = np.random.default_rng(0).normal(size=(50, 3))
    flat = np.concatenate([x[:, :2], np.zeros((50, 1))], axis=1)  # rank-deficient covariance
    assert np.isfinite(M.fid(flat, flat + 1.0))
    assert M.fid(flat, flat + 1.0) == pytest.approx(3.0, abs=1e-3)


def test_r_precision_perfect_shuffled_and_second_nearest():
    rng = np.random.default_rng(0)
    motions = rng.normal(size=(96, 16)) * 10
    perfect = M.matching_metrics(motions + 0.01, motions)
    assert perfect.r_precision == (1.0, 1.0, 1.0) and perfect.pairs == 96
    assert perfect.mm_dist == pytest.approx(0.01 * 4.0)  # |0.01 * ones(16)| = 0.04
    # Text i sits nearest to motion i+1 (within its group of 32), second nearest to its own motion.
    base = np.eye(32) * 10.0
    own = np.roll(base, 1, axis=0)  # motion i = 10 e_(i-1)
    text = (
        0.6 * base + 0.4 * own
    )  # 4 sqrt(2) from motion i+1 (10 e_i), 6 sqrt(2) from its own, 12.3 from others
    m = M.matching_metrics(text, own)
    assert m.r_precision[0] == 0.0 and m.r_precision[1] == 1.0 and m.r_precision[2] == 1.0
    # Random embeddings: chance level 1/32, 2/32, 3/32.
    t, mo = rng.normal(size=(32 * 300, 4)), rng.normal(size=(32 * 300, 4))
    chance = M.matching_metrics(t, mo).r_precision
    for k, value in enumerate(chance, start=1):
        assert value == pytest.approx(k / 32, abs=0.01)


def test_r_precision_drops_incomplete_group_and_checks_shapes():
    x = np.random.default_rng(0).normal(size=(70, 4))
    assert M.matching_metrics(x, x).pairs == 64
    with pytest.raises(ControlMMError, match="at least 32"):
        M.matching_metrics(x[:10], x[:10])
    with pytest.raises(ControlMMError, match="differ in shape"):
        M.matching_metrics(x, x[:, :3])
    with pytest.raises(ControlMMError, match="NaN"):
        M.matching_metrics(np.full((32, 2), np.nan), np.zeros((32, 2)))


def test_diversity_and_multimodality():
    rng = np.random.default_rng(0)
    same = np.ones((400, 5))
    assert M.diversity(same) == 0.0
    points = rng.normal(size=(400, 5))
    r = np.random.default_rng(3)
    first, second = r.choice(400, 300, replace=False), r.choice(400, 300, replace=False)
    expected = np.linalg.norm(points[first] - points[second], axis=1).mean()
    assert M.diversity(points, 300, np.random.default_rng(3)) == pytest.approx(expected)
    # Two clusters 10 apart: pairs across clusters are 10 apart, within 0.
    two = np.concatenate([np.zeros((200, 2)), np.full((200, 2), 10 / np.sqrt(2))])
    assert 3.0 < M.diversity(two, 300, np.random.default_rng(0)) < 7.0
    with pytest.raises(ControlMMError, match="more than 300"):
        M.diversity(points[:300])
    mm = np.repeat(rng.normal(size=(6, 1, 4)), 12, axis=1)  # every generation of a text identical
    assert M.multimodality(mm) == 0.0
    spread = mm + rng.normal(size=mm.shape)
    assert M.multimodality(spread) > 0.5
    with pytest.raises(ControlMMError, match="more than 10"):
        M.multimodality(mm[:, :10])


def test_mean_ci():
    mean, ci = M.mean_ci([1.0, 2.0, 3.0])
    assert mean == 2.0 and ci == pytest.approx(1.96 * np.std([1, 2, 3]) / np.sqrt(3))
    assert M.mean_ci([5.0]) == (5.0, 0.0)


def test_columns_from_embeddings_small_sets_use_smaller_groups():
    rng = np.random.default_rng(0)
    motion = rng.normal(size=(20, 6)) * 5
    cols = columns_from_embeddings(motion, motion, motion, seed=0)
    assert cols["r_precision_top1"] == 1.0 and cols["fid"] == pytest.approx(0.0, abs=1e-8)
    assert cols["r_precision_group"] == 20 and cols["diversity_pairs"] == 19 and cols["samples"] == 20
    assert cols["mm_dist"] == pytest.approx(0.0, abs=1e-6)
