"""Simulation feedback -> editing loss terms: frames, joints and values on the real HumanML3D sample."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from controlmm.frames import HumanToWorld
from controlmm.motion.skeleton import joint_index
from controlmm.pipeline.feedback import (
    FeedbackConfig,
    contact_loss,
    feedback_terms,
    human_frames,
    lift_loss,
    separation_loss,
    smoothness_loss,
)
from retarget import load_robot, robot_scale
from sim import Failure


@pytest.fixture(scope="module")
def g1_body_joints():
    return load_robot("g1").body_joints


def _grad(term, joints: np.ndarray) -> np.ndarray:
    x = torch.as_tensor(joints, dtype=torch.float64)[None].clone().requires_grad_(True)
    term(x).sum().backward()
    return x.grad[0].abs().sum(-1).numpy()  # (T, 22)


def test_robot_frames_map_to_padded_human_frames():
    assert human_frames(50, 75, 50.0, 196, pad=0) == list(range(20, 31))
    assert human_frames(50, 75, 50.0, 196, pad=3) == list(range(17, 34))
    assert human_frames(0, 4, 50.0, 100, pad=3) == list(range(0, 6))  # ceil(4 * 0.4) + 3; clipped at 0
    assert human_frames(290, 299, 50.0, 120, pad=3) == list(range(113, 120))  # and at the end


def test_floor_failure_lifts_only_the_bodys_joints_over_its_frames(sample_joints, g1_body_joints):
    transform = HumanToWorld(scale=robot_scale("g1"))
    failure = Failure("floor_penetration", 100, 120, "left_ankle_roll_link", "floor", 0.02)
    (term,) = feedback_terms(
        [failure],
        sample_joints,
        body_joints=g1_body_joints,
        transform=transform,
        robot_fps=50.0,
        round_index=0,
    )
    assert term.name.startswith("feedback1:floor_penetration:left_ankle_roll_link")
    grad = _grad(term, sample_joints)
    frames = human_frames(100, 120, 50.0, len(sample_joints), FeedbackConfig().frame_pad)
    outside = np.ones(len(sample_joints), bool)
    outside[frames] = False
    assert grad[outside].sum() == 0
    touched = {j for j in range(22) if grad[frames, j].sum() > 0}
    assert touched and touched <= {joint_index(j) for j in g1_body_joints["left_ankle_roll_link"]}
    assert "left" in " ".join(g1_body_joints["left_ankle_roll_link"])
    # The previous motion violates it; the same motion lifted by the asked amount satisfies it.
    assert float(term(torch.as_tensor(sample_joints)[None])) > 0
    lifted = sample_joints.copy()
    lifted[..., 1] += (0.02 + FeedbackConfig().margin_m) / transform.scale + 1e-4
    assert float(term(torch.as_tensor(lifted)[None])) == 0


def test_self_collision_failure_asks_the_two_bodies_apart(sample_joints, g1_body_joints):
    transform = HumanToWorld(scale=robot_scale("g1"))
    failure = Failure("self_collision", 10, 40, "right_wrist_yaw_link", "right_hip_roll_link", 0.01)
    (term,) = feedback_terms(
        [failure],
        sample_joints,
        body_joints=g1_body_joints,
        transform=transform,
        robot_fps=50.0,
        round_index=1,
    )
    assert term.weight == pytest.approx(FeedbackConfig().weight * FeedbackConfig().growth)
    grad = _grad(term, sample_joints)
    wrist = {joint_index(j) for j in g1_body_joints["right_wrist_yaw_link"]}
    hip = {joint_index(j) for j in g1_body_joints["right_hip_roll_link"]}
    touched = {j for j in range(22) if grad[:, j].sum() > 0}
    assert touched and touched <= wrist | hip
    # Separation grows the distance: the motion itself violates it.
    assert float(term(torch.as_tensor(sample_joints)[None])) > 0


def test_grouping_merges_failures_of_one_body_and_kind(sample_joints, g1_body_joints):
    transform = HumanToWorld(scale=robot_scale("g1"))
    failures = [
        Failure("residual_force", 10, 12, None, None, 0.3),
        Failure("residual_force", 60, 61, None, None, 0.2),
        Failure("foot_sliding", 30, 40, "right_ankle_roll_link", None, 0.02),
    ]
    terms = feedback_terms(
        failures,
        sample_joints,
        body_joints=g1_body_joints,
        transform=transform,
        robot_fps=50.0,
        round_index=0,
    )
    assert len(terms) == 2
    smooth = next(t for t in terms if "residual_force" in t.name)
    grad = _grad(smooth, sample_joints)
    assert grad[:, [0, 3, 6, 9]].sum() > 0 and grad[:, [20, 21, 10, 11]].sum() == 0  # the trunk only
    rows = set(np.nonzero(grad.sum(1))[0])  # acceleration at frame f reaches frames f-1..f+1
    allowed = {
        g
        for f in human_frames(10, 12, 50.0, 170, 3) + human_frames(60, 61, 50.0, 170, 3)
        for g in (f - 1, f, f + 1)
    }
    assert rows and rows <= allowed


def test_losses_are_zero_when_satisfied(sample_joints):
    j = torch.as_tensor(sample_joints)[None]
    frames = list(range(20, 60))
    assert float(lift_loss(sample_joints, [0], frames, 0.0)(j)) == 0
    assert float(separation_loss(sample_joints, [(20, 21)], frames, 0.0)(j)) < 1e-7
    assert float(smoothness_loss(sample_joints, [0], frames, ratio=1.0)(j)) < 1e-7  # float32 rounding only
    still = np.repeat(sample_joints[:1], len(sample_joints), axis=0)
    assert float(contact_loss([7, 10], frames)(torch.as_tensor(still)[None])) == 0
    assert float(contact_loss([7, 10], frames)(j)) > 0  # the sample walks: its feet move


def test_obstacle_failure_uses_a_larger_margin(sample_joints, g1_body_joints):
    from scenes import load_scene

    scene = load_scene("pillars", robot=None)
    transform = scene.human_to_world(robot_scale("g1"))
    failure = Failure("obstacle_penetration", 0, 200, "left_elbow_link", "pillar_2", 0.05)
    small = feedback_terms(
        [failure],
        sample_joints,
        body_joints=g1_body_joints,
        transform=transform,
        robot_fps=50.0,
        round_index=0,
        sdf=scene.sdf(),
        config=FeedbackConfig(margin_m=0.0),
    )[0]
    large = feedback_terms(
        [failure],
        sample_joints,
        body_joints=g1_body_joints,
        transform=transform,
        robot_fps=50.0,
        round_index=0,
        sdf=scene.sdf(),
        config=FeedbackConfig(margin_m=2.0),
    )[0]
    j = torch.as_tensor(sample_joints)[None]
    assert float(large(j)) > float(small(j)) >= 0
    grad = _grad(large, sample_joints)
    assert grad[:, joint_index("left_elbow")].sum() > 0 and grad[:, joint_index("right_ankle")].sum() == 0
