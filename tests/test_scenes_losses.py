"""Obstacle (Eq. 9), body-volume and floor losses on the real HumanML3D sample."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from controlmm.control import LossTerm, total_loss
from controlmm.errors import ControlMMError
from controlmm.frames import HumanToWorld
from scenes import body_obstacle_loss, body_points, floor_loss, load_scene, obstacle_loss, scene_loss_terms

SCALE = 0.78  # a G1-like human -> robot scale


@pytest.fixture(scope="module")
def joints(sample_joints):
    return torch.as_tensor(sample_joints[:60], dtype=torch.float64)[None]  # (1, 60, 22, 3)


@pytest.fixture(scope="module")
def beam():
    return load_scene("low_beam", robot=None)


def _descend(term: LossTerm, joints: torch.Tensor, steps: int = 5, lr: float = 0.05) -> list[float]:
    x = joints.clone().requires_grad_(True)
    values = []
    for _ in range(steps):
        loss = term(x).sum()
        values.append(float(loss.detach()))
        (grad,) = torch.autograd.grad(loss, x)
        with torch.no_grad():
            x -= lr * grad / grad.norm().clamp_min(1e-12)
    values.append(float(term(x).sum().detach()))
    return values


def test_losses_are_zero_when_clear(beam, joints):
    tf = beam.human_to_world(SCALE)  # the sample motion stays 1.8 m before the beam
    for term in (
        obstacle_loss(beam.sdf(), tf),
        body_obstacle_loss(beam.sdf(), tf),
        floor_loss(tf, beam.floor_height),
    ):
        value = term(joints)
        assert value.shape == (1,) and float(value) == 0.0


def test_penetration_is_positive_and_decreases_along_the_gradient(beam, joints):
    tf = HumanToWorld(scale=SCALE, translation=(2.3, 0.0, 0.0))  # walks into the beam
    for term in (obstacle_loss(beam.sdf(), tf, safe_distance=0.05), body_obstacle_loss(beam.sdf(), tf)):
        values = _descend(term, joints)
        assert values[0] > 0 and values[-1] < values[0] and all(np.diff(values) <= 1e-12), (term.name, values)
    sunk = HumanToWorld(scale=SCALE, translation=(0.0, 0.0, -0.1))
    values = _descend(floor_loss(sunk), joints)
    assert values[0] > 0 and values[-1] < values[0]


def test_distances_are_world_metres_through_the_transform(joints):
    """A sphere at the scaled pelvis: the loss equals d - SDF in world metres, any scale/yaw."""
    sphere_xml = (
        '<mujoco><worldbody><body name="s" pos="{} {} {}"><geom type="sphere" size="0.1"/></body>'
        "</worldbody></mujoco>"
    )
    for scale, yaw in [(0.78, 0.0), (1.2, 1.0)]:
        tf = HumanToWorld(scale=scale, yaw=yaw, translation=(1.0, -2.0, 0.0))
        pelvis_world = tf.to_world(joints[0, 0, 0].numpy())
        centre = pelvis_world + [0.25, 0.0, 0.0]
        import mujoco

        from scenes import SceneSDF

        model = mujoco.MjModel.from_xml_string(sphere_xml.format(*centre))
        term = obstacle_loss(SceneSDF(model), tf, safe_distance=0.3, joints=["pelvis"], frames=[0])
        assert float(term(joints)) == pytest.approx(0.3 - (0.25 - 0.1), abs=1e-9)


def test_body_volume_catches_a_forearm_between_clear_joints(joints):
    """A thin bar through the middle of the right forearm: joint centres clear, the bone is not."""
    tf = HumanToWorld(scale=SCALE)
    frame = joints[0, 0].numpy()
    elbow, wrist = tf.to_world(frame[19]), tf.to_world(frame[21])
    mid = (elbow + wrist) / 2
    import mujoco

    from scenes import SceneSDF

    xml = (
        '<mujoco><worldbody><body name="bar" pos="{} {} {}"><geom type="capsule" size="0.01 0.3" '
        'euler="90 0 0"/></body></worldbody></mujoco>'
    ).format(*mid)
    sdf = SceneSDF(mujoco.MjModel.from_xml_string(xml))
    joint_term = obstacle_loss(sdf, tf, safe_distance=0.02, frames=[0])
    body_term = body_obstacle_loss(sdf, tf, safe_distance=0.0, frames=[0])
    assert float(joint_term(joints)) == 0.0
    assert float(body_term(joints)) > 0.0


def test_moving_obstacle_loss_depends_on_timing(joints):
    scene = load_scene("moving_obstacle", robot=None)
    # Stand still at the crossing point: frames 0..59 (0-3 s) see the cart pass at 2.5 s.
    still = joints[:, :1].expand(1, 60, 22, 3).contiguous()
    tf = HumanToWorld(scale=SCALE, translation=(2.2, 0.0, 0.0))
    hit = body_obstacle_loss(scene.sdf(), tf)(still)
    late = body_obstacle_loss(scene.sdf(), tf, time_offset=6.0)(still)  # the cart has passed
    assert float(hit) > 0.0 and float(late) == 0.0


def test_terms_work_with_the_editing_interface(beam, joints):
    tf = HumanToWorld(scale=SCALE, translation=(2.3, 0.0, 0.0))
    terms = scene_loss_terms(beam, tf)
    assert [t.name for t in terms] == ["body_obstacle:low_beam", "floor"]
    batch = torch.cat([joints, joints], dim=0).float()
    total = total_loss(terms, batch)
    assert total.shape == (2,) and total.dtype == torch.float32 and torch.all(total > 0)
    assert len(scene_loss_terms(load_scene("empty", robot=None), tf)) == 1  # floor only


def test_body_points_and_errors(beam):
    weights, radii = body_points()
    assert weights.shape[1] == 22 and len(weights) == len(radii) > 60
    assert np.allclose(weights.sum(1), 1.0)
    term = obstacle_loss(beam.sdf(), HumanToWorld(scale=SCALE))
    with pytest.raises(ControlMMError, match=r"\(B, T, 22, 3\)"):
        term(torch.zeros(5, 22, 3))
    with pytest.raises(ControlMMError, match="NaN"):
        term(torch.full((1, 2, 22, 3), float("nan")))
    with pytest.raises(ControlMMError, match="unknown joint"):
        obstacle_loss(beam.sdf(), HumanToWorld(), joints=["tail"])
    with pytest.raises(ControlMMError, match="finite"):
        floor_loss(HumanToWorld(), clearance=float("inf"))
