"""Failures: ranges of consecutive failing frames of one kind, robot body and geom.

``depth`` is the worst value over the range, in the unit of its kind:

=====================  =======================================================================
kind                   depth
=====================  =======================================================================
obstacle_penetration   metres of a robot geom inside ``obstacle_geom``
floor_penetration      metres of the robot body's lowest collision point below the floor
self_collision         metres of overlap; ``obstacle_geom`` names the *other robot body*
joint_limit            radians (metres for slides) past the range of ``joint``
joint_velocity         rad/s above the velocity limit of ``joint``
joint_coupling         radians (metres for slides) ``joint`` is from where the MJCF's joint
                       equality puts it (``<equality><joint>``: NAO's hips share one motor)
foot_sliding           metres the stance foot slid over the range
floating               metres between the robot's lowest point and the nearest support
residual_force         non-physical root force needed, as a fraction of m g
residual_moment        non-physical moment about the centre of mass / (m g), metres
torque_limit           |torque| / limit of ``joint`` (a ratio; > 1 is over the limit)
tracking_fall          metres the root dropped below its reference height (PD replay or the
                       physics execution check)
tracking_error         metres between the executed and the reference position of the root (world)
                       or of an end effector (relative to the root), physics execution check
=====================  =======================================================================

Frame ranges are inclusive: ``frame_start <= t <= frame_end``.

Every failure has a ``severity``: ``"error"`` fails the report (``passed`` is False),
``"warning"`` is reported but does not. The kinematic kinds are errors; the dynamic kinds
are warnings frame by frame and errors when sustained (see ``docs/simulation-checks.md``).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

SEVERITIES = ("error", "warning")

KINDS = (
    "obstacle_penetration",
    "floor_penetration",
    "self_collision",
    "joint_limit",
    "joint_velocity",
    "joint_coupling",
    "foot_sliding",
    "floating",
    "residual_force",
    "residual_moment",
    "torque_limit",
    "tracking_fall",
    "tracking_error",
)


@dataclass(frozen=True)
class Failure:
    """Consecutive failing frames ``frame_start..frame_end`` (inclusive) of one kind.

    Attributes:
        kind: one of :data:`KINDS`.
        frame_start, frame_end: inclusive frame range.
        robot_body: the robot body that fails (None when the whole robot does).
        obstacle_geom: the obstacle geom hit (penetration), the floor geom, or for
            ``self_collision`` the other robot body; None otherwise.
        depth: the worst value over the range (unit per kind, see the module docstring).
        joint: the joint for joint_limit / joint_velocity / joint_coupling / torque_limit
            failures.
        severity: ``"error"`` (fails the report) or ``"warning"`` (reported only).
    """

    kind: str
    frame_start: int
    frame_end: int
    robot_body: str | None
    obstacle_geom: str | None
    depth: float
    joint: str | None = None
    severity: str = "error"

    @property
    def is_error(self) -> bool:
        return self.severity == "error"

    @property
    def num_frames(self) -> int:
        return self.frame_end - self.frame_start + 1

    def to_dict(self) -> dict[str, Any]:
        out = asdict(self)
        out["depth"] = round(float(self.depth), 6)
        return out

    def describe(self, fps: float | None = None) -> str:
        """One line, e.g. ``obstacle_penetration left_elbow_link x table frames 40-55: 0.031``."""
        who = self.robot_body or "robot"
        if self.joint:
            who = self.joint
        if self.obstacle_geom:
            who += f" x {self.obstacle_geom}"
        span = (
            f"frame {self.frame_start}"
            if self.num_frames == 1
            else f"frames {self.frame_start}-{self.frame_end}"
        )
        if fps:
            span += f" ({self.frame_start / fps:.2f}-{self.frame_end / fps:.2f} s)"
        tag = "" if self.is_error else " (warning)"
        return f"{self.kind}{tag} {who} {span}: {self.depth:.4g}"


def runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """Inclusive (start, end) of each run of True in a 1-D boolean array."""
    mask = np.asarray(mask, dtype=bool)
    if not mask.any():
        return []
    edges = np.diff(np.concatenate([[0], mask.astype(np.int8), [0]]))
    starts = np.flatnonzero(edges == 1)
    ends = np.flatnonzero(edges == -1) - 1
    return list(zip(starts.tolist(), ends.tolist(), strict=True))


def from_mask(
    kind: str,
    mask: np.ndarray,
    values: np.ndarray,
    *,
    robot_body: str | None = None,
    obstacle_geom: str | None = None,
    joint: str | None = None,
    total: bool = False,
    severity: str = "error",
) -> list[Failure]:
    """One failure per run of ``mask``; depth = max of ``values`` over the run (sum if ``total``)."""
    out = []
    for a, b in runs(mask):
        seg = np.asarray(values[a : b + 1], dtype=np.float64)
        depth = float(np.nansum(seg) if total else np.nanmax(seg))
        out.append(Failure(kind, a, b, robot_body, obstacle_geom, depth, joint, severity))
    return out


def from_events(
    kind: str,
    frames: np.ndarray,
    keys: np.ndarray,
    depths: np.ndarray,
    label: Callable[[int], tuple[str | None, str | None]],
) -> list[Failure]:
    """Merge sparse (frame, key, depth) events into failures per key.

    Args:
        frames: (E,) frame index of each event.
        keys: (E,) integer key of each event (e.g. robot body * ngeom + geom); consecutive
            frames of the same key merge into one failure.
        depths: (E,) depth of each event; a failure's depth is the max over its frames.
        label: ``label(key) -> (robot_body, obstacle_geom)`` names for a key.
    """
    frames = np.asarray(frames, dtype=np.int64)
    keys = np.asarray(keys, dtype=np.int64)
    depths = np.asarray(depths, dtype=np.float64)
    if frames.size == 0:
        return []
    order = np.lexsort((frames, keys))
    frames, keys, depths = frames[order], keys[order], depths[order]
    # one entry per (key, frame): the deepest event
    first = np.concatenate([[True], (keys[1:] != keys[:-1]) | (frames[1:] != frames[:-1])])
    starts = np.flatnonzero(first)
    depth = np.maximum.reduceat(depths, starts)
    frames, keys = frames[starts], keys[starts]
    # runs: a new failure where the key changes or a frame is skipped
    new = np.concatenate([[True], (keys[1:] != keys[:-1]) | (frames[1:] != frames[:-1] + 1)])
    run_starts = np.flatnonzero(new)
    run_ends = np.concatenate([run_starts[1:], [frames.size]]) - 1
    worst = np.maximum.reduceat(depth, run_starts)
    out = []
    for a, b, d in zip(run_starts.tolist(), run_ends.tolist(), worst.tolist(), strict=True):
        body, geom = label(int(keys[a]))
        out.append(Failure(kind, int(frames[a]), int(frames[b]), body, geom, float(d)))
    return out


def sort_failures(failures: list[Failure]) -> list[Failure]:
    """Order errors before warnings, then by kind (as in :data:`KINDS`), start frame, body."""
    order = {k: i for i, k in enumerate(KINDS)}
    return sorted(
        failures,
        key=lambda f: (
            not f.is_error,
            order.get(f.kind, len(order)),
            f.frame_start,
            f.robot_body or "",
            f.obstacle_geom or "",
            f.joint or "",
        ),
    )
