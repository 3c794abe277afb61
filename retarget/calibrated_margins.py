"""Self-clearance margins calibrated on the real geoms of a solve that passed its check.

The relaxed margins (:mod:`retarget.selfcheck`: ``RELAX_FRACTION`` of a pair's looseness, at
most ``RELAX_MOST``) hold for any pose, so in a given motion the real geoms of a pair pressed
to its margin are often still far apart: G1's hands by its hips as it sits down (corpus clip
000014), their capsules at the margin in 164 frames, were 1.2 cm from the hip links at the
closest and 2-3 cm in most frames; the human's hands rest there, and the keypoints were
4.8 cm from the human's against 3.2 cm with no self-clearance at all.

:func:`calibrated_margins` measures, in the frames of the solve where a loose pair's capsules
are inside its margin (the ``CALIBRATION_FRAMES`` deepest), how much further apart its real
geoms are than its capsules (``mj_geomDistance``: convex hulls for meshes, as MuJoCo collides
them), and lowers the pair's margin by the smallest such excess, less ``CALIBRATED_GAP``:
where the capsules come to the new margin in those poses, the geoms are still that far apart.
The
retargeter solves again from the passing solve (:func:`retarget.retarget_motion`, a few
iterations at the motion's full rate: ``SolverConfig.calibrated_iterations``) and keeps the
new solve only where its real geoms overlap no deeper than the check allows.
"""

from __future__ import annotations

from dataclasses import replace

import mujoco
import numpy as np

from retarget.kinematics import KinematicTree, quat_to_mat
from retarget.selfcheck import geom_distances
from retarget.selfcollision import SelfClearance, close_pairs

CALIBRATION_FRAMES = 8
"""Frames in which each pair is measured at most: those where its capsules are deepest inside
its margin (a robot split into convex pieces has tens of thousands of pairs inside theirs)."""

CALIBRATED_GAP = 0.004
"""Metres the real geoms keep apart where the capsules come to a calibrated margin, in the
poses that calibrated it (the check allows relaxed pairs ``selfcheck.CHECK_DEPTH``, 2 mm, of
overlap where the next solve's poses differ)."""

CALIBRATED_SOLVES = 2
"""Solves at most with calibrated margins: the first, then, where its geoms overlap, one with
those pairs' safe margins back (:meth:`SelfClearance.tightened`)."""

MEASURED_UP_TO = 0.2
"""Geoms further apart than this (m) are measured as this far (``mj_geomDistance``'s cut-off)."""


def calibrated_margins(
    model: mujoco.MjModel, tree: KinematicTree, qpos: np.ndarray, clearance: SelfClearance
) -> SelfClearance | None:
    """``clearance`` (the margins a solve kept, P pairs) with each loose pair's margin lowered
    where its real geoms stayed further apart than its capsules in the frames of ``qpos``
    (T, nq) at the solver's rate (see the module); its ``safe_margin`` kept (the margins
    before any relaxing). Only margins of pairs whose ``looseness`` is above 0 and whose safe
    margin is at least 0 are lowered (enclosures that overlap at rest keep their calibration),
    never raised. None where no margin is lowered by a millimetre or more."""
    safe = clearance.margin if clearance.safe_margin is None else clearance.safe_margin
    if clearance.looseness is None:
        return None
    loose = (clearance.looseness > 0.0) & (safe >= 0.0)
    if not loose.any():
        return None
    qpos = np.asarray(qpos, dtype=np.float64)
    poses = tree.forward(qpos[:, :3], quat_to_mat(qpos[:, 3:7]), qpos[:, 7:])
    inside = close_pairs(poses, clearance)  # sparse: a robot split into convex pieces has 367,000 pairs
    keep = loose[inside.pair]
    frame, pair, dist = inside.frame[keep], inside.pair[keep], inside.dist[keep]
    if not pair.size:
        return None
    # Each pair's deepest CALIBRATION_FRAMES entries (furthest inside its margin).
    order = np.lexsort((dist, pair))
    frame, pair, dist = frame[order], pair[order], dist[order]
    starts = np.flatnonzero(np.r_[True, pair[1:] != pair[:-1]])
    rank = np.arange(len(pair)) - np.repeat(starts, np.diff(np.r_[starts, len(pair)]))
    take = rank < CALIBRATION_FRAMES
    frame, pair, dist = frame[take], pair[take], dist[take]
    geom1, geom2 = clearance.geom[clearance.first[pair]], clearance.geom[clearance.second[pair]]
    real = geom_distances(model, qpos, frame, geom1, geom2, MEASURED_UP_TO)
    excess = np.full(clearance.num_pairs, np.inf)  # (P,) real distance less the capsules'
    np.minimum.at(excess, pair, real - dist)
    margin = np.minimum(clearance.margin, np.where(np.isfinite(excess), CALIBRATED_GAP - excess, np.inf))
    if not np.any(margin < clearance.margin - 1e-3):
        return None
    return replace(clearance, margin=margin, safe_margin=safe)
