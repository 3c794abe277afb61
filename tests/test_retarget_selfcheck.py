"""The arms' self-clearance relaxed where the enclosures are loose, checked on the real geoms.

The motion is the corpus's first clip (``controlmm corpus --seed 0``, clip 000000, family
``pick_up``: a deep stoop with the hands at the feet), where the safe 2 cm margins between
G1's arm and leg capsules cost the fit most.
"""

from __future__ import annotations

from dataclasses import replace

import mujoco
import numpy as np
import pytest
from robot_checks import independent_check

import scenes
import sim
from controlmm.corpus import CorpusConfig, make_clip
from controlmm.corpus.dataset import plan_clips
from controlmm.frames import HumanToWorld
from controlmm.motion import Motion
from controlmm.motion.container import resample
from retarget import RobotModel, load_robot, retarget_motion, robot_mjcf, robot_mjcf_path
from retarget.capsules import robot_capsules
from retarget.compare import robot_keypoints, similarity_fit, stance_foot_speed
from retarget.human import size_ratio
from retarget.kinematics import KinematicTree, quat_to_mat
from retarget.metrics import replay, trajectory_metrics
from retarget.retarget_motion import (
    _gives_up_a_pass,
    _keypoint_error,
    _output_overlap,
    _rung_kept,
    _solve_clear_of_self,
    _with_relaxed_pairs,
    _with_room,
)
from retarget.selfcheck import (
    BALL_MARGIN,
    BALL_RADIUS,
    CHECK_DEPTH,
    OTHER_DEPTH,
    OUTPUT_FAR_DEPTH,
    OUTPUT_FIT_GIVE,
    OUTPUT_LIFT,
    OUTPUT_NEAR_GIVE,
    OUTPUT_SELF,
    OUTPUT_SLIP,
    OUTPUT_SPEED,
    RELAX_FRACTION,
    RELAX_MOST,
    RELAXED_SOLVES,
    _pair_index,
    contact_balls,
    overlap_frames,
    overlap_gaps,
    pair_overlaps,
    penetration_depths,
)
from retarget.selfcollision import SelfClearance, capsule_distances
from retarget.solver_config import SolverConfig
from retarget.targets import build_targets


@pytest.fixture(scope="module")
def stoop() -> Motion:
    spec = plan_clips(CorpusConfig(clips=9800, seed=0))[0]
    assert spec.family == "pick_up"
    _, joints, _, _ = make_clip(spec)
    return Motion(joints=joints.astype(np.float64), fps=20.0)


def _contact_depths(model: mujoco.MjModel, qpos: np.ndarray) -> dict[tuple[int, int], float]:
    """Deepest overlap (m) of every pair of geoms over the frames, by MuJoCo alone."""
    data = mujoco.MjData(model)
    out: dict[tuple[int, int], float] = {}
    for frame in qpos:
        data.qpos[:] = frame
        mujoco.mj_kinematics(model, data)
        mujoco.mj_collision(model, data)
        for c in data.contact[: data.ncon]:
            key = (min(c.geom1, c.geom2), max(c.geom1, c.geom2))
            out[key] = max(out.get(key, 0.0), -float(c.dist))
    return out


def test_relaxed_margins_follow_the_looseness_of_the_enclosures():
    g1 = load_robot("g1").self_clearance
    relaxed = g1.relaxed(RELAX_FRACTION, RELAX_MOST)
    # The relaxed solve also keeps the trunk from the shoulder links (G1's meshes: 10 pairs).
    base = g1.relaxed_pairs
    assert base is not None and relaxed.num_pairs == base.num_pairs == g1.num_pairs + 10
    np.testing.assert_array_equal(relaxed.safe_margin, base.margin)
    bigger = base.margin >= 0
    np.testing.assert_allclose(
        relaxed.margin[bigger],
        base.margin[bigger] - np.minimum(RELAX_FRACTION * base.looseness[bigger], RELAX_MOST),
    )
    np.testing.assert_array_equal(relaxed.margin[~bigger], base.margin[~bigger])
    assert (relaxed.margin < base.margin).sum() > 100  # G1's links are meshes: most pairs relax
    # H1's collision geoms are capsules, cylinders and boxes: nothing to relax, no extra pairs.
    h1 = load_robot("h1").self_clearance
    assert not np.any(h1.looseness > 0) and h1.relaxed_pairs is None
    np.testing.assert_array_equal(h1.relaxed(RELAX_FRACTION, RELAX_MOST).margin, h1.margin)
    # More room only where the real geoms overlap beyond the tolerance.
    depth = np.zeros(relaxed.num_pairs)
    depth[[0, 1]] = [0.004, 0.001]
    tight = relaxed.tightened(depth, CHECK_DEPTH)
    assert tight.margin[0] == pytest.approx(max(base.margin[0], relaxed.margin[0] + 0.004))
    np.testing.assert_array_equal(tight.margin[1:], relaxed.margin[1:])


@pytest.fixture(scope="module")
def loose_stoop(stoop) -> tuple[RobotModel, np.ndarray]:
    """G1 and the stoop retargeted without self-clearance (T, nq) at 30 fps: its arms in its legs."""
    rm = load_robot("g1")
    loose = retarget_motion(
        stoop,
        rm,
        fps=30.0,
        metrics=False,
        config=replace(SolverConfig(**rm.mapping.solver), self_clearance=False),
    )
    return rm, loose.qpos


def test_penetration_depths_are_mujocos(loose_stoop):
    """Without self-clearance the stoop's arms pass into the legs; the check reports, per pair,
    the depth MuJoCo's own collision detection finds for those two geoms."""
    rm, q = loose_stoop
    sc = rm.self_clearance.relaxed(RELAX_FRACTION, RELAX_MOST)
    depth = penetration_depths(rm.model, rm.tree, q, sc, other_depth=np.inf)
    assert depth.max() > 0.02  # centimetres into the thighs
    truth = _contact_depths(rm.model, q)
    for k in np.flatnonzero(depth > 0):
        a, b = int(sc.geom[sc.first[k]]), int(sc.geom[sc.second[k]])
        assert depth[k] == pytest.approx(truth[(min(a, b), max(a, b))], abs=1e-9)
    # Every overlap of a listed pair deeper than the tolerance is found.
    listed = {
        (min(int(a), int(b)), max(int(a), int(b)))
        for a, b in zip(sc.geom[sc.first], sc.geom[sc.second], strict=True)
    }
    for key, d in truth.items():
        if key in listed and d > CHECK_DEPTH:
            k = next(
                i
                for i in range(sc.num_pairs)
                if {int(sc.geom[sc.first[i]]), int(sc.geom[sc.second[i]])} == set(key)
            )
            assert depth[k] == pytest.approx(d)


def test_a_pair_overlapping_gets_room_from_where_its_capsules_were(loose_stoop):
    """More room for a pair whose geoms overlap counts from its capsules' distance in the frame
    of the deepest overlap (overlap_gaps): loose enclosures that overlap at rest (a shoulder
    link's inside the torso's) may overlap with the capsules outside their margin, where the
    margin plus the depth pushes nothing apart."""
    rm, q = loose_stoop
    sc = rm.self_clearance
    per = np.zeros((len(q), sc.num_pairs))  # (T, P)
    frame, pair, depth = pair_overlaps(rm.model, rm.tree, q, sc)
    per[frame, pair] = depth
    assert len(frame) == len(set(zip(frame, pair, strict=True))) and np.all(
        np.diff(frame * sc.num_pairs + pair) > 0
    )
    gaps = overlap_gaps(rm.model, rm.tree, q, sc)
    hit = per.max(axis=0) > 0
    assert hit.sum() >= 3 and np.all(np.isneginf(gaps[~hit]))
    poses = rm.tree.forward(q[:, :3], quat_to_mat(q[:, 3:7]), q[:, 7:])
    dist = capsule_distances(poses, sc)[0]  # (T, P)
    for k in np.flatnonzero(hit):
        assert gaps[k] == pytest.approx(dist[per[:, k].argmax(), k])
    depth = per.max(axis=0)
    tight = sc.tightened(depth, OTHER_DEPTH, gaps)
    bad = depth > OTHER_DEPTH
    np.testing.assert_allclose(
        tight.margin[bad], np.maximum(sc.tightened(depth, OTHER_DEPTH).margin[bad], gaps[bad] + depth[bad])
    )
    np.testing.assert_array_equal(tight.margin[~bad], sc.margin[~bad])
    # Frames with two geoms deeper than 5 mm, as an independent MuJoCo check counts them.
    assert overlap_frames(rm.model, q) == independent_check(robot_mjcf_path("g1"), q)[2] > 0
    # The output check replays every frame: each pair's depth is MuJoCo's deepest over all.
    every = penetration_depths(rm.model, rm.tree, q, sc, other_depth=np.inf, every_frame=True)
    truth = _contact_depths(rm.model, q)
    for k in range(sc.num_pairs):
        a, b = int(sc.geom[sc.first[k]]), int(sc.geom[sc.second[k]])
        assert every[k] == pytest.approx(max(truth.get((min(a, b), max(a, b)), 0.0), 0.0), abs=1e-9)


def test_an_overlap_between_the_calibration_poses_is_found():
    """The trunk-shoulder margins are calibrated on a sweep of a few joints; between its poses
    the real geoms may overlap with their capsules outside the margin. G1's right shoulder-yaw
    link 7 mm inside the torso, their capsules just outside the margin and no other pair close:
    the check sees it (on the old code MuJoCo was never asked about that frame)."""
    rm = load_robot("g1")
    sc = rm.self_clearance.relaxed_pairs
    q = rm.rest_q.copy()
    for name, angle in (("pitch", -0.44), ("roll", 0.11), ("yaw", 0.92)):
        q[rm.tree.joint_names.index(f"right_shoulder_{name}_joint")] = angle
    q[rm.tree.joint_names.index("right_elbow_joint")] = 1.3
    qpos = np.concatenate([[0.0, 0.0, 1.0, 1.0, 0.0, 0.0, 0.0], q])[None]
    bodies = [
        {rm.model.body(int(rm.model.geom_bodyid[sc.geom[i]])).name for i in (a, b)}
        for a, b in zip(sc.first, sc.second, strict=True)
    ]
    k = bodies.index({"right_shoulder_yaw_link", "torso_link"})
    poses = rm.tree.forward(qpos[:, :3], np.eye(3)[None], qpos[:, 7:])
    assert capsule_distances(poses, sc)[0][0, k] > sc.margin[k]
    a, b = int(sc.geom[sc.first[k]]), int(sc.geom[sc.second[k]])
    truth = _contact_depths(rm.model, qpos)[(min(a, b), max(a, b))]
    assert truth > OTHER_DEPTH
    assert penetration_depths(rm.model, rm.tree, qpos, sc)[k] == pytest.approx(truth)


def test_a_grown_clearance_still_sees_the_trunk_against_a_shoulder():
    """A clearance grown by the output check (a pair or balls added) no longer carries the
    relaxed solves' trunk-shoulder pairs; where the output has a shoulder in the torso deeper
    than OTHER_DEPTH, the robot's own pair for it is added back, so the rungs see and clear it
    (Unitree R1's upper arm 8.9 mm in its torso in corpus clip 000000 went unseen). G1's right
    shoulder-roll link 8.5 mm inside its torso (a pair only the relaxed solves keep)."""
    rm = load_robot("g1")
    relaxed = rm.self_clearance.relaxed_pairs
    q = rm.rest_q.copy()
    q[rm.tree.joint_names.index("right_shoulder_pitch_joint")] = -1.0
    q[rm.tree.joint_names.index("right_shoulder_roll_joint")] = 0.3
    qpos = np.concatenate([[0.0, 0.0, 1.0, 1.0, 0.0, 0.0, 0.0], q])[None]
    grown = rm.self_clearance.with_pairs(np.array([0]), np.array([1]), 0.01)
    assert grown.relaxed_pairs is None
    seen = _with_relaxed_pairs(rm, qpos, grown)
    new = np.arange(grown.num_pairs, seen.num_pairs)
    bodies = [
        {
            rm.model.body(int(rm.model.geom_bodyid[relaxed.geom[c]])).name
            for c in (seen.first[k], seen.second[k])
        }
        for k in new
    ]
    shoulder = [
        k for k, b in zip(new, bodies, strict=True) if b == {"right_shoulder_roll_link", "torso_link"}
    ]
    assert shoulder, bodies
    assert _output_overlap(rm, qpos, seen)[shoulder].max() > OTHER_DEPTH


def test_the_stoop_fits_closer_and_stays_clear_of_itself(stoop):
    rm = load_robot("g1")
    traj = retarget_motion(stoop, rm, fps=30.0, metrics=False)
    safe = retarget_motion(
        stoop, rm.with_self_clearance(replace(rm.self_clearance, looseness=None)), fps=30.0, metrics=False
    )
    assert safe.solver["self_clearance_solves"] == 1
    fit = similarity_fit(rm, traj.qpos, 30.0, stoop.joints, 20.0).mean
    fit_safe = similarity_fit(rm, safe.qpos, 30.0, stoop.joints, 20.0).mean
    assert fit < fit_safe - 0.005, (fit, fit_safe)  # 3.0 against 3.9 cm when measured
    # No two geoms of the robot overlap beyond what the safe margins leave (a pelvis and its hip
    # links by 2-3 mm), and the simulation check finds no self-collision.
    worst = max(_contact_depths(rm.model, traj.qpos).values(), default=0.0)
    assert worst <= OTHER_DEPTH + 1e-3, worst
    report = sim.check_trajectory(scenes.load_scene("empty", robot="g1"), traj.qpos, 30.0)
    assert report.stats["self_collision_frames"] == 0
    assert report.passed, report.stats["error_kinds"]


def test_planted_feet_hold_between_the_solver_frames(stoop):
    """Both feet stay planted through the stoop. Solved at 20 fps and resampled to 30, the
    spline made them wobble by ~0.15 mm per frame (0.45 cm/s); held, they stay within the
    solver's own drift (~0.1 cm/s)."""
    rm = load_robot("g1")
    at20 = retarget_motion(stoop, rm, fps=20.0, metrics=False)
    at30 = retarget_motion(stoop, rm, fps=30.0, metrics=False)
    speed20 = stance_foot_speed(rm, at20.qpos, 20.0, stoop.joints, 20.0)
    speed30 = stance_foot_speed(rm, at30.qpos, 30.0, stoop.joints, 20.0)
    assert speed30 < 0.002
    assert speed30 < 1.5 * speed20 + 0.0005, (speed30, speed20)


def test_the_safe_solve_is_checked_too():
    """Corpus clip 000703 (``kneel`` on the right knee, the right arm against the torso): the
    relaxed solve presses the right shoulder into the torso (2.3 cm), and the safe margins
    alone still leave them 8.8 mm deep (an enclosure pair that overlaps at rest: its margin is
    negative). The safe solve is checked as well, and the pair gets that much more room for a
    last solve: no self-collision, and the motion passes the simulation check."""
    spec = plan_clips(CorpusConfig(clips=9800, seed=0))[703]
    assert spec.family == "kneel"
    _, joints, _, _ = make_clip(spec)
    traj = retarget_motion(Motion(joints=joints.astype(np.float64), fps=20.0), "g1", fps=30.0, metrics=False)
    report = sim.check_trajectory(scenes.load_scene("empty", robot="g1"), traj.qpos, 30.0)
    assert report.stats["self_collision_frames"] == 0, [
        f for f in report.failures if f.kind == "self_collision"
    ]
    assert report.passed, report.stats["error_kinds"]


def test_the_output_frames_are_checked_at_the_end():
    """Corpus clip 000005 (``pick_up``, a stoop) at 30 fps: G1's last solve at the motion's
    rate (20 fps) swings the right arm from one side of the right hip links to the other
    between two of its frames (shoulder roll -0.14 -> 0.18 rad), so the output frames in
    between have the wrist 4 cm inside the hip. The output frames are checked too and the clip
    is solved again: at the motion's rate with the pairs kept apart halfway between frames
    (which overlaps more here: not kept), then at the output rate with a stiffer
    self-clearance, each rung of ``OUTPUT_SELF`` while the overlap lasts (here two; all three
    before the coarse level settled over more iterations): no self-collision left."""
    spec = plan_clips(CorpusConfig(clips=9800, seed=0))[5]
    assert spec.family == "pick_up"
    _, joints, _, _ = make_clip(spec)
    traj = retarget_motion(Motion(joints=joints.astype(np.float64), fps=20.0), "g1", fps=30.0)
    # the relaxed solves, the safe one and its tightened one, the midpoint one, output-rate ones
    assert (
        RELAXED_SOLVES + 2 + 1
        < traj.solver["self_clearance_solves"]
        <= RELAXED_SOLVES + 2 + 1 + 2 * len(OUTPUT_SELF)  # each rung: planted feet as they were, stiffer
    )
    report = sim.check_trajectory(scenes.load_scene("empty", robot="g1"), traj.qpos, 30.0)
    assert report.stats["self_collision_frames"] == 0, [
        f for f in report.failures if f.kind == "self_collision"
    ]
    # the metrics of the output-rate solve kept measure it against the human at its own rate
    human = np.asarray(traj.transform.to_world(joints.astype(np.float64)))
    again = trajectory_metrics(load_robot("g1"), traj.qpos, 30.0, human, 20.0)
    assert traj.metrics["keypoint_error_mm"]["all"]["mean"] == pytest.approx(
        again["keypoint_error_mm"]["all"]["mean"], rel=0.05
    )


@pytest.mark.parametrize("fps", [30.0, 50.0])
def test_a_stoop_keeps_g1s_hand_and_hips_apart_at_every_output_rate(fps):
    """Corpus clip 000005 (``pick_up``, a stoop with the left hand): at 50 fps the swing-foot
    lift after the solve bent G1's left hip into its left hand (2.7 cm, the solver's frames
    clear) and straightened the right knee at 23 rad/s (limit 20); at 30 fps the output-rate
    solve left the pelvis 5.9 mm into the right hip-roll link. The lift may not bring real
    geoms deeper into each other nor turn a joint faster than ``LIFT_SPEED``, and pairs the
    output-rate solve leaves overlapping get more room for one more: no self-collision, no
    joint past its speed limit."""
    spec = plan_clips(CorpusConfig(clips=9800, seed=0))[5]
    assert spec.family == "pick_up"
    _, joints, _, _ = make_clip(spec)
    traj = retarget_motion(Motion(joints=joints.astype(np.float64), fps=20.0), "g1", fps=fps, metrics=False)
    report = sim.check_trajectory(scenes.load_scene("empty", robot="g1"), traj.qpos, fps)
    assert report.stats["self_collision_frames"] == 0, [
        f for f in report.failures if f.kind == "self_collision"
    ]
    assert not [f for f in report.failures if f.kind == "joint_velocity" and f.severity == "error"]
    speed = np.abs(np.diff(traj.qpos[:, 7:], axis=0)) * fps
    assert speed.max() <= 20.0


def test_a_sweep_between_the_solver_frames_is_solved_again_with_the_midpoints():
    """Corpus clip 000012 (``sit_down``) on H1 at 50 fps: the first solve's elbows sweep 3 cm
    into the hips between two of its 20 fps frames. The output check solves it again at the
    motion's rate with the pairs kept apart halfway between frames (``self_midpoints``), which
    clears them: two solves, no output-rate one (whose x3 and x10 rungs slid the planted feet
    2 cm a frame and the x30 one 4.8 mm in a frame: 0.24 m/s, failing the simulation check),
    and the motion passes the simulation check."""
    spec = plan_clips(CorpusConfig(clips=9800, seed=0))[12]
    assert spec.family == "sit_down"
    _, joints, _, _ = make_clip(spec)
    traj = retarget_motion(Motion(joints=joints.astype(np.float64), fps=20.0), "h1", fps=50.0, metrics=False)
    assert traj.solver["self_clearance_solves"] == 2
    report = sim.check_trajectory(scenes.load_scene("empty", robot="h1"), traj.qpos, 50.0)
    assert report.stats["self_collision_frames"] == 0
    assert report.passed, report.stats["error_kinds"]


def test_the_output_is_checked_with_the_trunk_against_the_shoulders():
    """Corpus clip 000012 (``sit_down``) on G1 with its hands (the asset package's
    ``g1_with_hands.xml``, 43 DoF, given by path) at 30 fps: the relaxed solves overlap and the
    safe margins, which leave the trunk-shoulder pairs out, end with the right shoulder-yaw
    link 2.3 cm inside the torso in 25 frames. The output is checked with those pairs too, and
    solved again with them: no self-collision, and the motion passes the simulation check."""
    spec = plan_clips(CorpusConfig(clips=9800, seed=0))[12]
    assert spec.family == "sit_down"
    _, joints, _, _ = make_clip(spec)
    robot = robot_mjcf("g1").with_name("g1_with_hands.xml")
    traj = retarget_motion(Motion(joints=joints.astype(np.float64), fps=20.0), robot, fps=30.0, metrics=False)
    assert traj.qpos.shape[1] == 50
    report = sim.check_trajectory(scenes.load_scene("empty", robot=robot), traj.qpos, 30.0)
    assert report.stats["self_collision_frames"] == 0, [
        f.describe() for f in report.failures if f.kind == "self_collision"
    ]
    assert report.passed, report.stats["error_kinds"]


def test_a_seated_robot_keeps_its_feet_planted_while_its_shoulders_leave_its_torso():
    """Corpus clip 65 of the corpus plan (``walk_then_sit``) on G1 with its hands at 30 fps:
    the output-rate solves with only the self-clearance stiffer either slid a planted foot
    (x10: 27 mm in a frame) or left the right shoulder-yaw link up to 13 mm inside the torso
    (28 frames; the trunk-shoulder pairs were not counted in those solves). Each rung is now
    also solved with the planted feet's locks as stiff as the self-clearance, and the pairs
    are counted: the arms give way, the feet stay, no self-collision and the motion passes
    the simulation check."""
    spec = plan_clips(CorpusConfig(clips=9800, seed=0))[65]
    assert spec.family == "walk_then_sit"
    _, joints, _, _ = make_clip(spec)
    robot = robot_mjcf("g1").with_name("g1_with_hands.xml")
    traj = retarget_motion(Motion(joints=joints.astype(np.float64), fps=20.0), robot, fps=30.0, metrics=False)
    report = sim.check_trajectory(scenes.load_scene("empty", robot=robot), traj.qpos, 30.0)
    assert report.stats["self_collision_frames"] == 0, [
        f.describe() for f in report.failures if f.kind == "self_collision"
    ]
    assert report.passed, report.stats["error_kinds"]


def test_the_output_check_keeps_a_solve_only_if_it_overlaps_less_and_slides_no_more():
    """The rule of the output check's solves (``OUTPUT_SLIP``, ``OUTPUT_LIFT``, and for the midpoint solve no
    pair deeper than before and than ``OTHER_DEPTH``), on overlaps (m) of three pairs."""
    depth, slip = np.array([0.030, 0.006, 0.0]), 0.010
    assert _rung_kept(depth, slip, np.array([0.010, 0.006, 0.0]), 0.012, midpoint=False)
    assert not _rung_kept(depth, slip, np.array([0.030, 0.0, 0.0]), 0.001, midpoint=False)  # as deep
    assert not _rung_kept(depth, slip, np.array([0.010, 0.0, 0.0]), OUTPUT_SLIP + 0.001, midpoint=False)
    assert _rung_kept(depth, 0.020, np.array([0.010, 0.0, 0.0]), 0.020, midpoint=False)  # no further
    # the midpoint solve may not trade one overlap for another; a new pair counts from 0
    trade = np.array([0.010, 0.008, 0.0])
    assert _rung_kept(depth, slip, trade, slip, midpoint=False)
    assert not _rung_kept(depth, slip, trade, slip, midpoint=True)
    assert _rung_kept(depth, slip, np.array([0.010, 0.006, OTHER_DEPTH, OTHER_DEPTH]), slip, midpoint=True)
    assert not _rung_kept(depth, slip, np.array([0.010, 0.0, 0.0, 0.005]), slip, midpoint=True)
    # a new solve whose check found fewer unpaired geoms has fewer pairs (DRC-Hubo's: it raised)
    assert _rung_kept(depth, slip, np.array([0.010, 0.006]), slip, midpoint=True)
    assert not _rung_kept(depth, slip, np.array([0.010, 0.008]), slip, midpoint=True)
    # No joint turning faster than before and than OUTPUT_SPEED.
    speed = np.array([1.0, 9.0])
    less = np.array([0.010, 0.0, 0.0])
    assert _rung_kept(depth, slip, less, slip, False, speed, np.array([OUTPUT_SPEED, 9.0]))
    assert not _rung_kept(depth, slip, less, slip, False, speed, np.array([1.0, 9.5]))
    assert not _rung_kept(depth, slip, less, slip, False, speed, np.array([OUTPUT_SPEED + 0.1, 1.0]))
    # Nor one with more frames overlapping deeper than OUTPUT_FAR_DEPTH (shallower but spread).
    assert _rung_kept(depth, slip, less, slip, False, speed, speed, 3, 3)
    assert not _rung_kept(depth, slip, less, slip, False, speed, speed, 3, 57)
    # Nor one lifted off the floor (a geom below it) more than before and than OUTPUT_LIFT.
    assert _rung_kept(depth, slip, less, slip, False, speed, speed, 3, 3, 0.002, OUTPUT_LIFT)
    assert _rung_kept(depth, slip, less, slip, False, speed, speed, 3, 3, 0.03, 0.03)
    assert not _rung_kept(depth, slip, less, slip, False, speed, speed, 3, 3, 0.002, 0.035)


def test_the_output_check_measures_how_far_a_solve_gives_up_the_motion(stoop):
    """``_keypoint_error`` (the output check keeps no solve whose keypoints end more than
    ``OUTPUT_FIT_GIVE`` further from their targets than its first solve's): the mean distance of
    the robot's keypoints to the targets, 0 against its own keypoints, the shift against shifted
    ones, and G1's stoop a few centimetres from the targets it was solved for."""
    robot = load_robot("g1")
    traj = retarget_motion(stoop, "g1", fps=30.0, metrics=False)
    rep = replay(robot.model, traj.qpos)
    own = robot_keypoints(robot, traj.qpos)
    assert _keypoint_error(robot, rep, own) == pytest.approx(0.0, abs=1e-9)
    assert _keypoint_error(robot, rep, own + np.array([0.0, 0.03, 0.04])) == pytest.approx(0.05)
    dense = resample(stoop.joints, stoop.fps, 30.0)
    targets = build_targets(robot, dense, 30.0, traj.transform, SolverConfig(**robot.mapping.solver))
    assert 0.005 < _keypoint_error(robot, rep, targets.kp_pos) < 0.05


def test_apollos_thighs_stay_apart_in_a_turn():
    """Corpus clip 000006 (``turn_right``): Apollo's thighs, capsules of 10.5 cm radius 2 cm apart
    at rest, meet when its hips flex and turn in. Its capsules are its geoms (no loose
    enclosures): one solve with the safe margins left them 3 cm into each other and the
    swing-foot lift after it 1 cm more. Those pairs get more room and a stiffer weight for
    another solve, and the lift may not push exact capsules into each other: no
    self-collision, by the simulation check and by MuJoCo on the thigh geoms."""
    spec = plan_clips(CorpusConfig(clips=9800, seed=0))[6]
    assert spec.family == "turn_right"
    _, joints, _, _ = make_clip(spec)
    traj = retarget_motion(
        Motion(joints=joints.astype(np.float64), fps=20.0), "apollo", fps=50.0, metrics=False
    )
    assert traj.solver["self_clearance_solves"] >= 2  # the first solve overlapped
    report = sim.check_trajectory(scenes.load_scene("empty", robot="apollo"), traj.qpos, 50.0)
    assert report.stats["self_collision_frames"] == 0, [
        f for f in report.failures if f.kind == "self_collision"
    ]
    rm = load_robot("apollo")
    model, data = rm.model, mujoco.MjData(rm.model)
    left, right = (
        model.geom("collision_capsule_body_l_thigh").id,
        model.geom("collision_capsule_body_r_thigh").id,
    )
    gap = []
    for frame in traj.qpos:
        data.qpos[:] = frame
        mujoco.mj_kinematics(model, data)
        gap.append(mujoco.mj_geomDistance(model, data, left, right, 1.0, None))
    assert min(gap) > -0.005


def test_the_output_check_also_solves_from_the_room_the_first_solves_found():
    """Apollo on corpus clip 000006 (its thighs meet in a turn, exact capsules): the solves
    before the output check give the thigh pair more room than the safe margin; they hand
    that room on (the output check's rungs solve once more from it: before, they began again
    from the safe margins only, where ToddlerBot's elbow sat 5.3 mm in its box chest for 28
    frames of a carry, 0 from the room found), the other pairs as they were, and the safe
    clearance with it."""
    spec = plan_clips(CorpusConfig(clips=9800, seed=0))[6]
    _, joints, _, _ = make_clip(spec)
    rm = load_robot("apollo")
    config = SolverConfig(**rm.mapping.solver)
    transform = HumanToWorld(scale=rm.scale * size_ratio(joints))
    targets = build_targets(rm, joints.astype(np.float64), 20.0, transform, config)
    *_, solves, safe, handed_on = _solve_clear_of_self(rm, targets, config, "batched", 20.0, 30.0)
    base = rm.self_clearance
    assert solves >= 2 and handed_on is not None and base is not None and safe is not None
    assert np.array_equal(safe.margin[: len(base.margin)], base.margin)
    assert np.array_equal(handed_on.first[: len(base.first)], base.first)
    extra = handed_on.margin[: len(base.margin)] - base.margin
    assert extra.min() >= 0.0
    model = rm.model
    thighs = {
        model.geom("collision_capsule_body_l_thigh").id,
        model.geom("collision_capsule_body_r_thigh").id,
    }
    pairs = {int(k) for k in np.flatnonzero(extra > 0.001)}
    assert pairs and all(
        {int(base.geom[base.first[k]]), int(base.geom[base.second[k]])} == thighs for k in pairs
    ), pairs
    # The output check's room ladder starts from those margins, and only where they add room.
    roomier = _with_room(safe, handed_on)
    assert roomier is not None and _with_room(safe, safe) is None
    n = len(handed_on.margin)
    assert np.array_equal(roomier.margin[:n], np.maximum(safe.margin[:n], handed_on.margin))


_CYLINDER_HIPS = """<mujoco><compiler angle="degree"/><worldbody>
<body name="pelvis" pos="0 0 1"><freejoint/><inertial pos="0 0 0" mass="5" diaginertia="0.1 0.1 0.1"/>
<body name="hip_l" pos="0 0.085 0"><joint name="yaw_l" axis="0 0 1" range="-60 60"/>
<geom type="cylinder" size="0.06 0.07" euler="90 0 0"/></body>
<body name="hip_r" pos="0 -0.085 0"><joint name="yaw_r" axis="0 0 1" range="-60 60"/>
<geom type="cylinder" size="0.06 0.07" euler="90 0 0"/></body>
</body></worldbody></mujoco>"""
"""Kuavo S45's hips (GMR's file): a cylinder across each, 6 cm in radius and 14 cm long, the
flat ends 3 cm apart; a hip yaw turns each about its centre."""


def test_balls_at_a_contact_see_what_the_enclosing_capsules_miss():
    """Turning the hips toes-out swings the back rims of the two cylinders into each other
    (MuJoCo: 2.4 mm at 20 degrees, 7 at 25) while their enclosing capsules, which reach 6 cm
    past the flat ends, move apart: the solver cannot see the contact. contact_balls puts a
    ball in each cylinder at the contact; those part and overlap as the rims do."""
    model = mujoco.MjModel.from_xml_string(_CYLINDER_HIPS)
    tree = KinematicTree(model)
    caps = robot_capsules(model, tree)
    sc = SelfClearance(
        caps.node, caps.p0, caps.p1, caps.radius, np.array([0]), np.array([1]), caps.geom, np.array([-0.095])
    )
    data = mujoco.MjData(model)

    def pose(deg: float) -> np.ndarray:
        return np.array([0, 0, 1, 1, 0, 0, 0, np.radians(deg), -np.radians(deg)])

    def overlap(deg: float) -> float:
        data.qpos[:] = pose(deg)
        mujoco.mj_forward(model, data)
        return max([-float(c.dist) for c in data.contact[: data.ncon]], default=-np.inf)

    def distances(clearance: SelfClearance, deg: float) -> np.ndarray:
        q = pose(deg)[None]
        return capsule_distances(tree.forward(q[:, :3], quat_to_mat(q[:, 3:7]), q[:, 7:]), clearance)[0][0]

    assert overlap(0.0) == -np.inf and overlap(25.0) > OTHER_DEPTH
    assert distances(sc, 25.0)[0] > distances(sc, 0.0)[0] + 0.01  # the enclosures part
    node, centre, radius, geom = contact_balls(model, tree, pose(25.0)[None], sc)
    assert node.shape == (1, 2) and np.array_equal(geom[0], caps.geom) and radius.min() >= BALL_RADIUS
    for k in range(2):  # each ball lies in its cylinder (in its body's frame, axis along y)
        assert np.hypot(centre[0, k, 0], centre[0, k, 2]) <= 0.06 and abs(centre[0, k, 1]) <= 0.07
    balls = sc.with_balls(node, centre, radius, geom, BALL_MARGIN)
    assert balls.balls == 2 and balls.num_pairs == 2 and balls.margin[1] == BALL_MARGIN
    for deg in (20.0, 25.0, 30.0):  # the balls overlap as deep as the rims
        assert abs(distances(balls, deg)[1] + overlap(deg)) < 0.001, deg
    assert distances(balls, 0.0)[1] > 0.02  # and are apart where the cylinders are
    # A ball pair already held there is not held twice; apart, none is found.
    assert contact_balls(model, tree, pose(25.0)[None], balls)[0].shape == (0, 2)
    assert contact_balls(model, tree, pose(10.0)[None], sc)[0].shape == (0, 2)


def test_enclosures_that_overlap_at_rest_leave_a_contact_to_the_held_ladders_balls():
    """Kuavo's hip capsules overlap by 9 cm at rest (a negative margin): within that margin they
    still do not see the rims touch. The output check's "held" ladder takes balls there too and
    gives its more room to them, not to the enclosures, whose growing margin pressed the rims
    together (corpus clip 000015: 6.4, 7.0, 7.8 mm); the safe ladder goes on as before."""
    model = mujoco.MjModel.from_xml_string(_CYLINDER_HIPS)
    tree = KinematicTree(model)
    caps = robot_capsules(model, tree)
    q = np.array([[0, 0, 1, 1, 0, 0, 0, np.radians(25.0), -np.radians(25.0)]])
    poses = tree.forward(q[:, :3], quat_to_mat(q[:, 3:7]), q[:, 7:])

    def clearance(margin: float) -> SelfClearance:
        first, second = np.array([0]), np.array([1])
        return SelfClearance(
            caps.node, caps.p0, caps.p1, caps.radius, first, second, caps.geom, np.array([margin])
        )

    gap = float(capsule_distances(poses, clearance(0.0))[0][0, 0])
    assert gap < -0.05  # the capsules overlap deeply where the rims touch
    inside = clearance(gap + 0.01)  # inside a negative margin
    assert contact_balls(model, tree, q, inside)[0].shape == (0, 2)  # the safe ladder: none
    node, centre, radius, geom = contact_balls(model, tree, q, inside, inside_rest_overlap=True)
    assert node.shape == (1, 2)
    assert contact_balls(model, tree, q, clearance(0.0), inside_rest_overlap=True)[0].shape == (0, 2)
    assert not inside.seen_by_balls().any()
    balls = inside.with_balls(node, centre, radius, geom, BALL_MARGIN)
    assert balls.seen_by_balls().tolist() == [True, False]
    deep = np.array([0.006, 0.006])
    assert balls.tightened(deep, OTHER_DEPTH).margin[0] > balls.margin[0]  # the safe ladder's way
    held = balls.tightened(deep, OTHER_DEPTH, keep_seen=True)
    assert held.margin[0] == balls.margin[0] and held.margin[1] > balls.margin[1]
    apart = clearance(0.01).with_balls(node, centre, radius, geom, BALL_MARGIN)  # apart at rest
    assert not apart.seen_by_balls().any()
    assert apart.tightened(deep, OTHER_DEPTH, keep_seen=True).margin[0] > 0.01


def test_a_solve_that_passes_is_not_traded_for_one_that_gives_up_the_motion():
    """Once the solve kept overlaps no deeper than validate's 5 mm, a clear one is kept only
    within OUTPUT_NEAR_GIVE of its keypoint distance (ToddlerBot clapping: 4.1 mm kept, then a
    clear solve that fitted the human at 6.1 cm instead of 2.9); a solve that fails validate
    may still be traded within OUTPUT_FIT_GIVE."""
    passing = np.array([0.0, 0.0041, 0.001])
    failing = np.array([0.0, OUTPUT_FAR_DEPTH + 0.001])
    assert OUTPUT_NEAR_GIVE < OUTPUT_FIT_GIVE
    assert _gives_up_a_pass(passing, 0.03, 0.03 + OUTPUT_NEAR_GIVE + 0.001)
    assert not _gives_up_a_pass(passing, 0.03, 0.03 + OUTPUT_NEAR_GIVE - 0.001)
    assert not _gives_up_a_pass(failing, 0.03, 0.03 + OUTPUT_FIT_GIVE - 0.001)


def test_a_rung_refused_for_its_speed_alone_is_solved_again_slower():
    """Apollo lying down (the corpus's lie-down 000052 at 30 fps): its thighs 9.9 mm into each
    other in 6 frames after the output check's first rungs; the x10 rung cleared them (1.0 mm)
    but turned a hip at 10.6 rad/s, past 3 pi, and was refused. Solved again with that hip's
    velocity term stiffer there, it is kept: no frame past 5 mm, no joint past 3 pi rad/s or
    past its range, and the check passes self-collision and joint speed."""
    spec = plan_clips(CorpusConfig(clips=9800, seed=0))[52]
    assert spec.family == "lie_down"
    motion = Motion(joints=make_clip(spec)[1], fps=20.0)
    rm = load_robot("apollo")
    traj = retarget_motion(motion, rm, fps=30.0)
    assert overlap_frames(rm.model, traj.qpos) == 0
    assert np.abs(np.diff(traj.qpos[:, 7:], axis=0)).max() * 30.0 <= OUTPUT_SPEED
    assert traj.metrics["joint_limit_violations"] == 0
    report = sim.check_trajectory(scenes.load_scene("empty", robot="apollo"), traj.qpos, traj.fps)
    assert report.stats["self_collision_frames"] == 0 and report.stats["joint_velocity_violations"] == 0


def test_the_geom_pair_index_names_each_pair_of_geoms_and_nothing_else():
    """The sorted index of geom pairs (a robot split into convex pieces has 455,000 pairs)
    answers as a dict of the pairs would, both orders, for every two geoms of the model and
    for ids beyond them (MuJoCo's contacts name the floor and the scene's geoms too)."""
    robot = load_robot("g1")
    sc = robot.self_clearance
    assert sc is not None
    expected: dict[tuple[int, int], list[int]] = {}
    for k, (a, b) in enumerate(zip(sc.geom[sc.first].tolist(), sc.geom[sc.second].tolist(), strict=True)):
        expected.setdefault((a, b), []).append(k)
        if a != b:
            expected.setdefault((b, a), []).append(k)
    index = _pair_index(sc)
    ids = range(-1, robot.model.ngeom + 3 * int(sc.geom.max()))
    for a in ids:
        for b in ids:
            found = index.get(a, b)
            assert (None if found is None else found.tolist()) == expected.get((a, b)), (a, b)
    g1, g2 = np.meshgrid(np.array(ids), np.array(ids), indexing="ij")
    contains = index.contains(g1.ravel(), g2.ravel())
    assert contains.tolist() == [
        (int(a), int(b)) in expected for a, b in zip(g1.ravel(), g2.ravel(), strict=True)
    ]
    assert contains.sum() == len(expected)
