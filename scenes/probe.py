"""MuJoCo's own point distances, for validating SDFs: a tiny probe sphere on a mocap body.

MuJoCo has no geom-point distance function. ``mj_geomDistance(m, d, geom, probe, distmax)``
between a scene geom and a collision-free sphere of radius ``PROBE_RADIUS`` moved to the query
point gives the signed distance of the point (plus the probe's radius). MuJoCo collides mesh
geoms as their convex hulls, so for meshes this is the distance to the hull.
"""

from __future__ import annotations

from collections.abc import Sequence

import mujoco
import numpy as np

PROBE_RADIUS = 1e-6
PROBE_BODY = "controlmm_probe"


def add_probe(spec: mujoco.MjSpec) -> None:
    """Add the probe (a mocap body holding a tiny non-colliding sphere) to ``spec`` in place.

    Also tightens MuJoCo's convex collision tolerances (``ccd_iterations`` 200,
    ``ccd_tolerance`` 1e-10): with the defaults (35, 1e-6) penetration depths inside ellipsoids
    and meshes (EPA) are off by up to 0.5 mm.
    """
    spec.option.ccd_iterations = max(spec.option.ccd_iterations, 200)
    spec.option.ccd_tolerance = min(spec.option.ccd_tolerance, 1e-10)
    body = spec.worldbody.add_body(name=PROBE_BODY, mocap=True)
    body.add_geom(
        name=PROBE_BODY,
        type=mujoco.mjtGeom.mjGEOM_SPHERE,
        size=[PROBE_RADIUS, 0, 0],
        contype=0,
        conaffinity=0,
        group=5,
    )


def probe_distances(
    model: mujoco.MjModel,
    geom_ids: Sequence[int],
    points: np.ndarray,
    data: mujoco.MjData | None = None,
    distmax: float = 100.0,
) -> np.ndarray:
    """Signed distances (P, G) from world points (P, 3) to each geom, as MuJoCo computes them.

    ``model`` must hold the probe (:func:`add_probe`). ``data`` carries the poses of mocap
    obstacles (set them before the call); a fresh ``MjData`` is used when omitted.
    """
    data = mujoco.MjData(model) if data is None else data
    probe_geom = model.geom(PROBE_BODY).id
    mocap = model.body(PROBE_BODY).mocapid[0]
    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    out = np.empty((len(points), len(geom_ids)))
    for i, point in enumerate(points):
        data.mocap_pos[mocap] = point
        mujoco.mj_kinematics(model, data)
        for j, g in enumerate(geom_ids):
            out[i, j] = mujoco.mj_geomDistance(model, data, int(g), probe_geom, distmax, None) + PROBE_RADIUS
    return out
