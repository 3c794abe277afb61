"""The robot-task families (postures, actions, terrain, sequences): scene geometry in meta that
matches the motion, and captions whose words are true, measured here without the library's probes."""

from __future__ import annotations

import numpy as np
import pytest

from controlmm.corpus import family_names, make_clip
from controlmm.corpus.dataset import ClipSpec

NEW = (
    "sit_down",
    "lie_down",
    "bow",
    "pick_up",
    "kick",
    "stretch_arms",
    "push",
    "look_around",
    "point",
    "carry",
    "step_over",
    "platform",
    "stairs",
    "walk_then_sit",
    "walk_then_kick",
    "walk_then_bow",
    "pick_up_and_carry",
)


def _clip(family: str, index: int, split: str = "train"):
    feats, joints, caps, meta = make_clip(ClipSpec(index, f"{index:06d}", family, split, seed=77))
    return joints.astype(np.float64), caps, meta


def _local(box: dict, points: np.ndarray) -> np.ndarray:
    """Points (..., 3) in a scene box's own frame (x across, y up from its centre, z along)."""
    yaw = np.radians(box["yaw_deg"])
    d = points - np.asarray(box["center"])
    c, s = np.cos(yaw), np.sin(yaw)
    return np.stack([c * d[..., 0] - s * d[..., 2], d[..., 1], s * d[..., 0] + c * d[..., 2]], -1)


def test_the_new_families_are_registered():
    assert set(NEW) <= set(family_names()) and len(family_names()) == 49


@pytest.mark.parametrize("index", [0, 1])
def test_seats_hold_the_seated_pelvis(index):
    for family in ("sit_down", "walk_then_sit"):
        j, caps, meta = _clip(family, index)
        (seat,) = meta["scene"]["boxes"]
        assert meta["scene"]["kind"] == "seat" and meta["scene"]["frame"] == "clip"
        low = int(np.argmin(j[:, 0, 1]))
        rel = _local(seat, j[low, 0])
        top = 0.5 * seat["size"][1]
        assert abs(rel[0]) < 0.5 * seat["size"][0] and abs(rel[2]) < 0.5 * seat["size"][2]  # over the seat
        assert 0.1 < rel[1] - top < 0.25  # sitting on it, not through it
        assert seat["size"][1] == pytest.approx(meta["scene"]["seat_height"], abs=1e-3)


@pytest.mark.parametrize("index", [0, 1, 2])
def test_feet_stand_on_platforms_and_stairs_and_clear_obstacles(index):
    for family in ("platform", "stairs", "step_over"):
        j, caps, meta = _clip(family, index)
        scene = meta["scene"]
        feet = j[:, [7, 8, 10, 11]]
        if family == "step_over":
            (box,) = scene["boxes"]
            rel = _local(box, feet)
            half = 0.5 * np.asarray(box["size"])
            inside = (np.abs(rel) < half).all(-1)
            assert not inside.any()  # no foot joint ever inside the obstacle
            over = (np.abs(rel[..., 0]) < half[0]) & (np.abs(rel[..., 2]) < half[2])
            assert over.any() and (rel[..., 1][over] > half[1]).all()  # the feet pass above it
            continue
        tops = [b["center"][1] + 0.5 * b["size"][1] for b in scene["boxes"]]
        end_level = float(np.median(feet[-5:, :, 1].min(1)))
        start_level = float(np.median(feet[:5, :, 1].min(1)))
        up = scene["direction"] == "up"
        assert (
            all("up" in c.text or "onto" in c.text or "climbs" in c.text or "ascends" in c.text for c in caps)
            == up
        )
        high, low_level = (end_level, start_level) if up else (start_level, end_level)
        assert high == pytest.approx(max(tops) + 0.008, abs=0.02)  # toes on the top surface
        assert low_level == pytest.approx(0.0, abs=0.01)  # and on the floor
        if family == "stairs":
            assert len(scene["boxes"]) == scene["steps"]
            assert max(tops) == pytest.approx(scene["steps"] * scene["step_height"] - 0.008, abs=1e-3)


@pytest.mark.parametrize("index", [0, 1, 2])
def test_kick_point_and_look_captions_are_true(index):
    j, caps, meta = _clip("kick", index)
    leg = meta["params"]["leg"]
    ankle, other = (7, 8) if leg == "left" else (8, 7)
    assert j[:, ankle, 1].max() > 0.3 and j[:, other, 1].max() < 0.1
    assert all(
        f"{leg} leg" in c.text or f"{leg} foot" in c.text
        for c in caps
        if " leg" in c.text or " foot" in c.text
    )
    for family in ("kick", "walk_then_kick"):  # a count is claimed exactly where the words give one
        _, caps, meta = _clip(family, index)
        n = meta["params"]["kick"]["count"] if family == "walk_then_kick" else meta["params"]["count"]
        words = ("once", "one time", "a single", "one kick") if n == 1 else ("twice", "two", "2 ")
        for c in caps:
            assert c.claims.get("count") == (n if any(w in c.text for w in words) else None), c.text

    j, caps, meta = _clip("point", index)
    hand = meta["params"]["hand"]
    wrist, shoulder, other, other_shoulder = (20, 16, 21, 17) if hand == "left" else (21, 17, 20, 16)
    assert np.linalg.norm(j[:, wrist] - j[:, shoulder], axis=-1).max() > 0.45
    assert (j[:, other, 1] - j[:, other_shoulder, 1]).max() < -0.15
    assert all(f"{hand} hand" in c.text or f"{hand} arm" in c.text for c in caps)

    j, caps, meta = _clip("look_around", index)
    across = (j[:, 2] - j[:, 1]) + (j[:, 17] - j[:, 16])
    fwd = np.cross([0.0, 1.0, 0.0], across)
    left = np.cross([0.0, 1.0, 0.0], fwd)
    head = j[:, 15] - j[:, 12]
    yaw = np.degrees(np.arctan2((head * left).sum(-1), (head * fwd).sum(-1)))
    look = meta["params"]["look"]
    assert (yaw.max() > 30) == (look in ("both", "left")) and (yaw.min() < -30) == (look in ("both", "right"))
    assert np.linalg.norm(j[-1, 0, [0, 2]] - j[0, 0, [0, 2]]) < 0.3  # in place


@pytest.mark.parametrize("index", [0, 1])
def test_lying_sitting_and_picking_up_reach_the_floor_without_going_through(index):
    j, caps, meta = _clip("lie_down", index)
    assert j[:, 0, 1].min() < 0.25 and j[:, 15, 1].min() < 0.35  # pelvis and head down at the floor
    body = np.delete(j, [7, 8, 10, 11], axis=1)
    assert body[..., 1].min() > 0.03
    end_standing = j[-1, 0, 1] > 0.8
    assert end_standing == meta["params"]["stand_up"]
    j, caps, meta = _clip("pick_up", index)
    assert j[:, [20, 21], 1].min() < 0.35 and j[-1, 0, 1] > 0.8
    (obj,) = meta["scene"]["boxes"]
    wrists = j[:, [20, 21]]
    near = np.linalg.norm(wrists[..., [0, 2]] - np.asarray(obj["center"])[[0, 2]], axis=-1).min()
    assert near < 0.25  # a hand gets to the object on the floor


def test_every_clip_of_the_new_families_is_drawn_first_time():
    for family in NEW:
        for index in range(2):
            _, _, meta = _clip(family, index, split="test" if index else "train")
            assert meta["retry_reasons"] == [], (family, meta["retry_reasons"])
            assert len(meta["captions"]) == 3
