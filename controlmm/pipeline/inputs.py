"""Input checks before planning (a start pose clear of obstacles, reachable and free targets) and
the plan's default motion length.

* :func:`start_pose_error` - the robot standing at the scene's start must not overlap an obstacle
  (an error: nothing the generator does can fix it).
* :func:`constraint_warnings` - a target too far to reach in its time, at a height the joint cannot
  have, or inside an obstacle (warnings with the distance: the plan still runs and the report
  shows the error achieved).
* :func:`plan_seconds` - with a control spec and no length given, the motion ends 0.5 s after the
  last constraint (the generator's 6 s would leave the motion free to walk on into what the
  constraint stopped it at, e.g. the table it reaches across).
"""

from __future__ import annotations

import torch

from controlmm.control.reach import reach_warnings, target_name
from controlmm.control.spec import ControlSpec
from controlmm.frames import HumanToWorld
from controlmm.generate.api import frames_for
from controlmm.motion.skeleton import FPS, MAX_FRAMES, MIN_FRAMES
from sim import CheckConfig, check_pose

FRAMES_AFTER_LAST_CONSTRAINT = 10
"""How long a plan's motion runs on after its last constraint when no length is given (0.5 s)."""


def plan_seconds(seconds: float | None, spec: ControlSpec | None) -> float | None:
    """Motion length (s) a plan generates: ``seconds`` when given; None (the generator's default,
    6 s) without a spec; with one, the motion ends ``FRAMES_AFTER_LAST_CONSTRAINT`` frames after the
    last constrained frame, but never later than the generator's default would (6 s, or just long
    enough for a constraint after that) and never shorter than 2 s.
    """
    if seconds is not None or spec is None or not spec.constraints or spec.last_frame >= MAX_FRAMES:
        return seconds  # (a constraint past the longest motion fails in the generator, with its frame)
    end = spec.last_frame + 1  # frames needed to reach the last constraint
    return max(MIN_FRAMES, end, min(frames_for(1)[0], end + FRAMES_AFTER_LAST_CONSTRAINT)) / FPS


def start_pose_error(scene) -> str | None:
    """A one-line error when the robot's start pose penetrates an obstacle, else None."""
    report = check_pose(scene, scene.robot_start_qpos(), CheckConfig(dynamics=False))
    hits = [f for f in report.failures if f.kind == "obstacle_penetration"]
    if not hits:
        return None
    worst = max(hits, key=lambda f: f.depth)
    return (
        f"scene '{scene.name}': obstacle '{worst.obstacle_geom}' overlaps the robot's start pose at "
        f"x={scene.start.x:g}, y={scene.start.y:g} by {worst.depth * 100:.1f} cm; "
        f"move the obstacle or the start (controlmm.start)"
    )


def constraint_warnings(spec: ControlSpec, transform: HumanToWorld, sdf=None) -> list[str]:
    """Warnings for targets that look unreachable (:func:`controlmm.control.reach.reach_warnings`)
    or lie inside an obstacle of ``sdf``, one line each in constraint order (world metres)."""
    reach = reach_warnings(spec, transform)
    world = transform.to_world(spec.human_positions(transform))
    inside = None
    if sdf is not None:
        with torch.no_grad():
            inside = sdf(
                torch.as_tensor(world, dtype=torch.float64)[None],
                torch.zeros(1, dtype=torch.float64) if getattr(sdf, "is_moving", False) else None,
            )[0].numpy()
    warnings: list[str] = []
    for k, c in enumerate(spec.constraints):
        warnings += reach[k]
        if inside is not None and inside[k] < 0:
            warnings.append(
                f"{target_name(c.joint, c.frame, world[k])} is {-inside[k]:.2f} m inside an obstacle; "
                "the obstacle loss and the target pull against each other"
            )
    return warnings
