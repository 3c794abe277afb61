"""Foot targets (``retarget/foot_targets.py``) on G1's own footprints and the real HumanML3D
clip 012314: the feet are spaced by their exact turned footprints, a swinging foot goes around
a planted one, and a foot turns towards a bent knee whose toes point away from it; stance
feet are pinned (``retarget/feet.py``) on the point of them that stays on the floor."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest

import retarget.foot_targets as ft
from controlmm.corpus import CorpusConfig, make_clip, plan_clips
from controlmm.frames import HumanToWorld
from controlmm.motion import Motion
from controlmm.motion.skeleton import JOINT_INDEX
from retarget import load_robot, retarget_motion, robot_scale
from retarget.compare import similarity_fit
from retarget.feet import PIVOT_RISE, pin_points, pin_stance_feet
from retarget.robots import robot_mjcf
from retarget.solver import solve
from retarget.solver_config import SolverConfig
from retarget.swing_lift import lift_swing_feet
from retarget.targets import build_targets, stiffer_locks

FPS = 20.0


@pytest.fixture(scope="module")
def g1():
    return load_robot("g1")


@pytest.fixture(scope="module")
def world(sample_joints) -> np.ndarray:
    """The clip placed at G1's scale (T, 22, 3), Z up."""
    return np.asarray(HumanToWorld(scale=robot_scale("g1")).to_world(sample_joints.astype(np.float64)))


def _polygon(corners: np.ndarray) -> np.ndarray:
    """The four corners of ``_footprint_corners`` (a 2 x 2 grid) in order around the rectangle."""
    return corners[[0, 1, 3, 2]]


def _overlap(a: np.ndarray, b: np.ndarray) -> bool:
    """Whether two convex polygons (N, 2) intersect (separating axis test)."""
    for poly in (a, b):
        for i in range(len(poly)):
            edge = poly[(i + 1) % len(poly)] - poly[i]
            normal = np.array([-edge[1], edge[0]])
            pa, pb = a @ normal, b @ normal
            if pa.max() < pb.min() or pb.max() < pa.min():
                return False
    return True


def test_sideways_overlap_is_the_exact_interval(g1):
    """For turned footprints at random places, the shifts along y at which the left one meets
    the right one are exactly the interval returned (checked by the separating axis test just
    inside and just outside each end, and along the whole line where they never meet)."""
    rng = np.random.default_rng(0)
    n = 200
    left = ft._footprint_corners(g1, "left", rng.uniform(-np.pi, np.pi, n))
    right = ft._footprint_corners(g1, "right", rng.uniform(-np.pi, np.pi, n))
    left = left + rng.uniform([-0.3, -0.3], [0.3, 0.3], (n, 2))[:, None]
    lo, hi = ft.sideways_overlap(left, right)
    met = np.isfinite(lo)
    assert 20 < met.sum() < n  # both cases occur
    up = np.array([0.0, 1.0])
    for t in range(n):
        a, b = _polygon(left[t]), _polygon(right[t])
        if not met[t]:
            assert not any(_overlap(a + d * up, b) for d in np.linspace(-1, 1, 81))
            continue
        assert lo[t] <= hi[t]
        eps = 1e-6
        assert _overlap(a + (lo[t] + eps) * up, b) and _overlap(a + (hi[t] - eps) * up, b)
        assert not _overlap(a + (lo[t] - eps) * up, b) and not _overlap(a + (hi[t] + eps) * up, b)


def _feet_kp(g1, world: np.ndarray, squeeze: float) -> np.ndarray:
    """Keypoint targets with only the ankles set: the human's, brought ``squeeze`` times as
    close sideways (so that the robot's feet would overlap in many frames)."""
    kp = np.zeros((len(world), len(g1.joints), 3))
    left, right = world[:, JOINT_INDEX["left_ankle"]], world[:, JOINT_INDEX["right_ankle"]]
    mid = (left + right) / 2
    kp[:, g1.keypoint_index("left_ankle")] = mid + squeeze * (left - mid)
    kp[:, g1.keypoint_index("right_ankle")] = mid + squeeze * (right - mid)
    return kp


def _footprints(g1, kp: np.ndarray, world: np.ndarray, t: int) -> tuple[np.ndarray, np.ndarray]:
    """Both grown footprints (4, 2) at frame ``t`` in the world's XY (the pelvis facing +X)."""
    out = []
    for side in ("left", "right"):
        turn = ft.foot_heading_pitch(world, side)[0] + ft.knee_turn(world, side)
        corners = ft._footprint_corners(g1, side, turn[t : t + 1])[0]
        out.append(_polygon(corners) + kp[t, g1.keypoint_index(f"{side}_ankle"), :2])
    return out[0], out[1]


def test_feet_shortfall_parts_the_real_footprints_exactly(g1, world):
    """Where the robot's grown footprints overlap, the left foot moved by the shortfall along
    the left axis just clears the right one (touching within 0.1 mm); where they do not
    overlap, the shortfall is 0."""
    kp = _feet_kp(g1, world, 0.4)
    pelvis = np.tile(np.eye(3), (len(world), 1, 1))  # facing +X: the left axis is +Y
    short, y = ft.feet_shortfall(g1, kp, world, pelvis)
    np.testing.assert_allclose(y, np.tile([0.0, 1.0, 0.0], (len(world), 1)))
    assert 10 < np.count_nonzero(short) < len(world)
    for t in range(len(world)):
        a, b = _footprints(g1, kp, world, t)
        assert _overlap(a, b) == (short[t] != 0), t
        if short[t] != 0:
            step = np.array([0.0, short[t]])
            assert not _overlap(a + step * (1 + 1e-3) + np.sign(short[t]) * np.array([0, 1e-4]), b)
            assert _overlap(a + step - np.sign(short[t]) * np.array([0, 1e-4]), b)


def test_a_swinging_foot_goes_around_a_planted_one(g1, world):
    """The left foot planted (locked in every frame), the right one swinging too close: the
    planted foot keeps its targets and the swinging one moves until the feet no longer
    overlap."""
    kp = _feet_kp(g1, world, 0.4)
    before = kp.copy()
    pelvis = np.tile(np.eye(3), (len(world), 1, 1))
    assert np.any(ft.feet_shortfall(g1, kp, world, pelvis)[0] != 0)
    runs = {"left": np.zeros(len(world), dtype=int), "right": np.full(len(world), -1)}
    alpha_xy = {"left": np.ones(len(world)), "right": np.zeros(len(world))}
    ft.separate_locks(g1, kp, world, pelvis, runs, alpha_xy)
    kl, kr = g1.keypoint_index("left_ankle"), g1.keypoint_index("right_ankle")
    np.testing.assert_array_equal(kp[:, kl], before[:, kl])
    assert np.abs(kp[:, kr] - before[:, kr]).max() > 0.01
    np.testing.assert_allclose(ft.feet_shortfall(g1, kp, world, pelvis)[0], 0.0, atol=1e-9)


def _toes_turned_out(joints: np.ndarray, degrees: float) -> np.ndarray:
    """The clip with each toe joint turned ``degrees`` outwards about its ankle's vertical axis
    (HumanML3D: Y up; a turn about +Y by a positive angle takes any heading to its left)."""
    out = joints.copy()
    for side, sign in (("left", 1.0), ("right", -1.0)):
        a, f = JOINT_INDEX[f"{side}_ankle"], JOINT_INDEX[f"{side}_foot"]
        angle = np.radians(degrees) * sign
        c, s = np.cos(angle), np.sin(angle)
        v = out[:, f] - out[:, a]
        # rotation about +Y (up): x' = c x + s z, z' = -s x + c z
        out[:, f, 0] = out[:, a, 0] + c * v[:, 0] + s * v[:, 2]
        out[:, f, 2] = out[:, a, 2] - s * v[:, 0] + c * v[:, 2]
    return out


def test_knee_turn_is_bounded_and_points_to_the_knee(world):
    """The turn is 0 where the toes point within KNEE_TWIST_DEG of the knee, never more than
    KNEE_TURN_MOST_DEG, and always towards the knee."""
    for side in ("left", "right"):
        turn = ft.knee_turn(world, side)
        toe = ft.foot_heading_pitch(world, side)[0]
        knee, bend = ft.knee_direction(world, side)
        twist = np.angle(np.exp(1j * (knee - toe)))
        assert np.abs(turn).max() <= np.radians(ft.KNEE_TURN_MOST_DEG) + 1e-12
        assert np.all(turn[np.abs(twist) <= np.radians(ft.KNEE_TWIST_DEG)] == 0)
        assert np.all(turn * twist >= 0)
        assert np.all(bend >= 0) and np.all(bend < 0.5)


def test_toes_turned_out_keep_the_knees_over_the_feet(sample_joints, monkeypatch):
    """The clip with the toes turned out 30 degrees: G1's feet turn towards the human's knees,
    and its knees fit the human's closer than with feet that follow the toes alone."""
    joints = _toes_turned_out(sample_joints.astype(np.float64), 30.0)
    g1 = load_robot("g1")

    def knees_fit() -> float:
        traj = retarget_motion(Motion(joints=joints, fps=FPS), "g1", fps=FPS, metrics=False)
        fit = similarity_fit(g1, traj.qpos, FPS, joints, FPS)
        return fit.per_joint["left_knee"] + fit.per_joint["right_knee"]

    turned = knees_fit()
    monkeypatch.setattr(ft, "KNEE_TURN_MOST_DEG", 0.0)
    toes_only = knees_fit()
    assert turned < toes_only - 0.005, (turned, toes_only)


def test_stiffer_locks_weigh_only_the_planted_feet(g1, sample_joints):
    """``stiffer_locks`` (the output check's stiffer solves): the feet's keypoints and the
    ankles' orientation weigh ``factor`` times more where fully locked, in proportion to the
    lock where it ramps, and as before in swing; every other keypoint as before."""
    targets = build_targets(
        g1, sample_joints.astype(np.float64), FPS, HumanToWorld(scale=robot_scale("g1")), SolverConfig()
    )
    stiff = stiffer_locks(g1, targets, 10.0)
    feet = {side: ft.foot_keypoints(g1, side) for side in ("left", "right")}
    assert all(g1.keypoint_index(f"{side}_ankle") in feet[side] for side in feet)
    ori = targets.ori_kp.tolist()
    for side, keys in feet.items():
        lock = targets.lock[side]
        assert (lock == 1.0).any() and (lock == 0.0).any() and ((lock > 0) & (lock < 1)).any()
        for k in keys:
            np.testing.assert_allclose(stiff.kp_weight[:, k], targets.kp_weight[:, k] * (1 + 9 * lock))
        o = ori.index(g1.keypoint_index(f"{side}_ankle"))
        np.testing.assert_allclose(stiff.ori_weight[:, o], targets.ori_weight[:, o] * (1 + 9 * lock))
    others = [k for k in range(targets.kp_weight.shape[1]) if k not in feet["left"] + feet["right"]]
    np.testing.assert_array_equal(stiff.kp_weight[:, others], targets.kp_weight[:, others])
    np.testing.assert_array_equal(stiff.kp_pos, targets.kp_pos)
    assert stiff.kp_weight is not targets.kp_weight  # the targets given are left alone


@pytest.mark.parametrize(("ankle_pitch", "lifted"), [(-0.25, True), (-0.6, False)])
def test_a_foot_with_its_knee_at_the_stop_lifts_its_toe_by_turning(tmp_path, ankle_pitch, lifted):
    """A crouching walk's swing foot skims the floor with its knee at the stop (Fourier GR1T2,
    corpus crouch walk: 9 mm up at 3 m/s, read as a stance foot sliding). G1 with knees that
    stop at 1.2 rad, the ankle under the hip, the toe 5 mm up and moving at 1 m/s: pointing the
    toe down, the foot lifts it by turning at the ankle, above the check's 1 cm and where it was
    (the rise of the foot's origin alone, all the leg could give, lowered the toe 1.7 mm and
    moved it 6 cm); flat, no turn raises the sole and the foot stays as it was."""
    src = robot_mjcf("g1")
    spec = mujoco.MjSpec.from_file(str(src))
    spec.meshdir = str(src.parent / "assets")
    for side in ("left", "right"):
        spec.joint(f"{side}_knee_joint").range = [-0.087, 1.2]
    path = tmp_path / "g1_short_knees.xml"
    path.write_text(spec.to_xml())
    robot = load_robot(path)
    index = {robot.model.joint(int(j)).name: i for i, j in enumerate(robot.tree.joint_ids)}
    frames, fps = 30, 50.0
    q = np.zeros((frames, robot.tree.nj))
    for name, angle in (
        ("left_knee_joint", 1.2),
        ("left_hip_pitch_joint", -0.6),
        ("left_ankle_pitch_joint", ankle_pitch),
        ("right_knee_joint", 1.2),
        ("right_hip_pitch_joint", -1.2),
    ):
        q[:, index[name]] = angle
    root_rot = np.repeat(np.eye(3)[None], frames, axis=0)
    root_pos = np.zeros((frames, 3))
    root_pos[:, 0] = np.arange(frames) / fps
    foot = robot.feet["left"]
    root_pos[:, 2] = 0.005 - foot.lowest(robot.tree.forward(root_pos, root_rot, q))[0]
    h0, p0 = foot.lowest(robot.tree.forward(root_pos, root_rot, q))
    none = np.zeros(frames)
    out, _ = lift_swing_feet(robot, root_pos, root_rot, q, {"left": none, "right": none}, fps)
    h1, p1 = foot.lowest(robot.tree.forward(root_pos, root_rot, out))
    assert np.all(out[:, index["left_knee_joint"]] == 1.2)
    assert np.abs(p1 - p0)[:, :2].max() < 0.002
    if lifted:
        assert h1.min() > 0.010
    else:
        np.testing.assert_allclose(h1, h0, atol=1e-6)


def test_a_rolling_foot_is_pinned_on_the_pivot_it_rolls_on(g1):
    """On a generated walk (the default corpus's first), the G1's stance feet are pinned by
    the heel or toe pivot they roll on where the targets roll them (heel strikes, toe-offs;
    where the targets hold the foot level, by its ankle keypoint unless the solve tilts it,
    and on a point between while one end is less than PIVOT_RISE up);
    pinned, those pivots end within 1 mm of their places on average (1.3 mm when the ankle
    keypoint was pinned instead) and at a third of the solve's own error."""
    spec = next(s for s in plan_clips(CorpusConfig(clips=9800, seed=0)) if s.family == "walk")
    joints = make_clip(spec)[1].astype(np.float64)
    config = SolverConfig(pin_iterations=0)
    targets = build_targets(g1, joints, FPS, HumanToWorld(scale=g1.scale), config)
    sol = solve(g1, targets, config)
    pinned = pin_stance_feet(g1, targets, sol.root_pos, sol.root_rot, sol.q, SolverConfig().pin_iterations)
    for side in ("left", "right"):
        frames = np.flatnonzero(targets.stance[side] & (targets.lock[side] >= 1.0))
        solved = g1.tree.forward(sol.root_pos[frames], sol.root_rot[frames], sol.q[frames])
        point, goal = pin_points(g1, targets, side, frames, solved)
        k = g1.keypoint_index(f"{side}_ankle")
        node = int(g1.nodes[k])
        on_pivot = np.linalg.norm(point - g1.offsets[k], axis=1) > 1e-9
        heel, toe = ft.foot_pivots(g1, side)
        rot = targets.ori_rot[frames, list(targets.ori_kp).index(k)]
        rise = np.einsum("fij,j->fi", rot, heel - toe)[:, 2]  # > 0: the targets lift the heel
        assert (rise > PIVOT_RISE).sum() > 10 and (rise < -PIVOT_RISE).sum() > 5, side
        assert np.all(np.isclose(point[rise > PIVOT_RISE], toe).all(axis=1)), side
        assert np.all(np.isclose(point[rise < -PIVOT_RISE], heel).all(axis=1)), side
        error = {}
        for name, q in (("solved", sol.q), ("pinned", pinned)):
            poses = g1.tree.forward(sol.root_pos[frames], sol.root_rot[frames], q[frames])
            place = np.einsum("fij,fj->fi", poses.rot[:, node], point) + poses.pos[:, node]
            error[name] = float(np.linalg.norm(place - goal, axis=1)[on_pivot].mean())
        assert error["pinned"] < 0.001 and error["pinned"] < error["solved"] / 3, (side, error)
