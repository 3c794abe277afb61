"""Reading any BVH file: its joint names, their world positions per frame, and its frame rate.

:func:`parse_bvh` runs the file's forward kinematics for every joint (any hierarchy, any channel
order, position channels on any joint); :func:`bvh_to_smpl22` maps the joints onto the 22 SMPL
joints by their names (:mod:`controlmm.motion.formats.naming`: LAFAN1, CMU, Mixamo and SMPL names
are recognised; any other skeleton takes a mapping file). Positions keep the file's units and axes;
:mod:`controlmm.motion.formats.conventions` converts them.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from controlmm.errors import InputFileError
from controlmm.files import input_file
from controlmm.motion.formats.naming import SkeletonMap, detect_family, unmapped_error


@dataclass
class BvhAnimation:
    """The joints of a BVH file and their world positions.

    Attributes:
        names: joint names (ROOT and JOINT entries; End Sites are left out), (J,).
        parents: index of each joint's parent in ``names`` (-1 for the root), (J,).
        positions: (T, J, 3) world positions in the file's units and axes.
        fps: 1 / Frame Time.
    """

    names: list[str]
    parents: list[int]
    positions: np.ndarray
    fps: float


def read_bvh_file(path: str | Path) -> BvhAnimation:
    """Parse the BVH file ``path`` (one-line errors naming the file)."""
    path = input_file(path, "BVH file")
    tokens = path.read_text(errors="replace").split()
    try:
        return parse_bvh(tokens)
    except (ValueError, IndexError, KeyError) as exc:
        raise InputFileError(f"'{path}' is not a valid BVH file ({exc})") from None


def parse_bvh(tokens: list[str]) -> BvhAnimation:
    """Parse the whitespace-separated tokens of a BVH file (ValueError/IndexError when malformed)."""
    if not tokens or tokens[0] != "HIERARCHY":
        raise ValueError("missing HIERARCHY")
    names: list[str | None] = []  # None: an End Site
    parents: list[int] = []
    offsets: list[np.ndarray] = []
    channels: list[list[str]] = []
    stack: list[int] = []
    last = -1
    i = 1
    while tokens[i] != "MOTION":
        tok = tokens[i]
        if tok in ("ROOT", "JOINT", "End"):
            if tok != "ROOT" and not stack:
                raise ValueError(f"'{tok}' outside the ROOT block")
            names.append(tokens[i + 1] if tok != "End" else None)
            parents.append(stack[-1] if stack else -1)
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
    if tokens[i + 1] != "Frames:" or tokens[i + 3] != "Frame" or tokens[i + 4] != "Time:":
        raise ValueError("expected 'Frames: N' and 'Frame Time: S' after MOTION")
    n_frames = int(tokens[i + 2])
    frame_time = float(tokens[i + 5])
    if not (np.isfinite(frame_time) and frame_time > 0):
        raise ValueError(f"Frame Time must be a positive number of seconds; got {tokens[i + 5]}")
    values = np.asarray(tokens[i + 6 :], dtype=np.float64)
    n_ch = sum(len(c) for c in channels)
    if n_frames < 1 or values.size != n_frames * n_ch:
        raise ValueError(f"expected {n_frames}x{n_ch} motion values, found {values.size}")
    values = values.reshape(n_frames, n_ch)

    # Every parent comes before its children, so joint j's transforms are the j-th appended.
    glob_rot: list[np.ndarray] = []
    glob_pos: list[np.ndarray] = []
    col = 0
    for j in range(len(names)):
        pos = np.tile(offsets[j], (n_frames, 1))
        axes = ""
        angles: list[np.ndarray] = []
        for ch in channels[j]:
            v = values[:, col]
            col += 1
            low = ch.lower()
            if low.endswith("position"):
                pos[:, "xyz".index(low[0])] = v
            elif low.endswith("rotation"):
                axes += low[0].upper()
                angles.append(v)
            else:
                raise ValueError(f"unknown channel '{ch}'")
        rot = (
            Rotation.from_euler(axes, np.stack(angles, -1), degrees=True).as_matrix()
            if axes
            else np.tile(np.eye(3), (n_frames, 1, 1))
        )
        p = parents[j]
        if p < 0:
            glob_pos.append(pos)
            glob_rot.append(rot)
        else:
            glob_pos.append(glob_pos[p] + np.einsum("tij,tj->ti", glob_rot[p], pos))
            glob_rot.append(np.einsum("tij,tjk->tik", glob_rot[p], rot))
    keep = [j for j, n in enumerate(names) if n is not None]
    new_index = {j: k for k, j in enumerate(keep)}
    return BvhAnimation(
        names=[str(names[j]) for j in keep],
        parents=[new_index.get(parents[j], -1) for j in keep],
        positions=np.stack([glob_pos[j] for j in keep], axis=1),
        fps=_rate(frame_time),
    )


def _rate(frame_time: float) -> float:
    """1 / ``frame_time``, snapped to a whole rate when the file's rounding is all that separates them
    (``Frame Time: 0.0333333`` is 30 fps)."""
    fps = 1.0 / frame_time
    whole = round(fps)
    return float(whole) if whole > 0 and abs(fps - whole) < 1e-4 * fps else fps


def bvh_to_smpl22(
    anim: BvhAnimation, what: str, mapping: SkeletonMap | None = None
) -> tuple[np.ndarray, SkeletonMap]:
    """SMPL-22 positions (T, 22, 3) of a parsed BVH (file units and axes) and the map used.

    Without ``mapping`` the naming family is detected; a skeleton that none maps raises the one-line
    error that lists the missing joints and the mapping file to write.
    """
    if mapping is None:
        mapping = detect_family(anim.names, anim.positions)
        if mapping is None:
            raise unmapped_error(what, anim.names)
    else:
        missing = mapping.missing(anim.names)
        if missing:
            raise InputFileError(
                f"{what}: the mapping '{mapping.name}' names joints the file lacks: {', '.join(missing[:12])}"
            )
    return mapping.apply(anim.names, anim.positions), mapping
