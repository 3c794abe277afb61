"""Self-clearance pairs: the trunk against the thighs, margins calibrated on the real geometry.

G1's pelvis and the hip-roll link below it overlap as enclosing capsules in every pose, so
their margin comes from a sweep of the hip joints measured by MuJoCo on the real meshes.
Checked here off the sweep's grid: random poses in which MuJoCo finds the geoms more than
8 mm deep (``controlmm validate`` allows 5 mm; the sweep's grid is coarse) must all fall
below the pair's margin, and the rest pose of every packaged robot must violate none.
"""

from __future__ import annotations

import mujoco
import numpy as np
import pytest
from capsule_humanoid import capsule_humanoid_xml
from g1_variants import g1_spec, saved_without_controls
from robot_checks import independent_check

from controlmm.motion import Motion
from retarget import load_robot, retarget_motion
from retarget.capsules import segment_distance
from retarget.robots import PACKAGED_ROBOTS
from retarget.selfcollision import SELF_MARGIN, _joints_between, capsule_distances


def _trunk_thigh_pairs(name: str) -> list[int]:
    robot = load_robot(name)
    sc = robot.self_clearance
    assert sc is not None
    root = int(robot.tree.node_body[0])
    body = robot.capsules.body
    return [k for k in range(sc.num_pairs) if body[sc.first[k]] == root and sc.margin[k] < SELF_MARGIN]


def _random_poses(robot, n: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """``n`` random joint vectors within the limits (+-pi for unlimited joints), root at the
    origin, and every self-clearance pair's capsule distance in them, (n, P)."""
    rng = np.random.default_rng(seed)
    lower, upper = np.clip(robot.lower, -np.pi, np.pi), np.clip(robot.upper, -np.pi, np.pi)
    q = rng.uniform(lower, upper, (n, len(lower)))
    poses = robot.tree.forward(np.zeros((n, 3)), np.tile(np.eye(3), (n, 1, 1)), q)
    dist, _, _ = capsule_distances(poses, robot.self_clearance)
    return q, dist


@pytest.mark.parametrize("name", PACKAGED_ROBOTS)
def test_rest_pose_violates_no_pair(name):
    robot = load_robot(name)
    sc = robot.self_clearance
    assert sc is not None
    dist, _, _ = capsule_distances(robot.rest, sc)
    assert np.all(dist[0] > sc.margin), name


def test_g1_pelvis_against_hip_links_from_the_real_meshes():
    robot = load_robot("g1")
    model, sc = robot.model, robot.self_clearance
    assert sc is not None
    pairs = _trunk_thigh_pairs("g1")
    names = {(model.body(int(robot.capsules.body[sc.second[k]])).name) for k in pairs}
    assert {"left_hip_roll_link", "right_hip_roll_link"} <= names
    # Random poses of every joint (not the sweep's grid): where the real geoms are > 8 mm deep,
    # the capsule pair is below its margin, so the solver pushes them apart.
    q, dist = _random_poses(robot, 1500, seed=0)
    n = len(q)
    data = mujoco.MjData(model)
    deep = 0
    for k in pairs:
        g1, g2 = int(sc.geom[sc.first[k]]), int(sc.geom[sc.second[k]])
        for t in range(n):
            data.qpos[:] = model.qpos0
            data.qpos[7:] = q[t]
            mujoco.mj_kinematics(model, data)
            if mujoco.mj_geomDistance(model, data, g1, g2, 0.05, None) < -0.008:
                deep += 1
                assert dist[t, k] < sc.margin[k], (k, t, dist[t, k], sc.margin[k])
    assert deep > 10  # the sample reaches the contacts it checks


def _sampled_distance(p: np.ndarray, d1: np.ndarray, q: np.ndarray, d2: np.ndarray) -> float:
    """Smallest distance between 401 points along each segment (brute force)."""
    s = np.linspace(0.0, 1.0, 401)[:, None]
    a, b = p + s * d1, q + s * d2
    return float(np.sqrt(((a[:, None] - b[None]) ** 2).sum(-1)).min())


def test_segment_distance_of_segments_and_points():
    """Closest points of two segments, either or both of them a point (a sphere's capsule),
    against brute-force sampling; the points returned lie on the segments at that distance."""
    rng = np.random.default_rng(3)
    for case in range(240):
        p, q = rng.normal(size=3), rng.normal(size=3)
        d1, d2 = rng.normal(size=3), rng.normal(size=3)
        if case % 4 == 1:
            d2 = np.zeros(3)
        elif case % 4 == 2:
            d1 = np.zeros(3)
        elif case % 4 == 3:
            d1, d2 = np.zeros(3), np.zeros(3)
        dist, pa, pb = segment_distance(p, d1, q, d2)
        sampled = _sampled_distance(p, d1, q, d2)
        step = (np.linalg.norm(d1) + np.linalg.norm(d2)) / 400  # the sampling's resolution
        assert sampled - step - 1e-9 <= float(dist) <= sampled + 1e-9, case
        assert np.isclose(np.linalg.norm(pa - pb), dist), case


@pytest.mark.parametrize("name", ["g1", "h1"])
def test_capsule_pairs_never_farther_than_their_geoms(name):
    """The capsules enclose their geoms, so in any pose a pair's capsule distance is at most
    MuJoCo's distance between the real geoms (G1's hip-pitch and H1's hip meshes are enclosed
    by spheres: a sphere's distance was once measured from the other capsule's end point)."""
    robot = load_robot(name)
    model, sc = robot.model, robot.self_clearance
    assert sc is not None
    sphere = np.linalg.norm(sc.p1 - sc.p0, axis=1) < 1e-9
    pairs = np.flatnonzero(sphere[sc.second] & ~sphere[sc.first])
    assert pairs.size > 20
    q, dist = _random_poses(robot, 40, seed=1)
    n = len(q)
    data = mujoco.MjData(model)
    for t in range(n):
        data.qpos[:] = model.qpos0
        data.qpos[7:] = q[t]
        mujoco.mj_kinematics(model, data)
        for k in pairs:
            g1, g2 = int(sc.geom[sc.first[k]]), int(sc.geom[sc.second[k]])
            real = mujoco.mj_geomDistance(model, data, g1, g2, 10.0, None)
            assert dist[t, k] <= real + 1e-4, (name, t, k, dist[t, k], real)


def _ankle_link_humanoid(heel_post: bool) -> str:
    """The capsule humanoid with its ankle split as most robots' is (shin -> ankle-pitch link ->
    foot), the foot optionally carrying a post that rises 20 cm behind the ankle, 1 cm clear of
    the shin at rest: pointing the toes swings it into the shin (as loco-mujoco's skeleton swings
    its heel bone into its tibia)."""
    post = '<geom type="capsule" fromto="-0.08 0 -0.02 -0.08 0 0.2" size="0.02"/>' if heel_post else ""
    lines, out, close_at = capsule_humanoid_xml("plain").splitlines(), [], None
    for i, line in enumerate(lines):
        indent = line[: len(line) - len(line.lstrip())]
        if '<body name="foot_' in line:
            side = line.split('name="foot_')[1][0]
            pitch = lines[i + 1].strip()
            assert pitch.startswith(f'<joint name="ankle_y_{side}"'), pitch
            out += [line.replace(f'"foot_{side}"', f'"ankle_{side}"'), f"{indent}  {pitch}"]
            out.append(f'{indent}  <inertial pos="0 0 0" mass="0.2" diaginertia="1e-4 1e-4 1e-4"/>')
            out += [f'{indent}<body name="foot_{side}" pos="0 0 0">', f"{indent}  {post}"]
            close_at = indent
            continue
        if line.strip().startswith('<joint name="ankle_y_'):
            continue
        out.append(line)
        if close_at is not None and line == f"{close_at}</body>":
            out.append(f"{close_at}</body>")
            close_at = None
    return "\n".join(out)


def test_a_shin_is_kept_off_its_own_foot_only_where_they_can_touch(tmp_path, sample_joints):
    """Pairs of a shin and its foot below the ankle link are kept where the real geoms touch
    within the ankle joints' ranges (a heel post pointing the toes swings into the shin):
    the retargeted real clip keeps them apart in MuJoCo's own contacts; G1's feet, which
    cannot reach their shins, add no pair."""
    pairs = {}
    for post in (False, True):
        path = tmp_path / f"post_{post}.xml"
        path.write_text(_ankle_link_humanoid(post))
        robot = load_robot(path)
        sc, m = robot.self_clearance, robot.model
        assert sc is not None
        pairs[post] = {  # (side, which geom of the foot)
            (side, int(sc.geom[sc.second[k]]) - m.body(f"foot_{side}").geomadr[0])
            for k in range(sc.num_pairs)
            for side in "lr"
            if int(sc.geom[sc.first[k]]) == m.body(f"shin_{side}").geomadr[0]
            and m.geom_bodyid[int(sc.geom[sc.second[k]])] == m.body(f"foot_{side}").id
        }
    # the post (each foot's second geom) adds its pair; the foot's capsule reaches the shin too
    assert pairs[True] - pairs[False] == {("l", 1), ("r", 1)}, pairs
    g1 = load_robot("g1")  # its knee and ankle-roll meshes never touch within its ankle's ranges
    shin_foot = {
        (
            g1.model.body(int(g1.capsules.body[g1.self_clearance.first[k]])).name,
            int(g1.capsules.body[g1.self_clearance.second[k]]),
        )
        for k in range(g1.self_clearance.num_pairs)
    }
    assert (
        not {(f"{s}_knee_link", g1.model.body(f"{s}_ankle_roll_link").id) for s in ("left", "right")}
        & shin_foot
    )
    traj = retarget_motion(Motion(joints=sample_joints.astype(np.float64), fps=20.0), str(path), fps=30.0)
    limits, floor_depth, self_frames = independent_check(path, traj.qpos)
    assert (limits, self_frames) == (0, 0) and floor_depth <= 0.005, (limits, floor_depth, self_frames)


def test_a_pair_in_side_by_side_branches_is_swept_through_both():
    """A waist link and a hip link hanging side by side from the pelvis (iRonCub's torso_1 and
    l_hip_2) are moved by the joints of both branches: the calibration sweeps those (it took
    the pair for unsweepable and dropped it: the hips went 16 mm into the waist in a stoop)."""
    model = load_robot("g1").model
    body = {model.body(b).name: b for b in range(model.nbody)}

    def names(first: str, second: str) -> set[str]:
        return {model.joint(j).name for j in _joints_between(model, body[first], body[second])}

    assert names("torso_link", "left_hip_roll_link") == {
        "waist_yaw_joint",
        "waist_roll_joint",
        "waist_pitch_joint",
        "left_hip_pitch_joint",
        "left_hip_roll_joint",
    }
    assert names("pelvis", "left_knee_link") == {
        "left_hip_pitch_joint",
        "left_hip_roll_joint",
        "left_hip_yaw_joint",
        "left_knee_joint",
    }
    assert names("left_knee_link", "left_knee_link") == set()


def _g1_of_boxes(tmp_path) -> str:
    """The G1 with each collision mesh replaced by its bounding box (a robot of boxes and
    cylinders, as the MIT humanoid is: its shoulder links' geoms are the G1's cylinders)."""
    spec = g1_spec()
    model = spec.compile()
    for body in spec.bodies:
        first = int(model.body(body.name).geomadr[0])
        for i, geom in enumerate(body.geoms):
            if geom.type != mujoco.mjtGeom.mjGEOM_MESH or geom.group != 3:
                continue
            centre, half = model.geom_aabb[first + i, :3], model.geom_aabb[first + i, 3:]
            turn = np.zeros(9)
            mujoco.mju_quat2Mat(turn, np.asarray(geom.quat, dtype=float))
            geom.type, geom.meshname = mujoco.mjtGeom.mjGEOM_BOX, ""
            geom.size, geom.pos = half, np.asarray(geom.pos) + turn.reshape(3, 3) @ centre
    return str(saved_without_controls(spec, tmp_path / "g1_boxes.xml"))


def test_a_robot_of_boxes_and_cylinders_keeps_its_shoulders_off_its_trunk(tmp_path):
    """Without a mesh among its arm pairs the trunk is kept from the shoulder links where MuJoCo
    collides their geoms, boxes and cylinders too, not only capsules and spheres (the MIT
    humanoid's cylinder upper arm went 33 mm into its box torso in 254 frames of six clips;
    none once kept apart)."""
    robot = load_robot(_g1_of_boxes(tmp_path))
    model, sc = robot.model, robot.self_clearance
    assert sc is not None and sc.relaxed_pairs is None  # no mesh: every pair in every solve
    assert not any(model.geom_type[int(g)] == mujoco.mjtGeom.mjGEOM_MESH for g in sc.geom)
    body = robot.capsules.body
    torso = model.body("torso_link").id
    for side in ("left", "right"):
        shoulder = model.body(f"{side}_shoulder_roll_link").id
        assert any(
            {int(body[sc.first[k]]), int(body[sc.second[k]])} == {torso, shoulder}
            for k in range(sc.num_pairs)
        ), side
