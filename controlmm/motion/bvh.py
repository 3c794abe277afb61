"""BVH export and import of the SMPL-22 hierarchy (metres, Y up), readable by Blender.

Export: each joint gets a global rotation chosen so that forward kinematics reproduces
the input positions. Joints with one child use the swing that points the child bone at
its observed direction with no twist relative to the parent (HumanML3D's IK). Joints
with several children (pelvis, spine3) use a rigid frame fitted to their children, with
rest offsets measured from the motion itself, so a rigid real skeleton is exact.
Leaf joints (feet, head, wrists) carry their parent's rotation and an End Site.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from controlmm.atomic import atomic_open
from controlmm.errors import InputFileError
from controlmm.motion.extract import check_joints
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


def write_bvh(path: str | Path, joints: np.ndarray, fps: float = 20.0) -> None:
    """Write positions (T, 22, 3) (metres, Y up) as a BVH file (atomic)."""
    joints = check_joints(joints, min_frames=1)
    glob, offsets = _fit_global_rotations(joints)
    t = joints.shape[0]
    local = np.empty_like(glob)
    local[:, 0] = glob[:, 0]
    for j in range(1, NUM_JOINTS):
        local[:, j] = np.einsum("tji,tjk->tik", glob[:, PARENTS[j]], glob[:, j])
    euler = (
        Rotation.from_matrix(local.reshape(-1, 3, 3)).as_euler(_EULER, degrees=True).reshape(t, NUM_JOINTS, 3)
    )
    euler = np.unwrap(euler, period=360.0, axis=0)

    lines = ["HIERARCHY"]

    def emit(j: int, depth: int) -> None:
        pad = "  " * depth
        kind = "ROOT" if j == 0 else "JOINT"
        lines.append(f"{pad}{kind} {JOINT_NAMES[j]}")
        lines.append(f"{pad}{{")
        off = np.zeros(3) if j == 0 else offsets[j]
        lines.append(f"{pad}  OFFSET {off[0]:.6f} {off[1]:.6f} {off[2]:.6f}")
        if j == 0:
            lines.append(f"{pad}  CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation")
        else:
            lines.append(f"{pad}  CHANNELS 3 Zrotation Xrotation Yrotation")
        kids = _children_sorted(j)
        for c in kids:
            emit(c, depth + 1)
        if not kids:
            end = RAW_OFFSETS[j] * _END_SITE
            lines.append(f"{pad}  End Site")
            lines.append(f"{pad}  {{")
            lines.append(f"{pad}    OFFSET {end[0]:.6f} {end[1]:.6f} {end[2]:.6f}")
            lines.append(f"{pad}  }}")
        lines.append(f"{pad}}}")

    emit(0, 0)
    order = _depth_first()
    lines += ["MOTION", f"Frames: {t}", f"Frame Time: {1.0 / fps:.8f}"]
    for f in range(t):
        vals = list(joints[f, 0]) + [v for j in order for v in euler[f, j]]
        lines.append(" ".join(f"{v:.6f}" for v in vals))
    with atomic_open(path, "w", encoding="ascii") as fh:
        fh.write("\n".join(lines) + "\n")


def _depth_first() -> list[int]:
    out: list[int] = []

    def visit(j: int) -> None:
        out.append(j)
        for c in _children_sorted(j):
            visit(c)

    visit(0)
    return out


def read_bvh(path: str | Path) -> tuple[np.ndarray, float]:
    """Read a BVH with the SMPL-22 joint names; return positions (T, 22, 3) and fps.

    Any channel order is accepted; joints are matched by name (extra joints are ignored).
    """
    path = Path(path)
    if not path.is_file():
        raise InputFileError(f"BVH file '{path}' does not exist")
    tokens = path.read_text(errors="replace").split()
    try:
        return _parse_bvh(tokens)
    except InputFileError:
        raise
    except (ValueError, IndexError) as exc:
        raise InputFileError(f"'{path}' is not a valid BVH file ({exc})") from exc


def _parse_bvh(tokens: list[str]) -> tuple[np.ndarray, float]:
    names: list[str | None] = []  # None: an End Site
    parents: list[int] = []
    offsets: list[np.ndarray] = []
    channels: list[list[str]] = []
    stack: list[int] = []
    i = 0
    if tokens[0] != "HIERARCHY":
        raise ValueError("missing HIERARCHY")
    i = 1
    last = -1
    while tokens[i] != "MOTION":
        tok = tokens[i]
        if tok in ("ROOT", "JOINT"):
            names.append(tokens[i + 1])
            parents.append(stack[-1] if stack else -1)
            offsets.append(np.zeros(3))
            channels.append([])
            last = len(names) - 1
            i += 2
        elif tok == "End":
            names.append(None)
            parents.append(stack[-1])
            offsets.append(np.zeros(3))
            channels.append([])
            last = len(names) - 1
            i += 2
        elif tok == "{":
            stack.append(last)
            i += 1
        elif tok == "}":
            stack.pop()
            i += 1
        elif tok == "OFFSET":
            offsets[last] = np.array([float(v) for v in tokens[i + 1 : i + 4]])
            i += 4
        elif tok == "CHANNELS":
            n = int(tokens[i + 1])
            channels[last] = tokens[i + 2 : i + 2 + n]
            i += 2 + n
        else:
            raise ValueError(f"unexpected token '{tok}'")
    n_frames = int(tokens[i + 2])
    frame_time = float(tokens[i + 5])
    values = np.array([float(v) for v in tokens[i + 6 :]])
    n_ch = sum(len(c) for c in channels)
    if values.size != n_frames * n_ch:
        raise ValueError(f"expected {n_frames}x{n_ch} motion values, found {values.size}")
    values = values.reshape(n_frames, n_ch)

    # Every parent comes before its children, so joint j's transforms are the j-th appended.
    glob_rot: list[np.ndarray] = []
    glob_pos: list[np.ndarray] = []
    col = 0
    for j in range(len(names)):
        pos = np.tile(offsets[j], (n_frames, 1))
        rot = np.tile(np.eye(3), (n_frames, 1, 1))
        axes = ""
        angles: list[np.ndarray] = []
        for ch in channels[j]:
            v = values[:, col]
            col += 1
            low = ch.lower()
            if low.endswith("position"):
                pos[:, "xyz".index(low[0])] = v
            else:
                axes += low[0].upper()
                angles.append(v)
        if axes:
            rot = Rotation.from_euler(axes, np.stack(angles, -1), degrees=True).as_matrix()
        p = parents[j]
        if p < 0:
            glob_pos.append(pos)
            glob_rot.append(rot)
        else:
            glob_pos.append(glob_pos[p] + np.einsum("tij,tj->ti", glob_rot[p], pos))
            glob_rot.append(np.einsum("tij,tjk->tik", glob_rot[p], rot))
    index = {n: k for k, n in enumerate(names) if n is not None}
    missing = [n for n in JOINT_NAMES if n not in index]
    if missing:
        raise InputFileError(f"BVH lacks SMPL-22 joints: {', '.join(missing)}")
    joints = np.stack([glob_pos[index[n]] for n in JOINT_NAMES], axis=1)
    return joints.astype(np.float32), 1.0 / frame_time
