"""Simulation feedback: every failure of a check becomes an extra editing loss on the human joints.

A :class:`sim.Failure` names a robot body, a frame range at the robot's rate and a depth. The
retargeter's mapping says which human joints each robot body follows
(``retarget.load_robot(robot).body_joints``), so a failure turns into a :class:`LossTerm` on
those joints over the matching human frames (20 fps, padded by ``frame_pad`` each side):

======================  ===================================================================
failure kind            loss term (world metres unless stated; 0 when satisfied)
======================  ===================================================================
obstacle_penetration    body-volume SDF loss on the body's bones with a larger safe distance
                        (scene margin + depth + ``margin_m``, accumulating over rounds while
                        the same body keeps penetrating)
floor_penetration       *lift*: the body's joints at least depth + margin higher than in the
                        failed round
self_collision          *separation*: the two bodies' joints at least (depth + margin) / scale
                        (human metres) further apart than in the failed round
foot_sliding            *contact*: the stance foot's joints (ankle, toes) do not move
                        horizontally over the range
floating                *support*: the lowest foot joint no higher than in the round's stance
                        frames (5th percentile)
dynamics and limits     *smoothness*: the body's joints' accelerations (and the pelvis'; the
(residual_force,        trunk's for a whole-robot wrench) at most half the failed round's
residual_moment,        (a physics fall or a tracking-error span of the root smooths the trunk
torque_limit,           and pelvis; a foot's or a hand's span that limb)
joint_velocity,
joint_limit,
tracking_fall,
tracking_error)
======================  ===================================================================

Terms built from the failed round's motion (lift, separation, support, smoothness) compare with
that motion's joints, so they ask for a *change* of the size the robot needed.
Weights grow with the round (``weight * growth ** round``) so a failure that persists gets more
of the editors' attention.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
import torch

from controlmm.control.terms import LossTerm
from controlmm.frames import HumanToWorld
from controlmm.motion.skeleton import FPS, JOINT_NAMES, PARENTS, joint_index
from scenes.losses import BODY_BONES, body_obstacle_loss

Tensor = torch.Tensor

FOOT_JOINTS = {"left": ("left_ankle", "left_foot"), "right": ("right_ankle", "right_foot")}
TRUNK = [0, 3, 6, 9]  # pelvis and spine: where a whole-body (root wrench) failure is smoothed
SMOOTH_KINDS = (
    "residual_force",
    "residual_moment",
    "torque_limit",
    "joint_velocity",
    "joint_limit",
    "tracking_fall",
    "tracking_error",
)


@dataclass(frozen=True)
class FeedbackConfig:
    """How failures become loss terms.

    Attributes:
        margin_m: extra clearance (world m) asked for beyond the measured depth.
        frame_pad: human frames added before and after a failure's range.
        weight: base weight of a feedback term; ``growth`` multiplies it each round.
        obstacle_distance_m: the scene's own safe distance (world m) the obstacle margin adds to.
    """

    margin_m: float = 0.03
    frame_pad: int = 3
    weight: float = 1.0
    growth: float = 2.0
    obstacle_distance_m: float = 0.03


def human_frames(
    frame_start: int, frame_end: int, robot_fps: float, num_frames: int, pad: int, fps: float = FPS
) -> list[int]:
    """Human frames (at ``fps``) covering robot frames ``frame_start..frame_end`` (inclusive) +- pad."""
    lo = math.floor(frame_start * fps / robot_fps) - pad
    hi = math.ceil(frame_end * fps / robot_fps) + pad
    return list(range(max(lo, 0), min(hi, num_frames - 1) + 1))


def body_human_joints(body_joints: Mapping[str, Sequence[str]], body: str | None) -> list[int]:
    """Human joint indices a robot body follows (the whole skeleton for None or an unknown body)."""
    if body is None or body not in body_joints:
        return list(range(len(JOINT_NAMES)))
    return sorted({joint_index(j) for j in body_joints[body]})


def feedback_terms(
    failures: Sequence,
    previous: np.ndarray,
    *,
    body_joints: Mapping[str, Sequence[str]],
    transform: HumanToWorld,
    robot_fps: float,
    round_index: int,
    sdf=None,
    config: FeedbackConfig = FeedbackConfig(),
    history: dict | None = None,
) -> list[LossTerm]:
    """Loss terms that ask the next round to fix ``failures``.

    Args:
        failures: :class:`sim.Failure` list of the failed round (frames at ``robot_fps``).
        previous: (T, 22, 3) human joints of the failed round (human frame, 20 fps).
        body_joints: robot body name -> human joint names (``retarget.load_robot(r).body_joints``).
        transform: human -> world placement used for that round (its scale is the robot's).
        robot_fps: frame rate of the checked trajectory.
        round_index: 0 for the first feedback round (weights grow with it).
        sdf: the scene's SDF (``scene.sdf()``), needed for obstacle penetrations.
        history: a dict kept across rounds by the caller: the extra obstacle clearance asked for each
            robot body so far. A body that still penetrates although its last term was met needs
            that clearance plus the new depth (the human body volume does not cover that robot
            part by at least this much), so obstacle margins accumulate over rounds.

    Returns:
        One term per (kind, robot body[, other body]) over the union of its failures' frames
        (kinds the loop cannot act on give none).
    """
    previous = np.asarray(previous, dtype=np.float32)
    num_frames = previous.shape[0]
    weight = config.weight * config.growth**round_index
    groups: dict[tuple[str, str | None, str | None], tuple[set[int], float]] = {}
    for failure in failures:  # one term per (kind, body, other): the union of their frames, the worst depth
        frames = human_frames(failure.frame_start, failure.frame_end, robot_fps, num_frames, config.frame_pad)
        key = (
            failure.kind,
            failure.robot_body,
            failure.obstacle_geom if failure.kind == "self_collision" else None,
        )
        have, depth = groups.get(key, (set(), 0.0))
        groups[key] = (have | set(frames), max(depth, float(failure.depth)))
    terms: list[LossTerm] = []
    for (kind, body, other), (frame_set, depth) in groups.items():
        frames = sorted(frame_set)
        if not frames:
            continue
        joints = body_human_joints(body_joints, body)
        label = f"feedback{round_index + 1}:{kind}:{body or 'robot'}"
        if kind == "obstacle_penetration" and sdf is not None:
            bones = [b for b in BODY_BONES if b.child in joints] or list(BODY_BONES)
            extra = (
                (history.get(("obstacle", body), 0.0) if history is not None else 0.0)
                + depth
                + config.margin_m
            )
            if history is not None:
                history[("obstacle", body)] = extra
            distance = config.obstacle_distance_m + extra
            terms.append(
                body_obstacle_loss(
                    sdf,
                    transform,
                    safe_distance=distance,
                    bones=bones,
                    frames=frames,
                    weight=weight,
                    name=label,
                )
            )
        elif kind == "floor_penetration":
            terms.append(
                lift_loss(
                    previous,
                    joints,
                    frames,
                    (depth + config.margin_m) / transform.scale,
                    weight=weight,
                    name=label,
                )
            )
        elif kind == "self_collision":
            others = body_human_joints(body_joints, other)
            pairs = [(a, b) for a in joints for b in others if a != b and PARENTS[a] != b and PARENTS[b] != a]
            if pairs:
                terms.append(
                    separation_loss(
                        previous,
                        pairs,
                        frames,
                        (depth + config.margin_m) / transform.scale,
                        weight=weight,
                        name=f"{label}:{other}",
                    )
                )
        elif kind == "foot_sliding":
            side = _side(body)
            feet = [joint_index(j) for s in ((side,) if side else ("left", "right")) for j in FOOT_JOINTS[s]]
            terms.append(contact_loss(feet, frames, weight=weight, name=label))
        elif kind == "floating":
            feet = [joint_index(j) for s in ("left", "right") for j in FOOT_JOINTS[s]]
            height = float(np.percentile(previous[:, feet, 1].min(axis=1), 5))
            terms.append(support_loss(feet, frames, height, weight=weight, name=label))
        elif kind in SMOOTH_KINDS:
            ids = TRUNK if body is None else sorted(set(joints) | {0})
            terms.append(smoothness_loss(previous, ids, frames, weight=weight, name=label))
    return terms


def _side(body: str | None) -> str | None:
    if not body:
        return None
    name = body.lower()
    return "left" if "left" in name else "right" if "right" in name else None


def _index(frames: Sequence[int], num_frames: int, device: torch.device) -> Tensor:
    return torch.tensor([f for f in frames if f < num_frames], dtype=torch.long, device=device)


def lift_loss(
    previous: np.ndarray,
    joints: Sequence[int],
    frames: Sequence[int],
    lift: float,
    weight: float = 1.0,
    name: str = "lift",
) -> LossTerm:
    """Joints at least ``lift`` (human m) above their height (Y) in ``previous`` (T, 22, 3): mean relu."""
    target = torch.as_tensor(previous[:, :, 1] + lift)  # (T, 22)
    ids = list(joints)

    def fn(motion: Tensor) -> Tensor:
        f = _index(frames, motion.shape[1], motion.device)
        goal = target.to(motion)[f][:, ids]
        return torch.relu(goal - motion[:, f][:, :, ids, 1]).mean(dim=(1, 2))

    return LossTerm(name, fn, weight)


def separation_loss(
    previous: np.ndarray,
    pairs: Sequence[tuple[int, int]],
    frames: Sequence[int],
    extra: float,
    weight: float = 1.0,
    name: str = "separation",
) -> LossTerm:
    """Joint pairs (a, b) at least ``extra`` (human m) further apart than in ``previous``: mean relu."""
    a = [p[0] for p in pairs]
    b = [p[1] for p in pairs]
    target = torch.as_tensor(np.linalg.norm(previous[:, a] - previous[:, b], axis=-1) + extra)  # (T, P)

    def fn(motion: Tensor) -> Tensor:
        f = _index(frames, motion.shape[1], motion.device)
        dist = (motion[:, f][:, :, a] - motion[:, f][:, :, b]).norm(dim=-1)
        return torch.relu(target.to(motion)[f] - dist).mean(dim=(1, 2))

    return LossTerm(name, fn, weight)


def contact_loss(
    joints: Sequence[int], frames: Sequence[int], weight: float = 1.0, name: str = "contact"
) -> LossTerm:
    """Stance foot joints do not slide: mean horizontal (XZ) displacement per frame (human m)."""
    ids = list(joints)

    def fn(motion: Tensor) -> Tensor:
        f = _index(frames, motion.shape[1], motion.device)
        if len(f) < 2:
            return motion.new_zeros(motion.shape[0])
        p = motion[:, f][:, :, ids][..., [0, 2]]
        return (p[:, 1:] - p[:, :-1]).norm(dim=-1).mean(dim=(1, 2))

    return LossTerm(name, fn, weight)


def support_loss(
    joints: Sequence[int], frames: Sequence[int], height: float, weight: float = 1.0, name: str = "support"
) -> LossTerm:
    """The lowest of ``joints`` no higher than ``height`` (human m, Y) in every frame: mean relu."""
    ids = list(joints)

    def fn(motion: Tensor) -> Tensor:
        f = _index(frames, motion.shape[1], motion.device)
        lowest = motion[:, f][:, :, ids, 1].amin(dim=-1)
        return torch.relu(lowest - height).mean(dim=1)

    return LossTerm(name, fn, weight)


def smoothness_loss(
    previous: np.ndarray,
    joints: Sequence[int],
    frames: Sequence[int],
    ratio: float = 0.5,
    weight: float = 1.0,
    name: str = "smoothness",
    fps: float = FPS,
) -> LossTerm:
    """Accelerations (m/s^2) of ``joints`` at most ``ratio`` x their value in ``previous``: mean relu / g."""
    ids = list(joints)
    acc = np.zeros(previous.shape[:2], dtype=np.float32)
    acc[1:-1] = np.linalg.norm(previous[2:] - 2 * previous[1:-1] + previous[:-2], axis=-1) * fps * fps
    limit = torch.as_tensor(ratio * acc)  # (T, 22)

    def fn(motion: Tensor) -> Tensor:
        f = _index([x for x in frames if 0 < x < motion.shape[1] - 1], motion.shape[1], motion.device)
        if len(f) == 0:
            return motion.new_zeros(motion.shape[0])
        a = (motion[:, f + 1] - 2 * motion[:, f] + motion[:, f - 1])[:, :, ids].norm(dim=-1) * fps * fps
        return (torch.relu(a - limit.to(motion)[f][:, ids]) / 9.81).mean(dim=(1, 2))

    return LossTerm(name, fn, weight)
