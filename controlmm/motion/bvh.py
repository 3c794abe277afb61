"""BVH export and import of the SMPL-22 hierarchy (metres, Y up), readable by Blender.

Export: each joint gets a global rotation chosen so that forward kinematics reproduces
the input positions. Joints with one child use the swing that points the child bone at
its observed direction with no twist relative to the parent (HumanML3D's IK). Joints
with several children (pelvis, spine3) use a rigid frame fitted to their children, with
rest offsets measured from the motion itself, so a rigid real skeleton is exact.
Leaf joints (feet, head, wrists) carry their parent's rotation and an End Site.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from controlmm.atomic import atomic_open
from controlmm.errors import InputFileError
from controlmm.motion.extract import check_joints
from controlmm.motion.formats.bvh_import import read_bvh_file
from controlmm.motion.quaternion import qbetween, quat_to_matrix
from controlmm.motion.skeleton import JOINT_NAMES, NUM_JOINTS, PARENTS, RAW_OFFSETS

_CHILDREN: list[list[int]] = [[c for c in range(NUM_JOINTS) if PARENTS[c] == j] for j in range(NUM_JOINTS)]
_EULER = "ZXY"  # BVH channel order Zrotation Xrotation Yrotation (intrinsic)
_END_SITE = 0.05  # metres


def _normalize(v: np.ndarray) -> np.ndarray:
    return v / np.maximum(np.linalg.norm(v, axis=-1, keepdims=True), 1e-12)


def _kabsch(rest: np.ndarray, obs: np.ndarray) -> np.ndarray:
    """Rotations (T, 3, 3) best mapping rest vectors (K, 3) onto observed (T, K, 3)."""
    h = np.einsum("ki,tkj->tij", rest, obs)
    u, _, vt = np.linalg.svd(h)
    d = np.sign(np.linalg.det(np.einsum("tij,tjk->tik", u, vt)))
    fix = np.ones((len(d), 3))
    fix[:, 2] = d
    return np.einsum("tji,tj,tkj->tik", vt, fix, u)


def _fit_global_rotations(joints: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Global rotation matrices (T, 22, 3, 3) and rest offsets (22, 3) for positions (T, 22, 3)."""
    t = joints.shape[0]
    glob = np.tile(np.eye(3), (t, NUM_JOINTS, 1, 1))
    # Rest offsets: raw directions x the mean observed bone length (exact for any skeleton
    # with constant bone lengths, not only HumanML3D's reference skeleton).
    lengths = np.linalg.norm(joints[:, 1:] - joints[:, list(PARENTS[1:])], axis=-1).mean(0)
    offsets = RAW_OFFSETS * np.concatenate([[0.0], lengths])[:, None]
    for j in range(NUM_JOINTS):
        kids = _children_sorted(j)
        parent_rot = glob[:, PARENTS[j]] if PARENTS[j] >= 0 else np.tile(np.eye(3), (t, 1, 1))
        if len(kids) >= 2:
            obs = joints[:, kids] - joints[:, j : j + 1]
            # Frame from the children (x: right child -> left child, y: up child), then rest
            # offsets as the mean local vectors, refined by Kabsch.
            x = _normalize(obs[:, 0] - obs[:, 1]) if j == 0 else _normalize(obs[:, 1] - obs[:, 2])
            up = obs[:, 2] if j == 0 else obs[:, 0]
            y = _normalize(up - (up * x).sum(-1, keepdims=True) * x)
            rot = np.stack([x, y, np.cross(x, y)], axis=-1)
            for _ in range(3):
                rest = np.einsum("tji,tkj->ki", rot, obs) / t
                rot = _kabsch(rest, obs)
            offsets[kids] = rest
            glob[:, j] = rot
        elif len(kids) == 1:
            c = kids[0]
            rest_dir = np.einsum("tij,j->ti", parent_rot, offsets[c])
            swing = quat_to_matrix(qbetween(rest_dir, joints[:, c] - joints[:, j]))
            glob[:, j] = np.einsum("tij,tjk->tik", swing, parent_rot)
        else:
            glob[:, j] = parent_rot
    return glob, offsets


def _children_sorted(j: int) -> list[int]:
    return sorted(_CHILDREN[j])


def write_bvh(
    path: str | Path,
    joints: np.ndarray,
    fps: float = 20.0,
    *,
    names: Mapping[str, str] | None = None,
    units_per_metre: float = 1.0,
    insert: Mapping[str, str] | None = None,
    rotations: np.ndarray | None = None,
) -> None:
    """Write positions (T, 22, 3) (metres, Y up) as a BVH file (atomic).

    Args:
        names: SMPL joint -> the name it gets in the file (default: the SMPL names), e.g. LAFAN1's.
        units_per_metre: length unit of the file (100: centimetres).
        insert: new joint name -> the SMPL joint it becomes the parent of: a pass-through joint with
            zero offset and zero rotation (CMU-style ``LHipJoint`` above ``LeftUpLeg``); forward
            kinematics is unchanged.
        rotations: global rotations (T, 22, 3, 3) of the joints' bone frames (another skeleton's
            conventions, e.g. LAFAN1's) instead of the rotations fitted to the SMPL rest pose; every
            joint then also gets position channels (in its parent's frame), so the file reproduces
            ``joints`` exactly whatever the frames.
    """
    joints = check_joints(joints, min_frames=1)
    if not (np.isfinite(units_per_metre) and units_per_metre > 0):
        raise InputFileError(f"units per metre must be a positive number; got {units_per_metre}")
    label = {n: (names or {}).get(n, n) for n in JOINT_NAMES}
    above = {child: new for new, child in (insert or {}).items()}
    t = joints.shape[0]
    moving = np.zeros((t, NUM_JOINTS, 3))  # per-joint position channels (only with ``rotations``)
    if rotations is None:
        glob, offsets = _fit_global_rotations(joints)
        offsets = offsets * units_per_metre
    else:
        glob = np.asarray(rotations, dtype=np.float64)
        if glob.shape != (t, NUM_JOINTS, 3, 3):
            raise InputFileError(f"rotations must be ({t}, {NUM_JOINTS}, 3, 3); got {glob.shape}")
        for j in range(1, NUM_JOINTS):
            bone = joints[:, j] - joints[:, PARENTS[j]]
            moving[:, j] = np.einsum("tji,tj->ti", glob[:, PARENTS[j]], bone) * units_per_metre
        offsets = moving.mean(axis=0)
    local = np.empty_like(glob)
    local[:, 0] = glob[:, 0]
    for j in range(1, NUM_JOINTS):
        local[:, j] = np.einsum("tji,tjk->tik", glob[:, PARENTS[j]], glob[:, j])
    euler = (
        Rotation.from_matrix(local.reshape(-1, 3, 3)).as_euler(_EULER, degrees=True).reshape(t, NUM_JOINTS, 3)
    )
    euler = np.unwrap(euler, period=360.0, axis=0)

    lines = ["HIERARCHY"]
    order: list[int | None] = []  # motion columns: a joint, or None for a pass-through joint

    def emit(j: int, depth: int) -> None:
        if JOINT_NAMES[j] in above:
            pad = "  " * depth
            lines.extend(
                [
                    f"{pad}JOINT {above[JOINT_NAMES[j]]}",
                    f"{pad}{{",
                    f"{pad}  OFFSET 0.000000 0.000000 0.000000",
                    f"{pad}  CHANNELS 3 Zrotation Xrotation Yrotation",
                ]
            )
            order.append(None)
            depth += 1
        pad = "  " * depth
        kind = "ROOT" if j == 0 else "JOINT"
        lines.append(f"{pad}{kind} {label[JOINT_NAMES[j]]}")
        lines.append(f"{pad}{{")
        off = np.zeros(3) if j == 0 else offsets[j]
        lines.append(f"{pad}  OFFSET {off[0]:.6f} {off[1]:.6f} {off[2]:.6f}")
        if j == 0 or rotations is not None:
            lines.append(f"{pad}  CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation")
        else:
            lines.append(f"{pad}  CHANNELS 3 Zrotation Xrotation Yrotation")
        order.append(j)
        kids = _children_sorted(j)
        for c in kids:
            emit(c, depth + 1)
        if not kids:
            end = RAW_OFFSETS[j] * _END_SITE * units_per_metre
            lines.append(f"{pad}  End Site")
            lines.append(f"{pad}  {{")
            lines.append(f"{pad}    OFFSET {end[0]:.6f} {end[1]:.6f} {end[2]:.6f}")
            lines.append(f"{pad}  }}")
        lines.append(f"{pad}}}")
        if JOINT_NAMES[j] in above:
            lines.append(f"{'  ' * (depth - 1)}}}")

    if JOINT_NAMES[0] in above:
        raise InputFileError("a joint cannot be inserted above the root")
    emit(0, 0)
    zero = np.zeros(3)
    lines += ["MOTION", f"Frames: {t}", f"Frame Time: {1.0 / fps:.8f}"]
    for f in range(t):
        vals = list(joints[f, 0] * units_per_metre)
        for col in order:
            if col is not None and col > 0 and rotations is not None:
                vals += list(moving[f, col])
            vals += list(zero if col is None else euler[f, col])
        lines.append(" ".join(f"{v:.6f}" for v in vals))
    with atomic_open(path, "w", encoding="ascii") as fh:
        fh.write("\n".join(lines) + "\n")


def read_bvh(path: str | Path) -> tuple[np.ndarray, float]:
    """Read a BVH with the SMPL-22 joint names; return positions (T, 22, 3) and fps.

    Any channel order is accepted; joints are matched by name (extra joints are ignored).
    Other skeletons (LAFAN1, CMU, Mixamo names, or a mapping file) are read by
    :func:`controlmm.motion.load_motion`.
    """
    path = Path(path)
    if not path.is_file():
        raise InputFileError(f"BVH file '{path}' does not exist")
    anim = read_bvh_file(path)
    index = {n: k for k, n in enumerate(anim.names)}
    missing = [n for n in JOINT_NAMES if n not in index]
    if missing:
        raise InputFileError(f"BVH lacks SMPL-22 joints: {', '.join(missing)}")
    joints = anim.positions[:, [index[n] for n in JOINT_NAMES]]
    return joints.astype(np.float32), anim.fps
