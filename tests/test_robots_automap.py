"""Every packaged humanoid by name, mappings inferred from any humanoid MJCF, bad robot files.

The inferred mapping reads the kinematic tree and geometry only: a G1 whose bodies and
joints are renamed, with the left and right names swapped, still maps its left leg to +Y.
"""

from __future__ import annotations

import json
import re
from pathlib import Path

import mujoco
import numpy as np
import pytest
from capsule_humanoid import capsule_humanoid_xml
from cli_helpers import console, in_process as cli
from g1_variants import g1_spec, saved_without_controls
from robot_checks import independent_check

from controlmm.corpus.dataset import ClipSpec, make_clip
from controlmm.errors import ControlMMError
from controlmm.motion import Motion
from controlmm.pipeline import PlanConfig
from controlmm.pipeline.plan import resolve_inputs
from retarget import (
    infer_mapping,
    load_robot,
    load_robot_spec,
    retarget_motion,
    robot_mjcf,
)
from retarget.compare import similarity_fit, stance_foot_speed
from retarget.geoms import excluded_body_pairs
from retarget.robot_files import exclude_rest_contacts
from retarget.robots import PACKAGED_ROBOTS, robot_scene
from scenes import load_scene
from sim import check_trajectory

ROBOTS = tuple(PACKAGED_ROBOTS)


@pytest.fixture(scope="module")
def motion(sample_features) -> Motion:
    return Motion.from_features(sample_features)


def _renamed_g1(tmp_path: Path) -> Path:
    """G1 with every body and joint renamed and the left/right names swapped (names lie)."""
    src = robot_mjcf("g1")
    spec = mujoco.MjSpec.from_file(str(src))
    spec.meshdir = str(src.parent / "assets")
    swap = {"left": "right", "right": "left"}
    for i, body in enumerate(spec.bodies):
        if body.name and body.name != "world":
            side = next((s for s in swap if body.name.startswith(s)), None)
            body.name = f"{swap[side]}_b{i}" if side else f"b{i}"
    for i, joint in enumerate(spec.joints):
        if joint.name:
            joint.name = f"j{i}"
    for a in list(spec.actuators):
        spec.delete(a)
    for s in list(spec.sensors):
        spec.delete(s)
    for k in list(spec.keys):
        spec.delete(k)
    path = tmp_path / "renamed.xml"
    path.write_text(spec.to_xml())
    return path


def _outside_humanoid(tmp_path: Path) -> Path:
    """A humanoid from outside the package's naming and DoF: the G1 with its six wrist joints
    removed (23 DoF) and every body and joint renamed to numbered links, no actuators."""
    src = robot_mjcf("g1")
    spec = mujoco.MjSpec.from_file(str(src))
    spec.meshdir = str(src.parent / "assets")
    for kind in (spec.actuators, spec.sensors, spec.keys, [j for j in spec.joints if "wrist" in j.name]):
        for element in list(kind):
            spec.delete(element)
    for i, body in enumerate(spec.bodies):
        if body.name and body.name != "world":
            body.name = f"link{i:02d}"
    for i, joint in enumerate(spec.joints):
        joint.name = f"q{i:02d}" if joint.name else joint.name
    path = tmp_path / "outside.xml"
    path.write_text(spec.to_xml())
    return path


def test_outside_humanoid_by_path_through_the_cli(tmp_path, motion):
    """Issue 35's check: a humanoid MJCF of other naming and DoF, given by path, retargets the
    real clip; MuJoCo alone finds no limit, floor or self-collision fault, the similarity-aligned
    fit is close to the packaged G1's, and ``controlmm validate`` passes it."""
    path = _outside_humanoid(tmp_path)
    src = tmp_path / "clip.npy"
    np.save(src, motion.joints)
    prefix = tmp_path / "out"
    done = console("retarget", src, "--robot", path, "--fps", 30, "--out", prefix)  # as a user runs it
    assert done.returncode == 0, done.stderr
    with np.load(f"{prefix}.npz") as data:
        qpos = data["qpos"]
    assert qpos.shape == (len(np.arange(0, (motion.num_frames - 1) / motion.fps + 1e-9, 1 / 30)), 30)
    limits, floor_depth, self_frames = independent_check(path, qpos)
    assert (limits, self_frames) == (0, 0) and floor_depth <= 0.005, (limits, floor_depth, self_frames)
    fit = similarity_fit(load_robot(path), qpos, 30, motion.joints, motion.fps).mean
    assert fit <= 0.05, fit
    report = tmp_path / "report.json"
    checked = cli("validate", f"{prefix}.npz", "--robot", path, "--out", report, "--no-plot")
    assert checked.returncode == 0, checked.stdout + checked.stderr
    assert json.loads(report.read_text())["passed"] is True


def test_inferred_mapping_reads_geometry_not_names(tmp_path):
    path = _renamed_g1(tmp_path)
    mapping = infer_mapping(path)
    robot = load_robot(path)
    assert set(robot.keypoint_names) == set(load_robot("g1").keypoint_names)
    for joint in robot.keypoint_names:
        p = robot.rest_keypoints[robot.keypoint_index(joint)]
        if joint.startswith("left_"):
            assert p[1] > 0.03, joint  # +Y is the robot's left, whatever the names say
            assert mapping["keypoints"][joint]["body"].startswith("right_") or "_" not in joint[:1]
        if joint.startswith("right_"):
            assert p[1] < -0.03, joint
    # the same points as the packaged G1's inferred mapping, renamed
    packaged = load_robot(robot_mjcf("g1"))
    np.testing.assert_allclose(robot.rest_keypoints, packaged.rest_keypoints, atol=1e-9)
    # hip, knee and ankle from the chain and the joint axes: the knee keypoint is the knee joint
    g1 = mujoco.MjModel.from_xml_path(str(robot_mjcf("g1")))
    data = mujoco.MjData(g1)
    mujoco.mj_kinematics(g1, data)
    knee = robot.rest_keypoints[robot.keypoint_index("left_knee")]
    np.testing.assert_allclose(knee[:2], data.xanchor[g1.joint("left_knee_joint").id][:2], atol=1e-6)


def _g1_on_plates(tmp_path: Path) -> Path:
    """The G1 with each foot's collision spheres moved, unmoved in the world, into a body welded
    below the foot (no joint) whose origin sits 20 cm ahead of the ankle and 15 cm above it, as
    files put a foot's cleats or sole plate in bodies of their own at any origin."""
    spec = g1_spec()
    offset = np.array([0.2, 0.0, 0.15])
    for side in ("left", "right"):
        foot = spec.body(f"{side}_ankle_roll_link")
        plate = foot.add_body(name=f"{side}_plate", pos=offset)
        for geom in [g for g in foot.geoms if g.contype or g.conaffinity]:
            plate.add_geom(
                type=geom.type,
                size=geom.size,
                pos=np.asarray(geom.pos) - offset,
                contype=geom.contype,
                conaffinity=geom.conaffinity,
                group=geom.group,
                friction=geom.friction,
            )
            spec.delete(geom)
    return saved_without_controls(spec, tmp_path / "plates.xml")


def test_feet_standing_on_welded_plates_are_the_feet_above_them(tmp_path):
    """A foot's collision geometry in a body welded below it counts as the foot's: the robot is
    read as facing the way its toes point (not the way the plate's own origin makes them seem
    to point), its left leg is the +Y one and its ankles are the foot links, so the inferred
    keypoints are the plain G1's."""
    path = _g1_on_plates(tmp_path)
    mapping = infer_mapping(path)
    for side in ("left", "right"):
        assert mapping["keypoints"][f"{side}_ankle"]["body"] == f"{side}_ankle_roll_link"
    robot = load_robot(path)
    plain = load_robot(robot_mjcf("g1"))
    np.testing.assert_allclose(robot.rest_keypoints, plain.rest_keypoints, atol=1e-9)
    assert robot.rest_keypoints[robot.keypoint_index("left_ankle")][1] > 0.05


def _g1_with_cranks(tmp_path: Path) -> Path:
    """The G1 with a short crank on each side of its torso (one hinge, a 4 cm capsule, 9 cm from
    the torso's origin), as files write the levers of a parallel waist (LimX's HU_D03)."""
    spec = g1_spec()
    for side, sign in (("left", 1.0), ("right", -1.0)):
        crank = spec.body("torso_link").add_body(name=f"{side}_crank", pos=[0.0, sign * 0.08, 0.05])
        crank.add_joint(name=f"{side}_crank_joint", axis=[0.0, 1.0, 0.0], range=[-1.0, 1.0])
        crank.add_geom(
            type=mujoco.mjtGeom.mjGEOM_CAPSULE, fromto=[0, 0, 0, 0.04, 0, 0], size=[0.01, 0, 0], mass=0.05
        )
    return saved_without_controls(spec, tmp_path / "cranks.xml")


def test_short_links_beside_the_torso_are_not_the_hands(tmp_path):
    """A crank beside the torso lies as far from the midline as the hands, but not as far out
    from the torso: the arms are still the arms (they were lost: the hands' common ancestor
    with the cranks was the torso, and the robot was read as legs only)."""
    mapping = infer_mapping(_g1_with_cranks(tmp_path))
    for side in ("left", "right"):
        assert mapping["keypoints"][f"{side}_elbow"]["body"] == f"{side}_elbow_link"
        assert mapping["keypoints"][f"{side}_wrist"]["body"] == f"{side}_wrist_yaw_link"
    plain = load_robot(robot_mjcf("g1"))
    robot = load_robot(tmp_path / "cranks.xml")
    np.testing.assert_allclose(robot.rest_keypoints, plain.rest_keypoints, atol=1e-9)


@pytest.mark.slow
def test_inferred_mappings_fit_within_20_percent_of_the_reviewed(motion):
    for name in ROBOTS:
        fits = {}
        for robot in (name, str(robot_mjcf(name))):
            rm = load_robot(robot)
            traj = retarget_motion(motion, robot, fps=30, metrics=False)
            fits[robot] = similarity_fit(rm, traj.qpos, 30, motion.joints, motion.fps).mean
            assert np.all(np.isfinite(traj.qpos))
        reviewed, inferred = fits[name], fits[str(robot_mjcf(name))]
        assert inferred <= 1.2 * reviewed, f"{name}: inferred {inferred:.4f} m vs reviewed {reviewed:.4f} m"


def test_g1_fits_the_real_clip_closely_with_planted_feet(motion):
    """Issue 35: mean similarity-aligned fit on 012314 at 30 fps at most holosoma's 3.9 cm,
    stance feet and joints far steadier than the peers' (24.9 cm/s, 655 rad/s^3)."""
    robot = load_robot("g1")
    traj = retarget_motion(motion, "g1", fps=30)
    fit = similarity_fit(robot, traj.qpos, 30, motion.joints, motion.fps)
    assert fit.mean <= 0.039, fit
    assert stance_foot_speed(robot, traj.qpos, 30, motion.joints, motion.fps) <= 0.249 / 5
    assert traj.metrics["joint_jerk_rms_rad_s3"] <= 655 / 5
    report = check_trajectory(load_scene("empty", robot="g1"), traj.qpos, traj.fps)
    assert report.passed, report.summary()


@pytest.mark.slow
@pytest.mark.parametrize("name", ["t1", "op3", "berkeley_humanoid"])
def test_close_feet_never_overlap(name):
    """A sideways shuffle brings the human's feet together; the robot's feet stay apart."""
    _, joints, _, _ = make_clip(ClipSpec(7, "000007", "sidestep_left", "train", 0))
    traj = retarget_motion(Motion(joints=joints, fps=20.0), name, fps=30)
    report = check_trajectory(load_scene("empty", robot=name), traj.qpos, traj.fps)
    assert report.stats["self_collision_frames"] == 0, report.summary()
    assert traj.metrics["joint_limit_violations"] == 0 and traj.metrics["floor_penetration_max_mm"] == 0


def test_legs_only_robot_retargets_pelvis_and_legs(motion):
    robot = load_robot("berkeley_humanoid")
    assert robot.keypoint_names == [
        "pelvis",
        "left_hip",
        "right_hip",
        "left_knee",
        "right_knee",
        "left_ankle",
        "right_ankle",
        "left_foot",
        "right_foot",
    ]
    traj = retarget_motion(motion.joints[:60], "berkeley_humanoid", fps=30)
    assert traj.metrics["joint_limit_violations"] == 0
    fit = similarity_fit(robot, traj.qpos, 30, motion.joints[:60], motion.fps)
    assert fit.joints == ("pelvis", "left_knee", "right_knee", "left_ankle", "right_ankle")
    assert fit.mean < 0.06, fit


def test_flat_feet_from_the_sole():
    # Berkeley Humanoid's qpos0 pitches its feet 10 degrees: the flat foot is tilted back level
    robot = load_robot("berkeley_humanoid")
    for side in ("left", "right"):
        f = robot.feet[side]
        world = f.points @ robot.foot_flat_rot[side].T
        low = world[:, 2] - f.radius
        sole = low <= low.min() + 0.001
        assert np.ptp(world[sole, 0]) > 0.1  # the whole sole on the floor, heel to toe
    g1 = load_robot("g1")
    np.testing.assert_allclose(g1.foot_flat_rot["left"], g1.rest.rot[0, g1.feet["left"].node], atol=1e-12)


def test_robots_cli_lists_and_maps(tmp_path):
    out = cli("robots")
    assert out.returncode == 0, out.stderr
    lines = out.stdout.strip().splitlines()
    assert lines[0].split()[:3] == ["robot", "DoF", "height"]
    rows = {line.split()[0]: line.split() for line in lines[1:]}
    assert list(rows) == ["g1", "h1", "t1", "apollo", "berkeley_humanoid", "op3"]
    dof = {name: int(row[1]) for name, row in rows.items()}
    height = {name: float(row[2]) for name, row in rows.items()}
    scale = {name: float(row[3]) for name, row in rows.items()}
    assert dof["g1"] == 29 and dof["h1"] == 19 and dof["berkeley_humanoid"] == 12
    assert 1.2 < height["g1"] < 1.4 and 1.7 < height["h1"] < 1.9 and 0.4 < height["op3"] < 0.6
    assert scale["g1"] == pytest.approx(load_robot("g1").scale, abs=1e-3)
    assert sorted(scale, key=scale.get) == sorted(height, key=height.get)  # taller, larger scale
    assert "pelvis and legs" in " ".join(rows["berkeley_humanoid"]) and "arms" in " ".join(rows["apollo"])
    mapping = tmp_path / "op3.json"
    done = cli("robots", "map", robot_mjcf("op3"), "--out", mapping)
    assert done.returncode == 0, done.stderr
    data = json.loads(mapping.read_text())
    assert data["keypoints"]["left_knee"]["body"] == "l_knee_link"
    assert load_robot(mapping).keypoint_names == load_robot("op3").keypoint_names
    again = cli("robots", "map", robot_mjcf("op3"), "--out", mapping)
    assert again.returncode == 2 and "--force" in again.stderr


def _write(path: Path, text: str) -> Path:
    path.write_text(text)
    return path


def test_bad_robot_files_are_one_line_errors(tmp_path, motion):
    no_free = _write(
        tmp_path / "nofree.xml",
        '<mujoco><worldbody><body name="a"><geom size="0.1"/></body></worldbody></mujoco>',
    )
    broken = _write(tmp_path / "broken.xml", '<mujoco><worldbody><body name="a"><geom size="0.1" typo="1"/>')
    ball = _write(
        tmp_path / "ball.xml",
        '<mujoco><worldbody><body name="a"><freejoint/><geom size="0.1"/></body></worldbody></mujoco>',
    )
    humanoid = capsule_humanoid_xml("plain")
    loose = '<body name="prop" pos="1 0 0.1"><freejoint/><geom size="0.1"/></body>\n  </worldbody>'
    scene = _write(tmp_path / "scene.xml", humanoid.replace("</worldbody>", loose, 1))
    # the left shoulder's three hinges written as one ball joint
    shoulder = re.sub(
        r'<joint name="shoulder_x_l"[^>]*/>', '<joint name="shoulder_l" type="ball"/>', humanoid
    )
    ball_joint = _write(
        tmp_path / "balljoint.xml", re.sub(r'\s*<joint name="shoulder_[yz]_l"[^>]*/>', "", shoulder)
    )
    # feet and toes that collide with nothing: the shins are the lowest collision geometry
    lines, body = [], ""
    for line in humanoid.splitlines():
        body = line.split('name="')[1].split('"')[0] if "<body " in line else body
        bare = "<geom " in line and body.startswith(("foot_", "toes_"))
        lines.append(line.replace("<geom ", '<geom contype="0" conaffinity="0" ') if bare else line)
    bare_feet = _write(tmp_path / "barefeet.xml", "\n".join(lines))
    # four capsule legs under a box: a quadruped standing on its "arms"
    legs = "".join(
        f'<body name="{n}_thigh" pos="{x} {y} 0"><joint name="{n}_hip" axis="0 1 0"/>'
        '<geom type="capsule" fromto="0 0 0 0 0 -0.15" size="0.02"/>'
        f'<body name="{n}_calf" pos="0 0 -0.15"><joint name="{n}_knee" axis="0 1 0"/>'
        '<geom type="capsule" fromto="0 0 0 0 0 -0.15" size="0.02"/></body></body>'
        for n, x, y in (("FL", 0.2, 0.1), ("FR", 0.2, -0.1), ("RL", -0.2, 0.1), ("RR", -0.2, -0.1))
    )
    quadruped = _write(
        tmp_path / "quadruped.xml",
        '<mujoco><worldbody><body name="base" pos="0 0 0.32"><freejoint/>'
        f'<geom type="box" size="0.25 0.12 0.05"/>{legs}</body></worldbody></mujoco>',
    )
    bad_body = json.loads((Path(__file__).parents[1] / "retarget/mappings/t1.json").read_text())
    bad_body["keypoints"]["left_knee"]["body"] = "Knee_Left"
    bad_mapping = _write(tmp_path / "bad.json", json.dumps(bad_body))
    src = tmp_path / "m.npy"
    np.save(src, motion.joints[:20])
    cases = [
        (no_free, "no free joint"),
        (broken, "does not load"),
        (ball, "no two legs"),
        (quadruped, "stands on four limbs: its left arm"),
        (bare_feet, "left leg that goes on below its collision geometry: link 'foot_l'"),
        (scene, r"2 free joints \(on root, prop\)"),
        (ball_joint, "joint 'shoulder_l' is a mjJNT_BALL joint; the retargeter supports hinge and slide"),
        (bad_mapping, "body 'Knee_Left'"),
        (tmp_path / "missing.xml", "does not exist"),
    ]
    for robot, needle in cases:
        with pytest.raises(ControlMMError, match=needle):
            load_robot(robot)
    for argv, needle in (
        (("retarget", src, "--robot", no_free, "--out", tmp_path / "r"), "no free joint"),
        (("retarget", src, "--robot", broken, "--out", tmp_path / "r"), "does not load"),
        (("retarget", src, "--robot", bad_mapping, "--out", tmp_path / "r"), "body 'Knee_Left'"),
        (("robots", "map", ball, "--out", tmp_path / "m.json"), "no two legs"),
        (("robots", "map", quadruped, "--out", tmp_path / "m.json"), "stands on four limbs"),
        (("robots", "map", bare_feet, "--out", tmp_path / "m.json"), "has none to stand on"),
        (("robots", "map", scene, "--out", tmp_path / "m.json"), "not a scene with loose bodies"),
        (("robots", "map", ball_joint, "--out", tmp_path / "m.json"), "joint 'shoulder_l' is a mjJNT_BALL"),
        (
            ("retarget", src, "--robot", ball_joint, "--out", tmp_path / "r"),
            "joint 'shoulder_l' is a mjJNT_BALL",
        ),
    ):
        done = cli(*argv)
        err = done.stderr.strip()
        assert done.returncode == 2 and needle in err and len(err.splitlines()) == 1, (argv, err)
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(
        [
            "nofree.xml",
            "broken.xml",
            "ball.xml",
            "barefeet.xml",
            "scene.xml",
            "balljoint.xml",
            "quadruped.xml",
            "bad.json",
            "m.npy",
        ]
    )


def test_any_robot_spec_plans_validates_and_shows(tmp_path, motion):
    """A mapping .json or an MJCF path works wherever a robot is taken (plan's inputs included)."""
    mapping = tmp_path / "apollo.json"
    mapping.write_text((Path(__file__).parents[1] / "retarget/mappings/apollo.json").read_text())
    for robot in (mapping, robot_mjcf("t1")):
        scene, _, _, transform = resolve_inputs(PlanConfig(scene="table", robot=str(robot)))
        assert scene.model.nq == load_robot(robot).model.nq
        assert transform.scale == pytest.approx(load_robot(robot).scale)
    traj = retarget_motion(motion.joints[:40], str(mapping), fps=30)
    prefix = tmp_path / "traj"
    traj.save(prefix)
    done = cli("validate", f"{prefix}.npz", "--out", tmp_path / "report.json", "--no-plot")
    assert done.returncode in (0, 1) and "contact:" in done.stdout, done.stderr
    with pytest.raises(ControlMMError):
        load_robot(tmp_path / "nothing.json")


def test_contacts_of_the_rest_pose_are_excluded(tmp_path):
    """Geoms that overlap in ``qpos0`` (a knee hull reaching the ankle) are the model's, not a
    motion's: the loaded robot excludes that body pair, and no other."""
    src = robot_mjcf("g1")
    spec = mujoco.MjSpec.from_file(str(src))
    spec.meshdir = str(src.parent / "assets")
    g1 = spec.compile()
    data = mujoco.MjData(g1)
    mujoco.mj_forward(g1, data)
    knee, ankle = g1.body("left_knee_link").id, g1.body("left_ankle_roll_link").id
    heel = next(g for g in range(g1.ngeom) if g1.geom_bodyid[g] == ankle and g1.geom_contype[g])
    reach = data.xmat[knee].reshape(3, 3).T @ (data.geom_xpos[heel] - data.xpos[knee])
    hull = spec.body("left_knee_link").add_geom()
    hull.type, hull.size, hull.fromto = mujoco.mjtGeom.mjGEOM_CAPSULE, [0.03, 0, 0], [0, 0, 0, *reach]
    hull.contype = hull.conaffinity = 1
    path = tmp_path / "g1_long_knee.xml"
    path.write_text(spec.to_xml())
    loaded = load_robot_spec(path)
    assert [(e.bodyname1, e.bodyname2) for e in loaded.excludes][-1:] == [
        ("left_ankle_roll_link", "left_knee_link")
    ]
    assert len(loaded.excludes) == len(spec.excludes) + 1
    model = load_robot(path).model
    pair = frozenset((model.body("left_knee_link").id, model.body("left_ankle_roll_link").id))
    assert pair in excluded_body_pairs(model) and pair not in excluded_body_pairs(g1)
    report = check_trajectory(load_scene("empty", robot=str(path)), load_robot(path).model.qpos0[None], 30)
    assert report.stats["self_collision_frames"] == 0, report.summary()


@pytest.mark.parametrize("robot", ROBOTS)
def test_packaged_robots_have_no_contacts_in_their_rest_pose(robot):
    """Loading a packaged robot skips the rest-contact search (a compile per load): that is right
    only while none of them has overlapping colliders in ``qpos0``."""
    assert exclude_rest_contacts(load_robot_spec(robot)) == []


def test_a_robot_given_by_its_scene_file_joins_any_scene():
    """Menagerie's ``scene.xml`` (the G1 with a floor, a sky and a ``groundplane`` texture and
    material, as the packaged scenes have) given as the robot: its body tree joins the scene,
    whose own floor assets it no longer repeats (this was an internal error in validate)."""
    path = robot_scene("g1")
    names = {t.name for t in mujoco.MjSpec.from_file(str(path)).textures}
    assert "groundplane" in names
    for name in ("empty", "table"):
        by_file, by_name = load_scene(name, robot=str(path)), load_scene(name, robot="g1")
        assert len(by_file.robot_geom_ids) == len(by_name.robot_geom_ids) > 0
        assert by_file.model.nq == by_name.model.nq and by_file.model.nu == by_name.model.nu


@pytest.mark.parametrize("scene_file", ["apollo:scene.xml", "g1:scene_mjx.xml"])
def test_a_scene_file_whose_feet_touch_the_floor_through_pairs_stands_on_any_floor(scene_file, sample_joints):
    """Menagerie's Apollo scene and G1 MJX scene collide only through ``<pair>`` elements, the
    feet's with the scene's own floor among them: given as the robot, their colliders are
    declared from the collision group (a floor geom with contype does not count as the
    robot's), the floor pairs are dropped (only the body tree joins a scene, whose floor the
    checks sense with margins), and the robot stands (this read as floating in validate, and
    the G1 MJX scene had "no collision geometry")."""
    robot, name = scene_file.split(":")
    path = robot_scene(robot).parent / name
    floor = {g.name for g in mujoco.MjSpec.from_file(str(path)).worldbody.geoms}
    assert any({p.geomname1, p.geomname2} & floor for p in mujoco.MjSpec.from_file(str(path)).pairs)
    spec = load_robot_spec(str(path))
    assert not any({p.geomname1, p.geomname2} & floor for p in spec.pairs)
    motion = Motion(joints=sample_joints[:40].astype(np.float64), fps=20.0)
    traj = retarget_motion(motion, str(path), fps=30.0, metrics=False)
    report = check_trajectory(load_scene("empty", robot=str(path)), traj.qpos, traj.fps)
    assert "floating" not in report.stats["error_kinds"]
    assert report.stats["self_collision_frames"] == 0
