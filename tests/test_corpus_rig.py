"""The corpus body rig: rotations, two-bone IK, rolling feet."""

from __future__ import annotations

import numpy as np

from controlmm.corpus.feet import (
    HEEL_LOCAL,
    Stance,
    ankle_from_pivot,
    foot_track,
    heel_position,
    toe_position,
)
from controlmm.corpus.rig import heading_vectors, rot_y, two_bone_ik


def test_positive_yaw_turns_forward_towards_the_persons_left():
    fwd, left = heading_vectors(np.array([0.0, np.pi / 2]))
    np.testing.assert_allclose(fwd[0], [0, 0, 1], atol=1e-12)
    np.testing.assert_allclose(left[0], [1, 0, 0], atol=1e-12)  # +X is the person's left
    np.testing.assert_allclose(fwd[1], [1, 0, 0], atol=1e-12)  # after a left turn, facing +X
    np.testing.assert_allclose(rot_y(np.array(np.pi / 2)) @ [0, 0, 1], [1, 0, 0], atol=1e-12)


def test_two_bone_ik_keeps_lengths_bends_towards_pole_and_clamps():
    rng = np.random.default_rng(0)
    root = rng.normal(size=(200, 3))
    target = root + rng.normal(size=(200, 3)) * 0.6  # some out of reach, some very close
    pole = rng.normal(size=(200, 3))
    mid, end = two_bone_ik(root, target, pole, 0.39, 0.43, max_reach=0.99)
    np.testing.assert_allclose(np.linalg.norm(mid - root, axis=-1), 0.39, atol=1e-9)
    np.testing.assert_allclose(np.linalg.norm(end - mid, axis=-1), 0.43, atol=1e-9)
    assert np.linalg.norm(end - root, axis=-1).max() <= 0.99 * 0.82 + 1e-9
    axis = (end - root) / np.linalg.norm(end - root, axis=-1, keepdims=True)
    off = (mid - root) - ((mid - root) * axis).sum(-1, keepdims=True) * axis
    pole_perp = pole - (pole * axis).sum(-1, keepdims=True) * axis
    assert np.all((off * pole_perp).sum(-1) > 0)  # never bends against the pole (no hyper-extension)
    reachable = np.linalg.norm(target - root, axis=-1) < 0.8
    np.testing.assert_allclose(end[reachable], target[reachable], atol=1e-9)


def test_planted_foot_rolls_about_a_fixed_toe_or_heel():
    flat = np.array([0.3, 0.055, 1.0])
    heel_up = np.linspace(0.0, -1.0, 20)  # push-off / tucked toes: pivot on the toe
    toe_up = np.linspace(0.0, 0.4, 20)  # heel strike: pivot on the heel
    yaw = 0.7
    a = ankle_from_pivot("left", flat, np.full(20, yaw), heel_up)
    toes = toe_position("left", a, np.full(20, yaw), heel_up)
    assert np.ptp(toes, axis=0).max() < 1e-12
    b = ankle_from_pivot("right", flat, np.full(20, yaw), toe_up)
    heels = heel_position(b, np.full(20, yaw), toe_up)
    assert np.ptp(heels, axis=0).max() < 1e-12
    np.testing.assert_allclose(heels[0], flat + rot_y(np.array(yaw)) @ HEEL_LOCAL, atol=1e-12)


def test_swing_clears_the_floor_and_lands_where_planned():
    t = np.arange(40) / 20.0
    a = Stance(-np.inf, 0.5, np.array([0.0, 0.0]), 0.0, lift_pitch=-0.6, lift_time=0.2)
    b = Stance(0.9, np.inf, np.array([0.0, 0.7]), 0.0, land_pitch=0.3, clearance=0.08)
    track = foot_track("left", [a, b], t)
    toes = toe_position("left", track.ankle, track.yaw, track.pitch)
    heels = heel_position(track.ankle, track.yaw, track.pitch)
    assert toes[:, 1].min() >= 0.008 - 1e-9 and heels[:, 1].min() >= -1e-9
    np.testing.assert_allclose(track.ankle[-1], [0.0, 0.055, 0.7], atol=1e-9)
    assert track.planted[:10].all() and not track.planted[11:18].any() and track.planted[19:].all()
