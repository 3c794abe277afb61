"""Obstacle and floor losses for inference-time editing, as ``controlmm.control.LossTerm``s.

Every loss takes generated joints (B, T, 22, 3) in the HUMAN frame (Y up, metres, frames
0..T-1 at ``fps``), converts them to the world with the given ``HumanToWorld`` (whose scale is
the retargeter's human -> robot scale, so what the human motion avoids the robot avoids after
retargeting) and measures distances in **world metres**. Each returns (B,) >= 0, zero when
satisfied.

* :func:`obstacle_loss` - paper Eq. 9: mean over the chosen joints and frames of
  max(d - SDF(p), 0) with a safe distance d.
* :func:`body_obstacle_loss` - the same over points sampled along the bones, each with the
  bone's radius added to d, so forearms, shins and the head (not only joint centres) stay clear.
* :func:`floor_loss` - no joint below the floor: mean of max(floor + clearance - z, 0). (A bone's
  lowest point is one of its ends, so joints cover the skeleton's bones too.)
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import torch

from controlmm.control import LossTerm
from controlmm.errors import ControlMMError, ShapeError
from controlmm.frames import HumanToWorld
from controlmm.motion.skeleton import BONE_LENGTHS, FPS, NUM_JOINTS, PARENTS, joint_index
from scenes.scene import Scene
from scenes.sdf.grid import GridSDF, banded_sdf
from scenes.sdf.scene_sdf import SceneSDF

Tensor = torch.Tensor


@dataclass(frozen=True)
class Bone:
    """A capsule along the bone parent -> child of the 22-joint skeleton (human metres).

    ``reach`` > 1 extends the capsule past the child joint (hands past the wrists, the top of
    the head past the head joint, toes past the foot joint).
    """

    child: int
    radius: float
    reach: float = 1.0

    @property
    def parent(self) -> int:
        return PARENTS[self.child]


BODY_BONES: tuple[Bone, ...] = (
    Bone(1, 0.09),
    Bone(2, 0.09),
    Bone(3, 0.12),  # pelvis -> hips, lower spine
    Bone(4, 0.075),
    Bone(5, 0.075),  # thighs
    Bone(6, 0.12),  # spine
    Bone(7, 0.05),
    Bone(8, 0.05),  # shins
    Bone(9, 0.13),  # chest
    Bone(10, 0.04, 1.3),
    Bone(11, 0.04, 1.3),  # feet, toes past the foot joint
    Bone(12, 0.06),  # neck
    Bone(13, 0.07),
    Bone(14, 0.07),  # collars
    Bone(15, 0.10, 1.6),  # head, up to the top of the skull
    Bone(16, 0.06),
    Bone(17, 0.06),  # shoulders
    Bone(18, 0.045),
    Bone(19, 0.045),  # upper arms
    Bone(20, 0.035, 1.35),
    Bone(21, 0.035, 1.35),  # forearms, hands past the wrists
)
"""Default body volume: one capsule per bone, radii of an adult in human metres (the loss
multiplies them by the transform's scale to get the robot-sized body)."""


def body_points(bones: Sequence[Bone] = BODY_BONES, spacing: float = 0.05) -> tuple[np.ndarray, np.ndarray]:
    """Sampling of the body volume: weights W (P, 22) and radii (P,) in human metres.

    Point p = W[p] @ joints lies on a bone (spacing at most ``spacing`` on the reference
    skeleton, ends included); radii[p] is its bone's radius.
    """
    if spacing <= 0 or not math.isfinite(spacing):
        raise ControlMMError(f"spacing must be a positive length in metres; got {spacing}")
    rows, radii = [], []
    for bone in bones:
        length = float(BONE_LENGTHS[bone.child]) * bone.reach
        n = max(2, int(math.ceil(length / spacing)) + 1)
        for s in np.linspace(0.0, bone.reach, n):
            w = np.zeros(NUM_JOINTS)
            w[bone.parent] += 1.0 - s
            w[bone.child] += s
            rows.append(w)
            radii.append(bone.radius)
    return np.stack(rows), np.asarray(radii)


def _check_joints(joints: Tensor) -> None:
    if joints.ndim != 4 or joints.shape[2:] != (NUM_JOINTS, 3):
        raise ShapeError(f"joints must have shape (B, T, 22, 3); got {tuple(joints.shape)}")


def _frames(frames: Sequence[int] | None, num_frames: int, device: torch.device) -> Tensor:
    if frames is None:
        return torch.arange(num_frames, device=device)
    idx = torch.as_tensor(list(frames), dtype=torch.long, device=device)
    return idx[(idx >= 0) & (idx < num_frames)]


def _joint_ids(joints: Sequence[str | int] | None) -> list[int]:
    return list(range(NUM_JOINTS)) if joints is None else [joint_index(j) for j in joints]


def _check_distance(name: str, value: float) -> float:
    if not math.isfinite(value):
        raise ControlMMError(f"{name} must be a finite distance in metres; got {value}")
    return float(value)


def _sdf_at(sdf: SceneSDF | GridSDF, world: Tensor, frames: Tensor, fps: float, time_offset: float) -> Tensor:
    """SDF (B, F, P) of world points (B, F, P, 3) at the given frames."""
    times = frames.to(world.dtype) / fps + time_offset
    return sdf(world, times if getattr(sdf, "is_moving", True) else None)


def obstacle_loss(
    sdf: SceneSDF,
    transform: HumanToWorld,
    safe_distance: float = 0.05,
    joints: Sequence[str | int] | None = None,
    frames: Sequence[int] | None = None,
    fps: float = FPS,
    time_offset: float = 0.0,
    weight: float = 1.0,
    name: str = "obstacle",
) -> LossTerm:
    """Paper Eq. 9 on joint centres: mean over (frames, joints) of max(d - SDF(p), 0), world metres.

    Args:
        sdf: a :class:`scenes.sdf.SceneSDF` (or any ``sdf(points (..., N, 3), t) -> (..., N)``).
        transform: human -> world (``scene.human_to_world(robot_scale(robot))``).
        safe_distance: d, clearance to keep from every obstacle (m, world).
        joints: joint names or indices (default all 22); frames: frame indices (default all;
            indices past the motion's end are ignored).
        fps, time_offset: frame f happens at ``time_offset + f / fps`` s on the obstacles' tracks.
    """
    d = _check_distance("safe_distance", safe_distance)
    ids = _joint_ids(joints)
    field = banded_sdf(sdf, d) if isinstance(sdf, SceneSDF) else sdf  # exact within d (module doc)

    def fn(motion: Tensor) -> Tensor:
        _check_joints(motion)
        f = _frames(frames, motion.shape[1], motion.device)
        if len(f) == 0:
            return motion.new_zeros(motion.shape[0])
        world = transform.to_world(motion[:, f][:, :, ids])
        return torch.relu(d - _sdf_at(field, world, f, fps, time_offset)).mean(dim=(1, 2))

    return LossTerm(name, fn, weight)


def body_obstacle_loss(
    sdf: SceneSDF,
    transform: HumanToWorld,
    safe_distance: float = 0.02,
    bones: Sequence[Bone] = BODY_BONES,
    spacing: float = 0.05,
    frames: Sequence[int] | None = None,
    fps: float = FPS,
    time_offset: float = 0.0,
    weight: float = 1.0,
    name: str = "body_obstacle",
) -> LossTerm:
    """Eq. 9 over the body volume: points along the bones keep d + radius * scale from obstacles.

    The bone radii (``bones``, human metres) scale with ``transform.scale`` like the body does.
    Mean over (frames, body points) of max(d + r - SDF(p), 0), world metres.
    """
    d = _check_distance("safe_distance", safe_distance)
    weights_np, radii_np = body_points(bones, spacing)
    cache: dict[tuple[torch.dtype, torch.device], tuple[Tensor, Tensor]] = {}
    reach = float(radii_np.max(initial=0.0)) * transform.scale + d  # the largest clearance
    field = banded_sdf(sdf, reach) if isinstance(sdf, SceneSDF) else sdf

    def fn(motion: Tensor) -> Tensor:
        _check_joints(motion)
        key = (motion.dtype, motion.device)
        if key not in cache:
            cache[key] = (
                torch.as_tensor(weights_np, dtype=motion.dtype, device=motion.device),
                torch.as_tensor(radii_np * transform.scale + d, dtype=motion.dtype, device=motion.device),
            )
        w, clearance = cache[key]
        f = _frames(frames, motion.shape[1], motion.device)
        if len(f) == 0:
            return motion.new_zeros(motion.shape[0])
        # the weights of a point sum to 1, so the (affine) world transform goes first, on 22 joints
        pts = torch.einsum("pj,bfjc->bfpc", w, transform.to_world(motion[:, f]))
        return torch.relu(clearance - _sdf_at(field, pts, f, fps, time_offset)).mean(dim=(1, 2))

    return LossTerm(name, fn, weight)


def floor_loss(
    transform: HumanToWorld,
    floor_height: float = 0.0,
    clearance: float = 0.0,
    joints: Sequence[str | int] | None = None,
    frames: Sequence[int] | None = None,
    weight: float = 1.0,
    name: str = "floor",
) -> LossTerm:
    """No joint below the floor: mean over (frames, joints) of max(floor + clearance - z, 0), world m.

    ``floor_height`` is the world z of the floor (``scene.floor_height``).
    """
    floor = _check_distance("floor_height", floor_height) + _check_distance("clearance", clearance)
    ids = _joint_ids(joints)

    def fn(motion: Tensor) -> Tensor:
        _check_joints(motion)
        f = _frames(frames, motion.shape[1], motion.device)
        if len(f) == 0:
            return motion.new_zeros(motion.shape[0])
        z = transform.to_world(motion[:, f][:, :, ids])[..., 2]
        return torch.relu(floor - z).mean(dim=(1, 2))

    return LossTerm(name, fn, weight)


def scene_loss_terms(
    scene: Scene,
    transform: HumanToWorld,
    safe_distance: float = 0.02,
    body: bool = True,
    obstacle_weight: float = 1.0,
    floor_weight: float = 1.0,
) -> list[LossTerm]:
    """The usual terms for a scene: body-volume (or joint) obstacle loss plus the floor loss.

    No obstacle term is returned for a scene without obstacles.
    """
    terms = []
    if scene.obstacle_geom_ids:
        make = body_obstacle_loss if body else obstacle_loss
        terms.append(
            make(
                scene.sdf(),
                transform,
                safe_distance=safe_distance,
                weight=obstacle_weight,
                name=f"{'body_obstacle' if body else 'obstacle'}:{scene.name}",
            )
        )
    terms.append(floor_loss(transform, scene.floor_height, weight=floor_weight))
    return terms
