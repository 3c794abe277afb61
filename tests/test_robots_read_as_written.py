"""Robot files written in ways seen outside the asset package, each the packaged G1 edited that
way (unmoved in the world unless said): a floating base whose origin is on the floor (Berkeley
Humanoid Lite's), feet that collide through ``<pair>`` elements alone (PNDbotics' Adam SP), feet
that do not stand level (K-Scale's Z-Bot), an ankle link whose origin lies ahead of the ankle
on its roll axis (ROBOTIS' THORMANG3), a heel cap near the floor on a robot written facing -X
(iCub), and a head with two eyes on joints of their own (Aldebaran's Romeo)."""

from __future__ import annotations

from pathlib import Path
from xml.etree import ElementTree

import mujoco
import numpy as np
import pytest
from cli_helpers import in_process as cli
from g1_variants import g1_spec, saved_without_controls
from robot_checks import independent_check

from controlmm.errors import ControlMMError
from controlmm.motion import Motion
from retarget import infer_mapping, load_robot, load_robot_spec, retarget_motion, robot_mjcf
from retarget.compare import similarity_fit
from retarget.rest_frame import rest_root_quat
from retarget.robot_files import compile_robot, free_root
from scenes import load_scene
from sim import check_trajectory

SIDES = ("left", "right")


@pytest.fixture(scope="module")
def walk(sample_joints) -> Motion:
    """The first 3 s of the real clip (a walk)."""
    return Motion(joints=sample_joints[:60].astype(np.float64), fps=20.0)


def _base_on_the_floor(tmp_path: Path) -> Path:
    """The G1 with its floating base (the pelvis) written with its origin on the floor, 0.79 m
    below where the G1 file has it, and everything in it that much higher in its frame."""
    spec = g1_spec()
    base = spec.body("pelvis")
    lift = np.array([0.0, 0.0, base.pos[2]])
    base.pos = np.asarray(base.pos) - lift
    for kind in (base.bodies, base.geoms, base.sites, base.cameras, base.lights):
        for element in kind:
            element.pos = np.asarray(element.pos) + lift
    base.ipos = np.asarray(base.ipos) + lift
    return saved_without_controls(spec, tmp_path / "base_on_floor.xml")


def test_a_floating_base_whose_origin_is_on_the_floor_stands_as_written(tmp_path, walk):
    """The robot is read standing up as written (its centre of mass, not its base's origin, is
    what stands above the feet; the legs part at the hips, above the base's origin), so its
    left leg is its +Y one, as in the G1 file: it was laid on its back and read with its sides
    swapped (Berkeley Humanoid Lite: a fit of 13.7 cm, 4.9 once read standing). It retargets
    the walk within 10 % of the G1 file's fit, with no limit, floor or self-collision fault."""
    path = _base_on_the_floor(tmp_path)
    model = compile_robot(path)
    assert model.body("pelvis").pos[2] == 0.0
    np.testing.assert_allclose(rest_root_quat(model, free_root(model)), [1.0, 0.0, 0.0, 0.0])
    mapping = infer_mapping(path)["keypoints"]
    plain_mapping = infer_mapping(robot_mjcf("g1"))["keypoints"]
    assert {k: v["body"] for k, v in mapping.items()} == {k: v["body"] for k, v in plain_mapping.items()}
    robot, plain = load_robot(path), load_robot(robot_mjcf("g1"))
    np.testing.assert_allclose(
        robot.rest_keypoints - [0, 0, robot.floor_z], plain.rest_keypoints - [0, 0, plain.floor_z], atol=1e-9
    )
    assert robot.rest_keypoints[robot.keypoint_index("left_hip"), 1] > 0.05
    qpos = retarget_motion(walk, str(path), fps=30.0, metrics=False).qpos
    plain_qpos = retarget_motion(walk, str(robot_mjcf("g1")), fps=30.0, metrics=False).qpos
    assert independent_check(path, qpos)[::2] == (0, 0)
    assert independent_check(path, qpos)[1] <= 0.005
    fit = similarity_fit(robot, qpos, 30.0, walk.joints, walk.fps).mean
    plain_fit = similarity_fit(plain, plain_qpos, 30.0, walk.joints, walk.fps).mean
    assert fit < 1.1 * plain_fit, (fit, plain_fit)


def _feet_in_pairs_alone(tmp_path: Path) -> Path:
    """The G1 with every geom's contype and conaffinity 0 but its pelvis's collision geom
    (contype 1), a floor, and ``<pair>`` elements for each foot's sole spheres with the floor and
    for the two feet with each other: its feet collide through those pairs alone."""
    spec = g1_spec()
    feet = {side: spec.body(f"{side}_ankle_roll_link") for side in SIDES}
    for geom in spec.geoms:
        geom.contype, geom.conaffinity = 0, 0
    pelvis = [g for g in spec.body("pelvis").geoms if g.group == 3]
    assert pelvis
    for geom in pelvis:
        geom.contype = 1
    floor = spec.worldbody.add_geom(name="floor", type=mujoco.mjtGeom.mjGEOM_PLANE, size=[0, 0, 0.05])
    soles = {side: [g for g in feet[side].geoms if g.group == 3] for side in SIDES}
    for side in SIDES:
        assert len(soles[side]) == 4
        for i, geom in enumerate(soles[side]):
            geom.name = f"{side}_sole_{i}"
            spec.add_pair(geomname1=geom.name, geomname2=floor.name)
    spec.add_pair(geomname1="left_sole_0", geomname2="right_sole_0")
    return saved_without_controls(spec, tmp_path / "pairs.xml")


def test_geoms_that_collide_through_pairs_alone_are_colliders(tmp_path, walk):
    """Geoms the file names in ``<pair>`` elements but leaves at contype and conaffinity 0 are
    colliders (they touch the floor and the obstacles), as group-3 geoms are in a file that
    sets no contype at all: the robot has two feet on its sole spheres (it had "no two legs"),
    the pair with the file's own floor is dropped and the feet's pair kept, and the walk
    retargeted to it stands on the empty scene's floor in ``controlmm validate``'s check."""
    path = _feet_in_pairs_alone(tmp_path)
    spec = load_robot_spec(str(path))
    names = {p.geomname1 for p in spec.pairs} | {p.geomname2 for p in spec.pairs}
    assert "floor" not in names and {"left_sole_0", "right_sole_0"} <= names
    robot = load_robot(path)
    for side in SIDES:
        sole = {robot.model.geom(f"{side}_sole_{i}").id for i in range(4)}
        assert sole <= set(robot.feet[side].geoms), side
        assert all(robot.model.geom_contype[g] == 1 for g in sole)
    mapping = infer_mapping(path)["keypoints"]
    assert [mapping[f"{side}_ankle"]["body"] for side in SIDES] == [
        "left_ankle_roll_link",
        "right_ankle_roll_link",
    ]
    traj = retarget_motion(walk, str(path), fps=30.0, metrics=False)
    report = check_trajectory(load_scene("empty", robot=str(path)), traj.qpos, traj.fps)
    assert "floating" not in report.stats["error_kinds"], report.stats["error_kinds"]
    assert report.stats["self_collision_frames"] == 0


def test_a_robot_file_whose_pairs_name_its_scenes_floor_loads_alone(tmp_path, walk):
    """The same robot written without the floor its pairs name (the file a scene includes,
    PNDbotics' ``adam_sp.xml``: MuJoCo does not compile it alone): the pairs naming the
    missing geom are dropped, the feet stay colliders, and the walk retargeted to it stands."""
    with_floor = _feet_in_pairs_alone(tmp_path)
    text = with_floor.read_text()
    floor_line = next(line for line in text.splitlines() if 'name="floor"' in line)
    path = tmp_path / "pairs_no_floor.xml"
    path.write_text(text.replace(floor_line + "\n", ""))
    with pytest.raises(ValueError, match="floor"):
        mujoco.MjModel.from_xml_path(str(path))
    robot = load_robot(path)
    assert {robot.model.geom(f"left_sole_{i}").id for i in range(4)} <= set(robot.feet["left"].geoms)
    assert robot.model.npair == 1  # the feet's pair with each other
    traj = retarget_motion(walk, str(path), fps=30.0, metrics=False)
    report = check_trajectory(load_scene("empty", robot=str(path)), traj.qpos, traj.fps)
    assert "floating" not in report.stats["error_kinds"], report.stats["error_kinds"]


def _right_sole_lowered(tmp_path: Path, drop: float) -> Path:
    """The G1 with its right foot's sole spheres ``drop`` m lower in the foot (a file whose
    collision geom sits away from its foot's sole, K-Scale's Z-Bot)."""
    spec = g1_spec()
    for geom in spec.body("right_ankle_roll_link").geoms:
        if geom.group == 3:
            geom.pos = np.asarray(geom.pos) - [0.0, 0.0, drop]
    return saved_without_controls(spec, tmp_path / "uneven.xml")


def test_feet_that_do_not_stand_level_are_a_one_line_error(tmp_path):
    """A robot whose feet are not level (10 cm apart, more than 5 % of the G1's height) keeps
    its file's orientation (it was laid on its side, the hips read as its feet) and is refused
    in one line that names the two feet and how far apart they are; ``controlmm robots map``
    exits 2 and writes nothing."""
    path = _right_sole_lowered(tmp_path, 0.1)
    model = compile_robot(path)
    np.testing.assert_allclose(rest_root_quat(model, free_root(model)), [1.0, 0.0, 0.0, 0.0])
    with pytest.raises(ControlMMError, match=r"standing level.*left_ankle_roll_link.*cm apart"):
        infer_mapping(path)
    out = tmp_path / "m.json"
    done = cli("robots", "map", path, "--out", out)
    assert done.returncode == 2 and not out.exists()
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and "right_ankle_roll_link" in lines[0] and "cm apart" in lines[0], lines


def _ankle_origin_ahead(
    tmp_path: Path, ahead: float, thicker: float = 0.07, anchor_ahead: bool = False
) -> Path:
    """The G1 on ``thicker`` m thicker soles (7 cm: its ankles 12 cm up, as THORMANG3's) with
    each ankle roll link's origin ``ahead`` m forward along its roll axis (+X), its geoms,
    sites, inertia and (unless ``anchor_ahead``: the same axis, anchored at the origin, as
    HighTorque's Pi+) joint moved back by as much (THORMANG3's URDF puts its ankle roll link
    5.7 cm ahead of the ankle)."""
    spec = g1_spec()
    for side in SIDES:
        link = spec.body(f"{side}_ankle_roll_link")
        shift = np.array([ahead, 0.0, 0.0])
        link.pos = np.asarray(link.pos) + shift
        for kind in (link.geoms, link.sites) if anchor_ahead else (link.joints, link.geoms, link.sites):
            for element in kind:
                element.pos = np.asarray(element.pos) - shift
        link.ipos = np.asarray(link.ipos) - shift
        for geom in link.geoms:
            if geom.group == 3:
                geom.pos = np.asarray(geom.pos) - [0.0, 0.0, thicker]
    return saved_without_controls(spec, tmp_path / "ankle_ahead.xml")


def test_the_toes_are_measured_from_where_the_ankle_turns(tmp_path):
    """With the ankles high above thick soles and the ankle roll links' origins 6 cm ahead of
    the ankle, the soles reach 3.5 cm ahead of where the ankle's pitch and roll axes cross: the
    robot faces +X as written, its left leg the +Y one, its toes ahead of its ankles. Measured
    from the roll links' origins (the highest bodies near the floor) the soles reached back
    (-2.5 cm) and the robot was turned round, its sides swapped."""
    path = _ankle_origin_ahead(tmp_path, 0.06)
    model = compile_robot(path)
    np.testing.assert_allclose(rest_root_quat(model, free_root(model)), [1.0, 0.0, 0.0, 0.0])
    mapping = infer_mapping(path)["keypoints"]
    assert [mapping[f"{side}_hip"]["body"] for side in SIDES] == ["left_hip_yaw_link", "right_hip_yaw_link"]
    robot = load_robot(path)
    kp = robot.rest_keypoints
    assert kp[robot.keypoint_index("left_hip"), 1] > 0.05
    assert kp[robot.keypoint_index("left_foot"), 0] > kp[robot.keypoint_index("left_ankle"), 0] + 0.05


def test_an_ankle_high_above_its_soles_turns_where_its_axes_cross(tmp_path):
    """On soles 25 cm thicker the ankle's pitch hinge is further above the floor than an ankle's
    band (ANKLE_AXES_BAND of the robot's height), but its axis crosses the roll axis, so it
    still says where the ankle turns: the robot faces +X as written, its toes ahead of its
    ankles. Without it the ankle was the roll hinge's anchor, the roll link's origin 6 cm ahead,
    and the robot was turned round, its sides swapped (HighTorque's Pi+, its ankle 8.5 cm above
    its soles)."""
    path = _ankle_origin_ahead(tmp_path, 0.06, thicker=0.25, anchor_ahead=True)
    model = compile_robot(path)
    np.testing.assert_allclose(rest_root_quat(model, free_root(model)), [1.0, 0.0, 0.0, 0.0])
    robot = load_robot(path)
    kp = robot.rest_keypoints
    assert kp[robot.keypoint_index("left_hip"), 1] > 0.05
    assert kp[robot.keypoint_index("left_foot"), 0] > kp[robot.keypoint_index("left_ankle"), 0] + 0.05


def _facing_back_with_heel_caps(tmp_path: Path) -> Path:
    """The G1 written facing -X (its root turned half round about +Z) with a collision box on
    each ankle roll link over the heel, 1 cm above the sole (iCub's ankle shells reach as near
    the floor and are written facing -X)."""
    spec = g1_spec()
    spec.body("pelvis").quat = [0.0, 0.0, 0.0, 1.0]
    for side in SIDES:
        spec.body(f"{side}_ankle_roll_link").add_geom(
            type=mujoco.mjtGeom.mjGEOM_BOX, size=[0.02, 0.03, 0.01], pos=[-0.045, 0.0, -0.015], group=3
        )
    return saved_without_controls(spec, tmp_path / "heel_caps.xml")


def test_a_heel_cap_near_the_floor_does_not_hide_where_the_toes_point(tmp_path):
    """The toes' reach is the middle of the sole's extent beyond the ankle: a heel cap near the
    floor leaves it at 3 cm, and the robot written facing -X is turned to face +X, its left leg
    the +Y one (its root's rest orientation the identity). With the mean of the sole geoms'
    centres the cap pulled the reach to 1.9 cm, under the 2 cm a half turn needs, and the robot
    was read facing back, sides swapped."""
    path = _facing_back_with_heel_caps(tmp_path)
    model = compile_robot(path)
    np.testing.assert_allclose(
        np.abs(rest_root_quat(model, free_root(model))), [1.0, 0.0, 0.0, 0.0], atol=1e-9
    )
    mapping = infer_mapping(path)["keypoints"]
    assert [mapping[f"{side}_knee"]["body"] for side in SIDES] == ["left_knee_link", "right_knee_link"]
    robot = load_robot(path)
    assert robot.rest_keypoints[robot.keypoint_index("left_hip"), 1] > 0.05
    assert (
        robot.rest_keypoints[robot.keypoint_index("left_foot"), 0]
        > robot.rest_keypoints[robot.keypoint_index("left_ankle"), 0]
    )


def _with_eyes(tmp_path: Path) -> Path:
    """The G1 with a head on a yaw joint above its torso and two eyes on pitch joints of their
    own, 3 cm either side of its midline (Romeo's)."""
    spec = g1_spec()
    head = spec.body("torso_link").add_body(name="head", pos=[0.0, 0.0, 0.45])
    head.add_joint(name="head_yaw", axis=[0.0, 0.0, 1.0], range=[-1.0, 1.0])
    head.add_geom(type=mujoco.mjtGeom.mjGEOM_SPHERE, size=[0.06, 0, 0], mass=0.5)
    for side, y in (("left", 0.03), ("right", -0.03)):
        eye = head.add_body(name=f"{side}_eye", pos=[0.05, y, 0.02])
        eye.add_joint(name=f"{side}_eye_pitch", axis=[0.0, 1.0, 0.0], range=[-0.5, 0.5])
        eye.add_geom(
            type=mujoco.mjtGeom.mjGEOM_SPHERE, size=[0.01, 0, 0], mass=0.01, contype=0, conaffinity=0
        )
    return saved_without_controls(spec, tmp_path / "eyes.xml")


def test_two_eyes_on_joints_of_their_own_are_the_heads(tmp_path):
    """The head follows the link the two eyes hang from, not one eye (the highest end near the
    midline was Romeo's left eye, and its eye joints took the head's posture weight)."""
    mapping = infer_mapping(_with_eyes(tmp_path))
    assert mapping["keypoints"]["head"]["body"] == "head"


def _knee_anchors_outboard(tmp_path: Path, out: float) -> Path:
    """The G1 with each knee hinge's anchor written ``out`` m outboard along its own axis (the
    same kinematics: THORMANG3's URDF puts its knee links' origins, and so its knee joints, 9.3
    cm outboard of its legs)."""
    spec = g1_spec()
    for side, sign in (("left", 1.0), ("right", -1.0)):
        joint = spec.joint(f"{side}_knee_joint")
        joint.pos = np.asarray(joint.pos) + sign * out * np.asarray(joint.axis) / np.linalg.norm(joint.axis)
    return saved_without_controls(spec, tmp_path / "knees_out.xml")


def test_a_knee_anchor_far_out_on_its_axis_is_read_on_the_leg(tmp_path):
    """A knee hinge anchored 8 cm outboard on its axis is the same knee: its keypoint is the
    point of the axis nearest the hip-ankle line, where the G1 file's is (within 1 cm; it was
    8 cm outboard, and the solve turned the legs to bring that point onto the human's knee)."""
    robot = load_robot(_knee_anchors_outboard(tmp_path, 0.08))
    plain = load_robot(robot_mjcf("g1"))
    for side in SIDES:
        k = robot.keypoint_index(f"{side}_knee")
        assert (
            np.linalg.norm(
                robot.rest_keypoints[k] - plain.rest_keypoints[plain.keypoint_index(f"{side}_knee")]
            )
            < 0.01
        )


def _rolling_knees(tmp_path: Path) -> Path:
    """The G1 with a rolling knee written as two parallel hinges (Draco3's): a second knee
    hinge 10 cm below the first, the shank below it 10 cm shorter."""
    spec = g1_spec()
    for kind in (spec.actuators, spec.sensors, spec.keys):
        for element in list(kind):
            spec.delete(element)
    root = ElementTree.fromstring(spec.to_xml())
    for side in SIDES:
        knee = root.find(f".//body[@name='{side}_knee_link']")
        ankle = knee.find(f"body[@name='{side}_ankle_pitch_link']")
        joint = knee.find("joint")
        below = ElementTree.SubElement(knee, "body", name=f"{side}_knee_lower", pos="0 0 -0.1")
        ElementTree.SubElement(below, "inertial", pos="0 0 0", mass="0.1", diaginertia="0.0001 0.0001 0.0001")
        ElementTree.SubElement(
            below, "joint", name=f"{side}_knee_lower_joint", axis=joint.get("axis", "0 1 0"), range="0 1"
        )
        knee.remove(ankle)
        x, y, z = (float(v) for v in ankle.get("pos").split())
        ankle.set("pos", f"{x} {y} {z + 0.1}")
        below.append(ankle)
    path = tmp_path / "rolling_knees.xml"
    path.write_text(ElementTree.tostring(root, encoding="unicode"))
    return path


def test_a_rolling_knee_of_two_parallel_hinges_is_one_knee(tmp_path):
    """The second hinge of a rolling knee, parallel to the first and nearer to it than to the
    ankle, is the knee's: the knee keypoint lies halfway between the two hinges and the ankle
    keypoint where the ankle's own axes cross, as in the G1 file (it was the point nearest all
    three axes after the knee, 8.3 cm above Draco3's ankle)."""
    path = _rolling_knees(tmp_path)
    robot, plain = load_robot(path), load_robot(robot_mjcf("g1"))
    for side in SIDES:
        ankle = robot.rest_keypoints[robot.keypoint_index(f"{side}_ankle")]
        assert np.linalg.norm(ankle - plain.rest_keypoints[plain.keypoint_index(f"{side}_ankle")]) < 1e-6
        knee = robot.rest_keypoints[robot.keypoint_index(f"{side}_knee")]
        plain_knee = plain.rest_keypoints[plain.keypoint_index(f"{side}_knee")]
        assert np.linalg.norm(knee - plain_knee) == pytest.approx(0.05, abs=1e-6)  # halfway down


def test_a_file_that_does_not_compile_is_one_line_even_where_an_edit_compiles_it(tmp_path):
    """The G1 with a massless body holding a joint beside it, tied to a hip joint (MuJoCo does not
    compile it): the edits that compile the file to read it (bodies beside the robot dropped)
    fail, and MuJoCo raises that failure again at the spec's next use; it is one line naming
    the file and the body, exit 2 from ``controlmm robots map`` (``controlmm retarget`` failed
    with an internal error)."""
    path = saved_without_controls(g1_spec(), tmp_path / "spare.xml")
    text = path.read_text()
    assert text.count("</worldbody>") == 1
    path.write_text(
        text.replace(
            "</worldbody>",
            '<body name="spare" pos="0 0 20"><joint name="spare_joint"/></body></worldbody>'
            '<equality><joint joint1="left_hip_yaw_joint" joint2="spare_joint"/></equality>',
        )
    )
    with pytest.raises(ValueError, match="mass and inertia"):
        mujoco.MjModel.from_xml_path(str(path))
    with pytest.raises(ControlMMError, match=r"spare.xml' does not compile: .*'spare'"):
        load_robot(path)
    out = tmp_path / "m.json"
    done = cli("robots", "map", path, "--out", out)
    assert done.returncode == 2 and not out.exists()
    assert len(done.stderr.strip().splitlines()) == 1 and "does not compile" in done.stderr, done.stderr
