"""Self-clearance margins calibrated on the real geoms of a solve (retarget.calibrated_margins).

The motion is the corpus's sit-down 000014 (``controlmm corpus --seed 0``, family
``sit_down``): the human's hands stay by the hips, where G1's loose hand and hip-link
enclosures kept its hands 1-3 cm further from its hips than its real geoms need.
"""

from __future__ import annotations

from dataclasses import replace

import mujoco
import numpy as np
import pytest

import scenes
import sim
from controlmm.corpus import CorpusConfig, make_clip
from controlmm.corpus.dataset import plan_clips
from controlmm.motion import Motion
from retarget import load_robot, retarget_motion
from retarget.calibrated_margins import CALIBRATED_GAP, CALIBRATION_FRAMES, calibrated_margins
from retarget.compare import similarity_fit
from retarget.kinematics import quat_to_mat
from retarget.selfcheck import OTHER_DEPTH, RELAX_FRACTION, RELAX_MOST
from retarget.selfcollision import capsule_distances
from retarget.solver_config import SolverConfig


@pytest.fixture(scope="module")
def sit_down() -> Motion:
    spec = plan_clips(CorpusConfig(clips=9800, seed=0))[14]
    assert spec.family == "sit_down"
    _, joints, _, _ = make_clip(spec)
    return Motion(joints=joints.astype(np.float64), fps=20.0)


def _deepest_contact(model: mujoco.MjModel, qpos: np.ndarray) -> float:
    """Deepest overlap (m) of any two geoms of the robot over the frames, by MuJoCo alone."""
    data = mujoco.MjData(model)
    worst = 0.0
    for frame in qpos:
        data.qpos[:] = frame
        mujoco.mj_kinematics(model, data)
        mujoco.mj_collision(model, data)
        for c in data.contact[: data.ncon]:
            if model.geom_bodyid[c.geom1] and model.geom_bodyid[c.geom2]:  # not the floor
                worst = max(worst, -float(c.dist))
    return worst


def test_calibrated_solve_brings_the_hands_closer_and_keeps_them_clear(sit_down):
    rm = load_robot("g1")
    traj = retarget_motion(sit_down, rm, fps=30.0, metrics=False)
    own = SolverConfig(**rm.mapping.solver)  # G1's flat contact feet
    off = retarget_motion(sit_down, rm, fps=30.0, metrics=False, config=replace(own, calibrated_iterations=0))
    assert traj.solver["self_clearance_solves"] > off.solver["self_clearance_solves"]
    fit = similarity_fit(rm, traj.qpos, 30.0, sit_down.joints, 20.0)
    fit_off = similarity_fit(rm, off.qpos, 30.0, sit_down.joints, 20.0)
    assert fit.mean < fit_off.mean - 0.005, (fit.mean, fit_off.mean)  # 4.02 against 4.83 cm written
    wrists = ("left_wrist", "right_wrist")
    assert all(fit.per_joint[w] < fit_off.per_joint[w] for w in wrists), fit.per_joint
    # No two geoms overlap beyond what the safe margins leave (a pelvis and its hip links by
    # 2-3 mm), and the simulation check finds no self-collision.
    assert _deepest_contact(rm.model, traj.qpos) <= OTHER_DEPTH + 1e-3
    report = sim.check_trajectory(scenes.load_scene("empty", robot="g1"), traj.qpos, 30.0)
    assert report.stats["self_collision_frames"] == 0
    assert report.passed, report.stats["error_kinds"]


def test_margins_come_down_by_what_the_real_geoms_leave(sit_down):
    """Each lowered margin leaves the real geoms ``CALIBRATED_GAP`` apart in the poses that
    calibrated it (the frames where its capsules are deepest inside the margin kept), measured
    here on their own; no margin rises, and exact enclosures keep theirs."""
    rm = load_robot("g1")
    own = SolverConfig(**rm.mapping.solver)
    solve = retarget_motion(
        sit_down, rm, fps=20.0, metrics=False, config=replace(own, calibrated_iterations=0)
    )
    assert rm.self_clearance is not None
    used = rm.self_clearance.relaxed(RELAX_FRACTION, RELAX_MOST)
    closer = calibrated_margins(rm.model, rm.tree, solve.qpos, used)
    assert closer is not None
    assert np.all(closer.margin <= used.margin)
    lowered = np.flatnonzero(closer.margin < used.margin - 1e-9)
    assert lowered.size >= 4  # the hands against the hip links, both sides
    assert closer.looseness is not None and np.all(closer.looseness[lowered] > 0)
    assert closer.safe_margin is not None and np.array_equal(closer.safe_margin, used.safe_margin)

    q = solve.qpos
    dist = capsule_distances(rm.tree.forward(q[:, :3], quat_to_mat(q[:, 3:7]), q[:, 7:]), used)[0]
    data = mujoco.MjData(rm.model)
    checked = 0
    for p in lowered:
        g1, g2 = int(used.geom[used.first[p]]), int(used.geom[used.second[p]])
        inside = np.flatnonzero(dist[:, p] < used.margin[p])
        assert inside.size > 0
        for frame in inside[np.argsort(dist[inside, p])][:CALIBRATION_FRAMES]:
            data.qpos[:] = q[frame]
            mujoco.mj_kinematics(rm.model, data)
            real = mujoco.mj_geomDistance(rm.model, data, g1, g2, 0.2, None)
            # the capsules brought from where they are to the new margin: the geoms that far closer
            assert real - (dist[frame, p] - closer.margin[p]) >= CALIBRATED_GAP - 1e-6
            checked += 1
    assert checked > 0
    assert calibrated_margins(rm.model, rm.tree, q, replace(used, looseness=None)) is None
