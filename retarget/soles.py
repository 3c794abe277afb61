"""Soles: the orientation in which a robot's foot stands flat on the floor.

The retargeter's foot targets are "flat" orientations: a stance foot lies on its sole. Most
MJCFs put the feet flat in ``qpos0``, but not all (the Berkeley Humanoid's ``qpos0`` pitches
its feet 10 degrees toe-up). :func:`flat_tilt` finds the smallest tilt (about the world's
horizontal axes) after which the foot stands on its largest footprint: the convex hull of the
foot's collision points (sphere centres, box corners, mesh hull vertices) within
``FOOTPRINT_TOL`` of its lowest point has the largest area.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import ConvexHull, QhullError

from retarget.kinematics import so3_exp

TILT_RANGE = 0.6
"""Largest tilt (rad) searched about each horizontal axis."""
COARSE_STEP = 0.02
TILT_STEP = 0.002
"""Grid steps (rad) of the search: coarse over the whole range, then fine around the best."""
FOOTPRINT_TOL = 0.001
"""Points within this height (m) of the lowest one are on the floor."""


def flat_tilt(points: np.ndarray, radius: np.ndarray, rot: np.ndarray) -> np.ndarray:
    """The tilt (3, 3), a rotation about the world x and y axes, that lays a foot flat.

    Args:
        points: (P, 3) collision points of the foot in its body frame; radius: (P,).
        rot: (3, 3) the foot body's world rotation in the rest pose.

    Returns:
        R such that ``R @ rot`` is the foot's flat orientation (the identity for a foot that
        already stands flat: among equal footprints the smallest tilt wins).
    """
    centre = np.zeros(2)
    # coarse, then fine (the coarse grid takes points within about a coarse step's rise as down)
    for step, half, tol in ((COARSE_STEP, TILT_RANGE, 0.002), (TILT_STEP, COARSE_STEP, FOOTPRINT_TOL)):
        offsets = np.arange(-half, half + 1e-9, step)
        roll, pitch = np.meshgrid(centre[0] + offsets, centre[1] + offsets, indexing="ij")
        vec = np.stack([roll.ravel(), pitch.ravel(), np.zeros(roll.size)], axis=1)  # (C, 3)
        score = _footprints(so3_exp(vec) @ rot, points, radius, tol)
        size = np.abs(vec).sum(axis=1)
        best = np.lexsort((size, -np.round(score, 8)))[0]  # the largest footprint, then the smallest tilt
        centre = vec[best, :2]
    return so3_exp(np.array([centre[0], centre[1], 0.0]))


def _footprints(rots: np.ndarray, points: np.ndarray, radius: np.ndarray, tol: float) -> np.ndarray:
    """(C,) area (m^2) of the convex hull of the points within ``tol`` of the floor, per
    orientation (C, 3, 3)."""
    world = np.einsum("cij,pj->cpi", rots, points)  # (C, P, 3)
    z = world[..., 2] - radius
    near = z <= z.min(axis=1, keepdims=True) + tol
    out = np.zeros(len(rots))
    for c in range(len(rots)):
        xy = world[c, near[c], :2]
        if len(xy) >= 3:
            try:
                out[c] = ConvexHull(xy).volume  # the area of a 2-D hull
            except QhullError:  # collinear points: no area
                pass
    return out


FOOT_POINTS_MOST = 64
"""A foot with more collision points than this (a mesh's hull vertices: PHC's G1 and H1, 500-1,000
a foot) keeps only those of :func:`lowest_candidates` (about 100-200 of them: the solver's
floor terms evaluate every point of every frame, and all of a finely meshed foot's took 70 %
of a call)."""
LOWEST_TILT = np.radians(75.0)
"""...the points that are the lowest of the foot for some tilt up to this from its rest pose
(a toe-off pitches a foot 40-60 degrees)..."""
LOWEST_DIRECTIONS = 2000
"""...sampled over this many evenly spread tilts."""


def lowest_candidates(points: np.ndarray, radius: np.ndarray, rot: np.ndarray) -> np.ndarray:
    """Indices of the foot's points (P, 3, in its body frame; radii (P,)) that are the lowest
    for some tilt of at most ``LOWEST_TILT`` from ``rot`` (3, 3, its rest orientation): the
    support points of the directions of a spherical cap around -Z (Fibonacci-spread). All of
    them where there are no more than ``FOOT_POINTS_MOST``."""
    if len(points) <= FOOT_POINTS_MOST:
        return np.arange(len(points))
    i = np.arange(LOWEST_DIRECTIONS) + 0.5
    cos = 1.0 - (1.0 - np.cos(LOWEST_TILT)) * i / LOWEST_DIRECTIONS
    sin = np.sqrt(1.0 - cos * cos)
    turn = i * np.pi * (3.0 - np.sqrt(5.0))
    down = np.stack([sin * np.cos(turn), sin * np.sin(turn), -cos], axis=1)  # (D, 3)
    depth = (points @ rot.T) @ down.T + radius[:, None]  # (P, D): how far down each point reaches
    return np.unique(np.argmax(depth, axis=0))
