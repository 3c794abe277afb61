"""Checks of a retargeted trajectory made with MuJoCo alone, as issue 35's checker makes them."""

from __future__ import annotations

from pathlib import Path

import mujoco
import numpy as np


def independent_check(path: Path, qpos: np.ndarray) -> tuple[int, float, int]:
    """(frames past a joint limit, deepest floor penetration m, frames with a robot-robot
    contact deeper than 5 mm), measured with MuJoCo alone on the robot MJCF plus a floor."""
    spec = mujoco.MjSpec.from_file(str(path))
    floor = spec.worldbody.add_geom()
    floor.type, floor.size, floor.name = mujoco.mjtGeom.mjGEOM_PLANE, [0, 0, 1], "check_floor"
    model = spec.compile()
    data = mujoco.MjData(model)
    floor_id = model.geom("check_floor").id
    hinge = [j for j in range(model.njnt) if model.jnt_type[j] == mujoco.mjtJoint.mjJNT_HINGE]
    q = qpos[:, model.jnt_qposadr[hinge]]
    lo, hi = model.jnt_range[hinge].T
    limits = int(np.any((q < lo - 1e-6) | (q > hi + 1e-6), axis=1).sum())
    floor_depth, self_frames = 0.0, 0
    for frame in qpos:
        data.qpos[:] = frame
        mujoco.mj_forward(model, data)
        contacts = data.contact[: data.ncon]
        on_floor = [c.dist for c in contacts if floor_id in (c.geom1, c.geom2)]
        floor_depth = max([floor_depth, *(-d for d in on_floor)])
        self_frames += any(floor_id not in (c.geom1, c.geom2) and c.dist < -0.005 for c in contacts)
    return limits, floor_depth, self_frames
