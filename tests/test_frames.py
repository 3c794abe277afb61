import numpy as np
import pytest
import torch

from controlmm.errors import ControlMMError
from controlmm.frames import HumanToWorld, human_to_world_axes, world_to_human_axes


def test_canonical_axes():
    forward, left, up = np.eye(3)[2], np.eye(3)[0], np.eye(3)[1]  # human +Z, +X, +Y
    assert np.array_equal(human_to_world_axes(forward), [1, 0, 0])
    assert np.array_equal(human_to_world_axes(left), [0, 1, 0])
    assert np.array_equal(human_to_world_axes(up), [0, 0, 1])
    p = np.random.default_rng(0).normal(size=(7, 3))
    assert np.array_equal(world_to_human_axes(human_to_world_axes(p)), p)


def test_transform_round_trip_numpy_and_torch():
    tf = HumanToWorld(scale=0.75, yaw=0.4, translation=(1.0, -2.0, 0.0))
    assert np.isclose(np.linalg.det(tf.rotation), 1.0)
    p = np.random.default_rng(1).normal(size=(4, 5, 3))
    assert np.allclose(tf.to_human(tf.to_world(p)), p)
    pt = torch.tensor(p, requires_grad=True)
    w = tf.to_world(pt)
    assert torch.allclose(w, torch.tensor(tf.to_world(p)))
    w.sum().backward()
    assert pt.grad is not None
    # Distances scale by the scale factor.
    assert np.isclose(
        np.linalg.norm(tf.to_world(p[0, 0]) - tf.to_world(p[0, 1])), 0.75 * np.linalg.norm(p[0, 0] - p[0, 1])
    )
    assert tf.distance_to_human(0.75) == pytest.approx(1.0)


def test_yaw_turns_forward():
    tf = HumanToWorld(yaw=np.pi / 2)
    assert np.allclose(tf.to_world(np.array([0.0, 0.0, 1.0])), [0.0, 1.0, 0.0])


def test_bad_scale():
    with pytest.raises(ControlMMError, match="scale"):
        HumanToWorld(scale=0.0)
