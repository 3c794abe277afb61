import numpy as np

from controlmm.motion.quaternion import (
    cont6d_to_matrix,
    matrix_to_quat,
    qbetween,
    qinv,
    qmul,
    qrot,
    quat_to_cont6d,
    quat_to_matrix,
)


def test_qbetween_maps_a_to_b_including_opposite():
    rng = np.random.default_rng(0)
    a = rng.normal(size=(100, 3))
    b = rng.normal(size=(100, 3))
    b[:5] = -a[:5] * 2.0  # opposite directions
    q = qbetween(a, b)
    rotated = qrot(q, a / np.linalg.norm(a, axis=-1, keepdims=True))
    assert np.allclose(rotated, b / np.linalg.norm(b, axis=-1, keepdims=True), atol=1e-9)


def test_matrix_6d_and_quaternion_agree():
    rng = np.random.default_rng(1)
    q = rng.normal(size=(50, 4))
    q /= np.linalg.norm(q, axis=-1, keepdims=True)
    v = rng.normal(size=(50, 3))
    assert np.allclose(quat_to_matrix(q) @ v[..., None], qrot(q, v)[..., None])
    assert np.allclose(cont6d_to_matrix(quat_to_cont6d(q)), quat_to_matrix(q))
    back = matrix_to_quat(quat_to_matrix(q))
    assert np.allclose(np.abs((back * q).sum(-1)), 1.0)
    assert np.allclose(qmul(q, qinv(q)), [1, 0, 0, 0], atol=1e-12)
