"""Targets a body cannot reach: warnings before generating (the generator still runs and reports
the error it achieved).

A constraint on joint ``j`` at frame ``t`` is flagged when its horizontal distance from the
motion's origin exceeds what the pelvis can travel in ``t / 20`` s at :data:`MAX_SPEED_MPS`
plus the joint's reach from the pelvis (:data:`REACH_M`), or when its height is outside the
heights the joint can have (:data:`HEIGHT_M`). Human frame: metres, Y up.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

from controlmm.control.spec import ControlSpec
from controlmm.frames import HumanToWorld
from controlmm.motion.skeleton import FPS, JOINT_NAMES

MAX_SPEED_MPS = 3.0
"""Fastest pelvis travel assumed reachable (human m/s): a run; the corpus' runs stay below it."""

REACH_M = {
    "pelvis": 0.0,
    "left_wrist": 0.85,
    "right_wrist": 0.85,
    "left_elbow": 0.6,
    "right_elbow": 0.6,
    "head": 0.45,
    "neck": 0.35,
}
"""Horizontal reach of a joint from the pelvis (human m); joints not listed: 0.6 (legs, torso)."""

HEIGHT_M = {
    "pelvis": (0.25, 1.45),
    "head": (0.35, 2.1),
    "neck": (0.3, 1.95),
    "left_wrist": (0.0, 2.35),
    "right_wrist": (0.0, 2.35),
    "left_elbow": (0.05, 2.1),
    "right_elbow": (0.05, 2.1),
}
"""Heights (human m, Y) a joint can have; joints not listed: 0 to 1.9 m."""


def reach_warnings(spec: ControlSpec, transform: HumanToWorld | None = None) -> list[list[str]]:
    """For each constraint of ``spec``, the reasons (one line each) its target looks unreachable:
    too far to reach in its time, or at a height its joint cannot have.

    With a ``transform`` (a plan's placement in its scene), positions are printed in the world
    frame and distances in world metres (human metres times ``transform.scale``); without one,
    in the human frame.
    """
    shown_in_world = transform is not None
    transform = transform or HumanToWorld()
    positions = spec.human_positions(transform)  # (K, 3) human frame
    shown = transform.to_world(positions) if shown_in_world else positions
    out: list[list[str]] = []
    for c, p, q in zip(spec.constraints, positions, shown, strict=True):
        warnings = []
        name = JOINT_NAMES[c.joint]
        where = target_name(c.joint, c.frame, q)
        t = c.frame / FPS
        horizontal = math.hypot(float(p[0]), float(p[2]))
        limit = MAX_SPEED_MPS * t + REACH_M.get(name, 0.6) + 0.1
        if horizontal > limit:
            warnings.append(
                f"{where} is {(horizontal - limit) * transform.scale:.2f} m beyond what the body can "
                f"reach in {t:.2f} s (at most {MAX_SPEED_MPS:g} m/s); it will likely be missed"
            )
        lo, hi = HEIGHT_M.get(name, (0.0, 1.9))
        if not lo <= p[1] <= hi:
            off = lo - p[1] if p[1] < lo else p[1] - hi
            warnings.append(
                f"{where} is {off * transform.scale:.2f} m {'below' if p[1] < lo else 'above'} the "
                f"heights a {name} can have ({lo * transform.scale:.2f}..{hi * transform.scale:.2f} m)"
            )
        out.append(warnings)
    return out


def target_name(joint: int, frame: int, position: Sequence[float]) -> str:
    """``"right_wrist at frame 80 (1.20, 0.00, 0.56)"``: how warnings name a target."""
    return f"{JOINT_NAMES[joint]} at frame {frame} ({', '.join(f'{v:.2f}' for v in position)})"
