"""Humanoid MJCFs written the way mocap-derived models are (:mod:`capsule_humanoid`): a root
frame that is Y up with the robot facing -Y (the CMU humanoid), or the whole robot written Y up
and lying along +Y (SMPL humanoids); toe links below the feet, finger and thumb links below
each hand, clavicles and a jointed spine of capsules. Such a robot retargets as the same robot
written plainly (+Z up, facing +X): the rest frame is read from its feet, not assumed."""

from __future__ import annotations

import os
from pathlib import Path

import mujoco
import numpy as np
import pytest
from capsule_humanoid import STYLES, capsule_humanoid_xml
from cli_helpers import console, in_process as cli
from robot_checks import independent_check
from scipy.spatial.transform import Rotation

from controlmm.motion import Motion
from retarget import RobotModel, infer_mapping, load_robot, retarget_motion
from retarget.automap import RIGID_POSTURE
from retarget.compare import robot_keypoints, similarity_fit
from retarget.geoms import geom_points
from retarget.rest_frame import rest_root_quat
from retarget.robot_files import compile_robot, free_root
from retarget.selfcheck import unpaired_overlaps
from retarget.selfcollision import REST_SLACK, SELF_MARGIN, capsule_distances
from retarget.soles import FOOT_POINTS_MOST
from retarget.spec_edits import drop_closed_chain_rods


@pytest.fixture(scope="module")
def motion(sample_features) -> Motion:
    return Motion.from_features(sample_features)


@pytest.fixture(scope="module")
def humanoids(tmp_path_factory) -> dict[str, Path]:
    folder = tmp_path_factory.mktemp("humanoids")
    out = {}
    for style in STYLES:
        out[style] = folder / f"{style}.xml"
        out[style].write_text(capsule_humanoid_xml(style))
    return out


def _capsule_body(robot: RobotModel, c: int) -> str:
    """The name of the body whose geom self-clearance capsule ``c`` encloses."""
    m, sc = robot.model, robot.self_clearance
    return m.body(int(m.geom_bodyid[int(sc.geom[c])])).name


def _pairs_between(robot: RobotModel, *pairs: tuple[str, str]) -> np.ndarray:
    """(P,) which of the robot's self-clearance pairs join the bodies of one of ``pairs``."""
    sc = robot.self_clearance
    wanted = [set(p) for p in pairs]
    return np.array(
        [
            {_capsule_body(robot, a), _capsule_body(robot, b)} in wanted
            for a, b in zip(sc.first, sc.second, strict=True)
        ]
    )


def _rest_and_turned(model: mujoco.MjModel, joint: str, degrees: float) -> tuple[np.ndarray, np.ndarray]:
    """The plain capsule humanoid's rest qpos standing at the origin, and the same with ``joint`` turned."""
    rest = model.qpos0.copy()
    rest[:7] = [0, 0, 0.96, 1, 0, 0, 0]
    turned = rest.copy()
    turned[model.jnt_qposadr[model.joint(joint).id]] = np.radians(degrees)
    return rest, turned


def _overlap(model: mujoco.MjModel, qpos: np.ndarray, first: str, second: str) -> float:
    """How deep (m, 0 if not at all) MuJoCo finds bodies ``first`` and ``second`` overlapping."""
    data = mujoco.MjData(model)
    data.qpos[:] = qpos
    mujoco.mj_forward(model, data)
    depths = [
        -c.dist
        for c in data.contact[: data.ncon]
        if {
            model.body(int(model.geom_bodyid[c.geom1])).name,
            model.body(int(model.geom_bodyid[c.geom2])).name,
        }
        == {first, second}
    ]
    return max([0.0, *depths])


def test_the_rest_frame_stands_every_style_up_facing_plus_x(humanoids):
    """The plain file keeps its identity root; the turned and the lying ones are turned so that
    their rest pose is the plain one's: the same keypoints, feet, scale and left leg (+Y)."""
    models = {k: mujoco.MjModel.from_xml_path(str(path)) for k, path in humanoids.items()}
    quats = {k: rest_root_quat(m, free_root(m)) for k, m in models.items()}
    assert np.allclose(quats["plain"], [1, 0, 0, 0])
    plain = load_robot(humanoids["plain"])
    for style in ("turned", "lying"):
        assert not np.allclose(np.abs(quats[style]), [1, 0, 0, 0])
        other = load_robot(humanoids[style])
        assert np.allclose(plain.rest_keypoints, other.rest_keypoints, atol=1e-9), style
        assert other.floor_z == pytest.approx(plain.floor_z) and other.scale == pytest.approx(plain.scale)
    b = load_robot(humanoids["turned"])
    mapping = infer_mapping(humanoids["turned"])
    kp = mapping["keypoints"]
    assert (kp["left_hip"]["body"], kp["right_knee"]["body"], kp["left_wrist"]["body"]) == (
        "thigh_l",
        "shin_r",
        "hand_l",
    )
    # The foot is the link above the toe link, and stands on the toe's geometry too; the toes
    # and fingers are held at rest.
    assert kp["left_ankle"]["body"] == "foot_l" and kp["right_ankle"]["body"] == "foot_r"
    toe_geoms = {
        g for g in range(b.model.ngeom) if b.model.body(int(b.model.geom_bodyid[g])).name == "toes_l"
    }
    assert toe_geoms and toe_geoms <= set(b.feet["left"].geoms)
    for joint in ("toes_l", "toes_r", "fingers_l", "thumb_r"):
        assert mapping["posture_weights"][joint] == RIGID_POSTURE


def test_robots_map_says_how_it_turns_a_file_it_reads_otherwise(tmp_path, humanoids):
    """``controlmm robots map`` says along which of the file's axes the robot stands and which
    way it faces where it turns it (the lying one: +Y up, facing +Z), and nothing where the
    file stands at +Z facing +X (so that a robot read the wrong way shows in the review)."""
    said = {}
    for style in ("plain", "turned", "lying"):
        done = cli("robots", "map", humanoids[style], "--out", tmp_path / f"{style}.json")
        assert done.returncode == 0, done.stderr
        said[style] = [line for line in done.stdout.splitlines() if "rest frame" in line]
    assert said["plain"] == []
    assert len(said["lying"]) == 1 and "stands along its world +Y axis and faces +Z" in said["lying"][0]
    assert len(said["turned"]) == 1 and "faces -Y" in said["turned"][0]


def test_the_spine_and_the_clavicles_are_kept_clear_on_a_capsule_humanoid(humanoids):
    """Capsule links that MuJoCo collides and the arm pairs leave out: the pelvis against the
    chest over the lower back, the chest against the upper arms (a lifted clavicle)."""
    robot = load_robot(humanoids["turned"])
    sc, m = robot.self_clearance, robot.model
    assert sc is not None
    pairs = {
        frozenset(m.body(int(m.geom_bodyid[sc.geom[i]])).name for i in (a, b))
        for a, b in zip(sc.first, sc.second, strict=True)
    }
    for pair in (
        ("root", "chest"),
        ("chest", "upperarm_l"),
        ("chest", "upperarm_r"),
        ("lowerback", "upperarm_l"),
        ("head", "clavicle_l"),  # a jointed neck folding the head onto a clavicle
        ("head", "clavicle_r"),
        ("head", "upperarm_l"),
        ("hand_l", "shin_l"),  # the foot hangs from the shin: a stooping hand reaches it
        ("hand_r", "shin_r"),
    ):
        assert frozenset(pair) in pairs, pair


def test_a_thumb_is_kept_out_of_its_fingers(humanoids):
    """Links branching from one hand (the fingers and the thumb) are a pair of their own: the
    arm's pairs push a thumb out of a shin, nothing else keeps it from turning into the
    fingers (the CMU humanoid's crouches). Clear at rest (3.7 cm apart), the pair falls short
    of its margin where the thumb is turned 90 degrees, 4-5 mm inside the finger by MuJoCo."""
    robot = load_robot(humanoids["plain"])
    sc, m = robot.self_clearance, robot.model
    assert sc is not None
    hand = _pairs_between(robot, ("fingers_l", "thumb_l"), ("fingers_r", "thumb_r"))
    assert hand.sum() == 2 and np.all(sc.margin[hand] == SELF_MARGIN)
    rest, folded = _rest_and_turned(m, "thumb_l", 90)
    assert _overlap(m, folded, "thumb_l", "fingers_l") > 0.003
    poses = robot.tree.forward(np.zeros((2, 3)), np.stack([np.eye(3)] * 2), np.stack([rest[7:], folded[7:]]))
    dist = capsule_distances(poses, sc.select_pairs(hand))[0]
    assert np.all(dist[0] > SELF_MARGIN) and dist[1, 0] < 0.0 < dist[1, 1]


def test_fingers_side_by_side_are_kept_apart(tmp_path):
    """Links of one hand 7 mm apart at rest (PHC's G1: its fingers side by side, their
    enclosures touching) are kept from coming more than ``REST_SLACK`` closer than that."""
    text = capsule_humanoid_xml("plain")
    for side in ("l", "r"):
        old = f'<body name="thumb_{side}" pos="0.04 0 -0.04">'
        assert old in text
        text = text.replace(old, f'<body name="thumb_{side}" pos="0 0.034 -0.09">')
    path = tmp_path / "close_thumbs.xml"
    path.write_text(text)
    robot = load_robot(path)
    sc = robot.self_clearance
    assert sc is not None
    hand = _pairs_between(robot, ("fingers_l", "thumb_l"), ("fingers_r", "thumb_r"))
    assert hand.sum() == 2
    rest = capsule_distances(robot.rest, sc.select_pairs(hand))[0][0]
    np.testing.assert_allclose(rest, 0.007, atol=1e-6)
    np.testing.assert_allclose(sc.margin[hand], rest - REST_SLACK, atol=1e-9)


def _meshed_sole_humanoid(tmp_path: Path) -> tuple[Path, np.ndarray]:
    """The plain capsule humanoid with its feet a rounded mesh of many vertices (a sole 20 x
    9 cm, 4 cm high, as finely tessellated as an STL foot) in place of their capsules; the
    path and the mesh's vertices (V, 3)."""
    u, v = np.meshgrid(np.linspace(0, 2 * np.pi, 40, endpoint=False), np.linspace(-np.pi / 2, np.pi / 2, 16))
    c, s = np.cos(v), np.sin(v)
    # a superellipsoid: flat-ish sole and sides, rounded edges
    sgn = lambda x, e: np.sign(x) * np.abs(x) ** e  # noqa: E731
    verts = np.stack(
        [
            0.1 * sgn(c, 0.4) * sgn(np.cos(u), 0.4),
            0.045 * sgn(c, 0.4) * sgn(np.sin(u), 0.4),
            0.02 * sgn(s, 0.4),
        ],
        -1,
    ).reshape(-1, 3)
    verts = np.unique(np.round(verts, 6), axis=0)
    text = capsule_humanoid_xml("plain").replace(
        "<worldbody>",
        '<asset><mesh name="sole" vertex="'
        + " ".join(f"{x:.6f}" for x in verts.ravel())
        + '"/></asset>\n  <worldbody>',
    )
    foot = '<geom type="capsule" fromto="-0.05 0 -0.04 0.1 0 -0.04" size="0.03"/>'
    assert text.count(foot) == 2
    text = text.replace(foot, '<geom type="mesh" mesh="sole" pos="0.025 0 -0.05"/>')
    path = tmp_path / "meshed_sole.xml"
    path.write_text(text)
    return path, verts


def test_a_finely_meshed_foot_keeps_the_points_that_can_touch_the_floor(tmp_path):
    """A foot whose collision mesh has hundreds of hull vertices (PHC's G1: 900-1,000, which
    made its floor terms 70 % of a call) keeps those that are its lowest for some tilt up to
    75 degrees from rest: the lowest point of the foot is the same for any such tilt, and
    the rest pose stands on the same floor."""
    path, verts = _meshed_sole_humanoid(tmp_path)
    robot = load_robot(path)
    model = robot.model
    mesh_geoms = [g for g in range(model.ngeom) if model.geom_type[g] == mujoco.mjtGeom.mjGEOM_MESH]
    assert len(mesh_geoms) == 2
    hull = len(geom_points(model, mesh_geoms[0])[0])
    assert hull > 300
    data = mujoco.MjData(model)
    mujoco.mj_kinematics(model, data)
    rng = np.random.default_rng(0)
    for side in ("left", "right"):
        f = robot.feet[side]
        assert FOOT_POINTS_MOST < len(f.points) < hull / 2
        # every point of the foot's geoms (its toe link's too), in the foot body's frame
        foot = int(robot.tree.node_body[f.node])
        every = np.concatenate(
            [
                (
                    data.xpos[model.geom_bodyid[g]]
                    + geom_points(model, g)[0] @ data.xmat[model.geom_bodyid[g]].reshape(3, 3).T
                    - data.xpos[foot]
                )
                @ data.xmat[foot].reshape(3, 3)
                for g in f.geoms
            ]
        )
        radius = np.concatenate([geom_points(model, g)[1] for g in f.geoms])
        rest = robot.rest.rot[0, f.node]
        for k in range(200):
            axis = rng.normal(size=3)
            axis[2] = 0.0
            angle = rng.uniform(0.0, np.radians(60)) if k else 0.0  # the rest pose first
            tilt = Rotation.from_rotvec(angle * axis / np.linalg.norm(axis)).as_matrix() @ rest
            lowest = ((f.points @ tilt.T)[:, 2] - f.radius).min()
            assert lowest == pytest.approx(((every @ tilt.T)[:, 2] - radius).min(), abs=1e-3)


def test_an_elbow_roll_is_not_taken_for_the_wrist(tmp_path, motion):
    """Arms whose only joint past the elbow rolls the forearm about its own length, 8 cm past
    the elbow, with the hand a rigid link below it (the older G1's elbow roll, PHC's G1): the
    wrist is where the hand is attached, 26 cm past the elbow as on the plain humanoid with its
    wrist joints, not the roll's anchor (8 cm: the real clip's wrists 14 cm from the human's);
    the real clip's wrists fit as on the plain humanoid."""
    fits = {}
    for roll in (False, True):
        path = tmp_path / f"roll_{roll}.xml"
        path.write_text(capsule_humanoid_xml("plain", forearm_roll=roll))
        robot = load_robot(path)
        for side in ("left", "right"):
            wrist, elbow = (
                robot.rest_keypoints[robot.keypoint_index(f"{side}_{j}")] for j in ("wrist", "elbow")
            )
            assert np.linalg.norm(wrist - elbow) == pytest.approx(0.26, abs=0.005), (roll, side)
        traj = retarget_motion(motion, robot, fps=30.0, metrics=False)
        fit = similarity_fit(robot, traj.qpos, 30.0, motion.joints, motion.fps)
        fits[roll] = [fit.per_joint[f"{side}_wrist"] for side in ("left", "right")]
    assert max(fits[True]) < 0.05
    assert np.allclose(fits[True], fits[False], atol=0.01)


def test_a_hand_without_wrist_joints_is_held_where_it_is_attached(tmp_path, motion):
    """Hands written without their wrist joints, a 24 cm mitten (GMR's T1 file): attached on
    the forearm's line, the wrist is where the hand is attached, 26 cm past the elbow as on the
    plain humanoid (on the old code 41 cm, most of the way to the mitten's end: the real clip's
    wrists 8-9 cm from the human's, the plain humanoid's 3.5-4.6), and the real clip's wrists
    fit as on the plain humanoid; attached 10 cm in front of that line (a hand hanging off a
    gear), the attachment is not taken: the wrist stays on the elbow -> hand tip line."""
    wrists, fits = {}, {}
    for hand in ("", "inline", "aside"):
        path = tmp_path / f"hand_{hand or 'plain'}.xml"
        path.write_text(capsule_humanoid_xml("plain", rigid_hand=hand))
        robot = load_robot(path)
        wrists[hand] = [
            robot.rest_keypoints[robot.keypoint_index(f"{side}_wrist")]
            - robot.rest_keypoints[robot.keypoint_index(f"{side}_elbow")]
            for side in ("left", "right")
        ]
        if hand in ("", "inline"):
            traj = retarget_motion(motion, robot, fps=30.0, metrics=False)
            fit = similarity_fit(robot, traj.qpos, 30.0, motion.joints, motion.fps)
            fits[hand] = [fit.per_joint[f"{side}_wrist"] for side in ("left", "right")]
    for side in range(2):
        assert np.allclose(wrists["inline"][side], wrists[""][side], atol=0.005), side
        aside = wrists["aside"][side]
        assert abs(aside[0]) < 0.01 and np.linalg.norm(aside - (0.1, 0.0, -0.2)) > 0.05, side
    assert max(fits["inline"]) < 0.05
    assert np.allclose(fits["inline"], fits[""], atol=0.01)


def test_an_arm_without_geometry_past_its_elbow_is_read_from_its_masses(tmp_path):
    """Forearms, hands and fingers written with masses but no geoms (BXI's Elf2 has only
    visual meshes there; without them nothing marks where its arms end): the arm's end is
    its farthest centre of mass, and its shoulder, elbow and wrist are where the plain
    humanoid's are (on the old code the arm ended at the hand's origin and the shoulder and
    elbow keypoints fell on the forearm and upper arm)."""
    keypoints = {}
    for bare in (False, True):
        path = tmp_path / f"bare_{bare}.xml"
        path.write_text(capsule_humanoid_xml("plain", bare_forearms=bare))
        mapping = load_robot(path).mapping
        keypoints[bare] = {k.joint: (k.body, k.offset) for k in mapping.keypoints}
    for side in ("left", "right"):
        for joint in ("shoulder", "elbow", "wrist"):
            (body, offset), (plain_body, plain_offset) = (
                keypoints[b][f"{side}_{joint}"] for b in (True, False)
            )
            assert body == plain_body, (side, joint)
            np.testing.assert_allclose(offset, plain_offset, atol=0.01)


def test_an_elbow_comes_after_the_upper_arms_twist(tmp_path, motion):
    """Clavicle joints 22 cm above the shoulder (Atlas's clavicle joint sits 25 cm above its
    shoulder-roll hinge, which comes a third of the way along its arm): the shoulder's hinge
    across the arm is no elbow; the elbow is the first such hinge past the upper arm's twist,
    also where the clavicle's first joint turns about the hanging arm (a twist at the limb's
    start, loco-mujoco's Atlas).
    The shoulder, elbow and wrist keypoints are on the bodies the plain humanoid's are, and
    the arms fit the real clip as closely (on the old code the elbow keypoint fell on the
    upper arm, at the shoulder)."""
    fits = {}
    for drop, yaw in ((0.0, False), (0.22, False), (0.22, True)):
        path = tmp_path / f"drop_{drop}_{yaw}.xml"
        path.write_text(capsule_humanoid_xml("plain", clavicle_drop=drop, clavicle_yaw=yaw))
        robot = load_robot(path)
        bodies = {k.joint: k.body for k in robot.mapping.keypoints}
        for side, s in (("left", "l"), ("right", "r")):
            assert bodies[f"{side}_elbow"] == f"forearm_{s}", (drop, yaw)
            assert bodies[f"{side}_shoulder"] == f"upperarm_{s}", (drop, yaw)
            assert bodies[f"{side}_wrist"] == f"hand_{s}", (drop, yaw)
        traj = retarget_motion(motion, robot, fps=30.0, metrics=False)
        fit = similarity_fit(robot, traj.qpos, 30.0, motion.joints, motion.fps)
        fits[drop, yaw] = np.array(
            [fit.per_joint[f"{side}_{j}"] for side in ("left", "right") for j in ("elbow", "wrist")]
        )
    for dropped in ((0.22, False), (0.22, True)):
        np.testing.assert_allclose(fits[dropped], fits[0.0, False], atol=0.01, err_msg=str(dropped))


def test_geoms_the_anatomy_leaves_alone_are_found_where_they_overlap(humanoids):
    """Without its head-clavicle pairs, the capsule humanoid's clearance does not keep the head
    off the clavicles; rolling the neck 45 degrees puts the head 1.4 cm into the right clavicle
    by MuJoCo: ``unpaired_overlaps`` finds that pair (apart at rest: a full 2 cm margin), and
    nothing at rest or once the pair is kept."""
    robot = load_robot(humanoids["plain"])
    sc, m = robot.self_clearance, robot.model
    assert sc is not None
    neck = _pairs_between(robot, ("head", "clavicle_l"), ("head", "clavicle_r"))
    assert neck.sum() == 2
    without = sc.select_pairs(~neck)
    rest, rolled = _rest_and_turned(m, "neck_x", 45)
    assert _overlap(m, rolled, "head", "clavicle_r") > 0.01
    first, second, margin = unpaired_overlaps(m, robot.tree, np.stack([rest, rolled]), without, robot.rest)
    assert [
        (_capsule_body(robot, a), _capsule_body(robot, b)) for a, b in zip(first, second, strict=True)
    ] == [("head", "clavicle_r")]
    assert margin.tolist() == [SELF_MARGIN]
    assert unpaired_overlaps(m, robot.tree, rest[None], without, robot.rest)[0].size == 0
    assert unpaired_overlaps(m, robot.tree, rolled[None], sc, robot.rest)[0].size == 0


def test_every_style_retargets_like_the_plain_one(tmp_path, humanoids, motion):
    """Issue 35's check on a humanoid written otherwise: given by path it retargets the real
    clip with no limit, floor or self-collision fault (MuJoCo alone), closely, passing
    ``controlmm validate``, and as the plain file does (the same poses)."""
    src = tmp_path / "clip.npy"
    np.save(src, motion.joints)
    qpos = {}
    for name, path in humanoids.items():
        prefix = tmp_path / name
        done = cli("retarget", src, "--robot", path, "--fps", 30, "--out", prefix)
        assert done.returncode == 0, done.stderr
        with np.load(f"{prefix}.npz") as data:
            qpos[name] = data["qpos"]
    fits = {
        k: similarity_fit(load_robot(humanoids[k]), q, 30, motion.joints, motion.fps).mean
        for k, q in qpos.items()
    }
    keypoints = {k: robot_keypoints(load_robot(humanoids[k]), q) for k, q in qpos.items()}
    for style in ("turned", "lying"):
        limits, floor_depth, self_frames = independent_check(humanoids[style], qpos[style])
        assert (limits, self_frames) == (0, 0) and floor_depth <= 0.005, (
            style,
            limits,
            floor_depth,
            self_frames,
        )
        assert fits[style] <= 0.04 and abs(fits[style] - fits["plain"]) < 0.002, fits
        # The same poses (the turned file exactly; the lying one up to rounding, which a wrist
        # the human does not observe may amplify in a frame or two).
        apart = np.linalg.norm(keypoints[style] - keypoints["plain"], axis=2)
        assert apart.mean() < 0.005, (style, apart.mean(), apart.max())
    checked = cli(
        "validate",
        f"{tmp_path / 'lying'}.npz",
        "--robot",
        humanoids["lying"],
        "--out",
        tmp_path / "r.json",
        "--no-plot",
    )
    assert checked.returncode == 0, checked.stdout + checked.stderr


def test_a_robot_given_by_path_renders_with_mujoco(tmp_path, humanoids, motion):
    """The render scene of a robot file (a light and a floor added to it) compiles with this
    MuJoCo: the video is drawn by MuJoCo, not the stick-figure fallback."""
    src = tmp_path / "clip.npy"
    np.save(src, motion.joints[:12])
    small = ("--render-width", "64", "--render-height", "48", "--render-fps", "10")
    env = {**os.environ, "MUJOCO_GL": "egl"}
    done = console(
        "retarget",
        src,
        "--robot",
        humanoids["turned"],
        "--out",
        tmp_path / "a",
        "--render",
        tmp_path / "a.mp4",
        *small,
        env=env,
    )
    assert done.returncode == 0, done.stderr
    assert "(mujoco)" in done.stdout and (tmp_path / "a.mp4").stat().st_size > 500, done.stdout


def _root_joints(text: str, joints: str) -> str:
    """``text`` with the root's free joint replaced by ``joints`` and, around them, a motor and
    a position sensor on the root's first slide (a file driving or reading its floating base)."""
    text = text.replace('<freejoint name="root"/>', joints, 1)
    extra = '<actuator><motor joint="root_x"/></actuator><sensor><jointpos joint="root_x"/></sensor>'
    return text.replace("</mujoco>", f"{extra}\n</mujoco>", 1)


def test_a_floating_base_written_as_joints_retargets_as_a_free_joint(tmp_path, humanoids, motion):
    """Three slides and three hinges (loco-mujoco's Talos, Atlas) or three slides and a ball
    (humanoid-gym's XBot-L) on the root body are a floating base: read as one free joint, the
    robot retargets exactly as the file written with ``<freejoint/>`` does; a keyframe's root
    pose is carried over. A bare-joint body beside the robot (Unitree's g1_23dof.xml keeps six
    spare joints on massless bodies 20 m up) is dropped. Three joints of a planar walker are
    no floating base: the one-line error stays."""
    plain = humanoids["plain"].read_text()
    slides = "".join(
        f'<joint name="root_{a}" type="slide" axis="{v}"/>'
        for a, v in zip("xyz", ("1 0 0", "0 1 0", "0 0 1"), strict=True)
    )
    hinges = "".join(
        f'<joint name="root_{a}" axis="{v}"/>'
        for a, v in zip(("yaw", "pitch", "roll"), ("0 0 1", "0 1 0", "1 0 0"), strict=True)
    )
    files = {
        "hinges": _root_joints(plain, slides + hinges),
        # ...on a root body without a name (the edits name it; the file's own qpos finds it)
        "unnamed": _root_joints(plain, slides + hinges).replace('<body name="root" ', "<body ", 1),
        "ball": _root_joints(plain, slides + '<joint name="root_ball" type="ball"/>'),
        "spare": plain.replace(
            "</worldbody>",
            '<body name="spare" pos="0 0 20"><inertial pos="0 0 0" mass="1e-3" diaginertia="1 1 1"/>'
            '<joint name="spare_joint"/></body></worldbody><actuator><motor joint="spare_joint"/></actuator>',
            1,
        ),
    }
    reference = compile_robot(humanoids["plain"])
    joint_names = [reference.joint(j).name for j in range(1, reference.njnt)]
    src = tmp_path / "clip.npy"
    np.save(src, motion.joints[:40])
    done = cli("retarget", src, "--robot", humanoids["plain"], "--fps", 30, "--out", tmp_path / "plain")
    assert done.returncode == 0, done.stderr
    with np.load(tmp_path / "plain.npz") as data:
        expected = data["qpos"]
    for name, text in files.items():
        path = tmp_path / f"{name}.xml"
        path.write_text(text)
        model = compile_robot(path)
        assert model.nq == reference.nq and model.nu == 0, (name, model.nq, model.nu)
        assert [model.joint(j).name for j in range(1, model.njnt)] == joint_names, name
        done = cli("retarget", src, "--robot", path, "--fps", 30, "--out", tmp_path / name)
        assert done.returncode == 0, done.stderr
        with np.load(tmp_path / f"{name}.npz") as data:
            np.testing.assert_allclose(data["qpos_floating"], expected, atol=1e-9, err_msg=name)
            in_file = data["qpos"]
        # ...and "qpos" is the file's own: set into the file as written, every body is where
        # the free joint's rows put it (the root joints solved, the spare joint at rest).
        _same_bodies(mujoco.MjModel.from_xml_string(text), in_file, reference, expected, name)
        checked = validate(tmp_path / f"{name}.npz", path)  # reads the rows it checks against
        assert checked.returncode in (0, 1) and not checked.stderr.strip(), (name, checked.stderr)
    # A keyframe's root joints become the free joint's pose: 10, 20, -30 cm and 90 degrees of yaw.
    key = np.zeros(reference.nq - 7 + 6)
    key[:4] = [0.1, 0.2, -0.3, np.pi / 2]
    key[6] = 0.25  # the first joint below the root keeps its value
    keyed = tmp_path / "keyed.xml"
    keyed.write_text(
        files["hinges"].replace(
            "</mujoco>", f'<keyframe><key qpos="{" ".join(map(str, key))}"/></keyframe></mujoco>'
        )
    )
    qpos = compile_robot(keyed).key_qpos[0]
    np.testing.assert_allclose(qpos[:3], reference.qpos0[:3] + [0.1, 0.2, -0.3], atol=1e-9)
    np.testing.assert_allclose(np.abs(qpos[3:7]), [np.sqrt(0.5), 0, 0, np.sqrt(0.5)], atol=1e-9)
    assert qpos[7] == 0.25 and not qpos[8:].any()
    planar = tmp_path / "planar.xml"
    planar.write_text(
        plain.replace(
            '<freejoint name="root"/>',
            '<joint name="root_x" type="slide" axis="1 0 0"/><joint name="root_z" type="slide" axis="0 0 1"/>'
            '<joint name="root_pitch" axis="0 1 0"/>',
        )
    )
    done = cli("robots", "map", planar, "--out", tmp_path / "planar.json")
    assert (
        done.returncode == 2 and "no free joint" in done.stderr and len(done.stderr.strip().splitlines()) == 1
    )


def _same_bodies(
    model: mujoco.MjModel,
    qpos: np.ndarray,
    reference: mujoco.MjModel,
    expected: np.ndarray,
    name: str,
    skip: tuple[str, ...] = (),
) -> None:
    """Every body of ``reference`` at ``expected`` (T, its nq) but ``skip`` is where ``model``'s
    body of the same name is at ``qpos`` (T, its nq), to 1e-6 m and rad."""
    assert qpos.shape == (len(expected), model.nq), (name, qpos.shape)
    ours, theirs = mujoco.MjData(reference), mujoco.MjData(model)
    for q_ref, q in zip(expected, qpos, strict=True):
        ours.qpos[:], theirs.qpos[:] = q_ref, q
        mujoco.mj_kinematics(reference, ours)
        mujoco.mj_kinematics(model, theirs)
        names = {model.body(i).name for i in range(model.nbody)}
        for b in range(1, reference.nbody):
            if reference.body(b).name in skip or reference.body(b).name not in names:
                continue  # (a root written without a name: its children, placed by it, are compared)
            other = model.body(reference.body(b).name).id
            np.testing.assert_allclose(theirs.xpos[other], ours.xpos[b], atol=1e-6, err_msg=name)
            np.testing.assert_allclose(theirs.xmat[other], ours.xmat[b], atol=1e-6, err_msg=name)


def validate(trajectory: Path, robot: Path):
    """``controlmm validate`` of a retargeted trajectory on an empty floor."""
    return cli(
        "validate", trajectory, "--robot", robot, "--out", trajectory.with_suffix(".report.json"), "--no-plot"
    )


def _with_rods(text: str, tied: bool = True) -> str:
    """``text`` with a rod on a ball joint behind each thigh whose lower end a ``<connect>``
    pins to the shin (with ``tied``), as Digit's and Cassie's achilles rods; an exclude, a
    sensor on a site of the rod and a sensor on the knee."""
    for side in "lr":
        rod = (
            f'<body name="rod_{side}" pos="-0.07 0 -0.05"><joint name="rod_{side}" type="ball"/>'
            f'<geom type="capsule" fromto="0 0 0 0 0 -0.38" size="0.008"/>'
            f'<site name="rod_end_{side}" pos="0 0 -0.38"/></body>'
        )
        text = text.replace(f'<body name="shin_{side}"', f'{rod}<body name="shin_{side}"', 1)
    connect = "".join(f'<connect body1="rod_{s}" body2="shin_{s}" anchor="0 0 -0.38"/>' for s in "lr")
    sensors = '<framepos objtype="site" objname="rod_end_l"/><jointpos joint="knee_l"/>'
    extra = (f"<equality>{connect}</equality>" if tied else "") + (
        f'<contact><exclude body1="rod_l" body2="shin_l"/></contact><sensor>{sensors}</sensor>'
    )
    return text.replace("</mujoco>", f"{extra}\n</mujoco>", 1)


def test_the_rods_of_closed_chains_are_dropped(tmp_path, humanoids, motion):
    """Digit's and Cassie's legs close loops through passive rods on ball joints, pinned to
    another link by a ``<connect>``: the rods, their constraints, the exclude and the sensor
    naming them and their keyframe entries go, and the robot retargets exactly as the file
    without them does. A ball joint that closes no loop is still refused in one line."""
    plain = humanoids["plain"].read_text()
    reference = compile_robot(humanoids["plain"])
    rods = _with_rods(plain)
    model = mujoco.MjModel.from_xml_string(rods)
    assert model.nq == reference.nq + 8 and model.neq == 2 and model.nsensor == 2
    key = np.concatenate([model.qpos0[:7], np.zeros(model.nq - 7)])
    key[7:] = 0.1 * np.arange(1, model.nq - 6)
    path = tmp_path / "rods.xml"
    path.write_text(
        rods.replace("</mujoco>", f'<keyframe><key qpos="{" ".join(map(str, key))}"/></keyframe></mujoco>')
    )
    dropped = compile_robot(path)
    assert dropped.nq == reference.nq and dropped.neq == 0 and dropped.nsensor == 1
    assert [dropped.joint(j).name for j in range(dropped.njnt)] == [
        reference.joint(j).name for j in range(reference.njnt)
    ]
    rod_qpos = [model.jnt_qposadr[model.joint(f"rod_{s}").id] + np.arange(4) for s in "lr"]
    np.testing.assert_array_equal(dropped.key_qpos[0], np.delete(key, np.concatenate(rod_qpos)))
    src = tmp_path / "clip.npy"
    np.save(src, motion.joints[:40])
    for name in ("plain", "rods"):
        robot = humanoids["plain"] if name == "plain" else path
        done = cli("retarget", src, "--robot", robot, "--fps", 30, "--out", tmp_path / name)
        assert done.returncode == 0, done.stderr
    with np.load(tmp_path / "plain.npz") as a, np.load(tmp_path / "rods.npz") as b:
        np.testing.assert_allclose(b["qpos_floating"], a["qpos"], atol=1e-9)
        plain_qpos, in_file = a["qpos"], b["qpos"]
    # "qpos" is the file's own: its bodies where the plain robot's are, the rods turned towards
    # their pins as far as their length lets them (closer than left at rest).
    _same_bodies(model, in_file, reference, plain_qpos, "rods")
    data = mujoco.MjData(model)
    gaps = []
    for qpos in in_file:
        data.qpos[:] = qpos
        mujoco.mj_forward(model, data)
        closed = np.linalg.norm(data.efc_pos[data.efc_type == mujoco.mjtConstraint.mjCNSTR_EQUALITY])
        rods = np.delete(np.arange(model.nq), np.concatenate(rod_qpos))
        data.qpos[:] = model.qpos0
        data.qpos[rods] = qpos[rods]
        mujoco.mj_forward(model, data)
        at_rest = np.linalg.norm(data.efc_pos[data.efc_type == mujoco.mjtConstraint.mjCNSTR_EQUALITY])
        assert closed <= at_rest + 1e-9, (closed, at_rest)
        gaps.append((closed, at_rest))
    closed_mean, at_rest_mean = np.mean(gaps, axis=0)  # a rod of fixed length reaches a bent shin only so far
    assert closed_mean < 0.95 * at_rest_mean, (closed_mean, at_rest_mean)
    loose = tmp_path / "loose.xml"
    loose.write_text(_with_rods(plain, tied=False))
    done = cli("robots", "map", loose, "--out", tmp_path / "loose.json")
    err = done.stderr.strip()
    assert done.returncode == 2 and "joint 'rod_l' is a mjJNT_BALL" in err and len(err.splitlines()) == 1, err


def test_a_crank_turns_to_close_its_rods_loop_in_the_files_own_qpos(tmp_path, humanoids, motion):
    """A crank on the shin (one hinge) drives the foot through a rod (a ball joint whose end a
    ``<connect>`` pins to the heel), as LimX's HU_D03 drives its ankles: the rod is dropped for
    the solve and the crank held at rest there, but the NPZ's ``qpos`` is the file's own, the
    crank and rod turned so that the loop closes wherever the linkage reaches (ankle pitch
    within 0.45 rad here: on the negative side it reaches to between -0.45 and -0.5 rad, where
    the closest the loop can come is 1.5 mm), and the rest of the robot where the solve put
    it."""
    linkage = (
        '<body name="crank_l" pos="-0.06 0 -0.10"><joint name="crank_l" axis="0 1 0" range="-90 90"/>'
        '<geom type="capsule" fromto="0 0 0 -0.08 0 0" size="0.01" contype="0" conaffinity="0"/>'
        '<body name="rod_l" pos="-0.08 0 0"><joint name="rod_l" type="ball"/>'
        '<geom type="capsule" fromto="0 0 0 0 0 -0.28" size="0.006" contype="0" conaffinity="0"/>'
        "</body></body>"
    )
    foot = '<body name="foot_l" pos="0 0 -0.42">'
    text = humanoids["plain"].read_text().replace(foot, linkage + foot, 1)
    pin = '<equality><connect body1="rod_l" body2="foot_l" anchor="0 0 -0.28"/></equality>'
    path = tmp_path / "crank.xml"
    path.write_text(text.replace("</mujoco>", pin + "</mujoco>", 1))
    model = mujoco.MjModel.from_xml_path(str(path))
    traj = retarget_motion(Motion(joints=motion.joints[:80], fps=motion.fps), path, fps=30, metrics=False)
    traj.save(tmp_path / "crank")
    with np.load(tmp_path / "crank.npz") as data:
        in_file, solved = data["qpos"], data["qpos_floating"]
    np.testing.assert_array_equal(solved, traj.qpos)
    edited = traj.robot_model().model
    _same_bodies(model, in_file, edited, solved, "crank", skip=("crank_l",))  # the solve's crank is at rest
    crank = in_file[:, model.jnt_qposadr[model.joint("crank_l").id]]
    ankle = in_file[:, model.jnt_qposadr[model.joint("ankle_y_l").id]]
    data_ = mujoco.MjData(model)
    gaps = []
    for qpos in in_file:
        data_.qpos[:] = qpos
        mujoco.mj_forward(model, data_)
        gaps.append(np.linalg.norm(data_.efc_pos[data_.efc_type == mujoco.mjtConstraint.mjCNSTR_EQUALITY]))
    reach = np.abs(ankle) < 0.45
    assert reach.sum() > 40 and np.abs(ankle).max() > 0.3, ankle  # the ankle does pitch
    assert max(np.asarray(gaps)[reach]) < 1e-6
    assert np.ptp(crank) > 0.3  # the crank turned with the ankle


def test_joints_without_a_range_take_their_position_servos(tmp_path, humanoids, motion):
    """A file written for position control leaves the joints' ranges to its servos
    (``<position ctrlrange=...>`` on joints without ``range``, as Rhoban's Sigmaban): each such
    joint takes its servo's control range over its gear, in the file's angle unit; a joint
    with a range of its own keeps it, and a servo range that leaves out the rest pose is not
    taken. The retargeted motion stays within the servos' ranges."""
    reference = compile_robot(humanoids["plain"])
    spec = mujoco.MjSpec.from_string(humanoids["plain"].read_text())
    servos = {}
    for joint in spec.joints:
        if joint.type != mujoco.mjtJoint.mjJNT_HINGE:
            continue
        j = reference.joint(joint.name).id
        lo, hi = reference.jnt_range[j]
        gear = 2.0 if joint.name == "knee_l" else 1.0
        if joint.name == "spine_x":  # keeps its own range, whatever its servo's
            ctrl = (-3.0, 3.0)
        elif joint.name == "spine_y":  # a servo range without the rest pose: not taken
            ctrl = (0.1, 0.4)
            joint.limited, joint.range = mujoco.mjtLimited.mjLIMITED_FALSE, [0.0, 0.0]
        else:
            ctrl = (gear * lo, gear * hi)
            joint.limited, joint.range = mujoco.mjtLimited.mjLIMITED_AUTO, [0.0, 0.0]
        spec.add_actuator(
            trntype=mujoco.mjtTrn.mjTRN_JOINT,
            target=joint.name,
            gear=[gear, 0, 0, 0, 0, 0],
            ctrlrange=list(ctrl),
            ctrllimited=mujoco.mjtLimited.mjLIMITED_TRUE,
        ).set_to_position(kp=50.0)
        servos[joint.name] = (ctrl[0] / gear, ctrl[1] / gear)
    path = tmp_path / "servos.xml"
    path.write_text(spec.to_xml())
    raw = mujoco.MjModel.from_xml_path(str(path))
    assert int(raw.jnt_limited.sum()) == 1  # spine_x only, as written
    model = compile_robot(path)
    for name in servos:
        j = model.joint(name).id
        if name == "spine_y":
            assert not model.jnt_limited[j]
        else:
            assert model.jnt_limited[j]
            np.testing.assert_allclose(
                model.jnt_range[j], reference.jnt_range[reference.joint(name).id], rtol=1e-5, atol=1e-6
            )
    qpos = retarget_motion(motion, path, fps=30.0, metrics=False).qpos
    for name, (lo, hi) in servos.items():
        if name in ("spine_x", "spine_y"):
            continue
        q = qpos[:, model.jnt_qposadr[model.joint(name).id]]
        assert lo - 1e-6 <= q.min() and q.max() <= hi + 1e-6, (name, q.min(), q.max(), lo, hi)


def test_what_acts_on_or_reads_a_rod_goes_with_it_and_nothing_else(tmp_path, humanoids):
    """Dropping the rods also drops a tendon through a rod's site, the actuators pulling on it
    and on the site (the keyframe's controls keep the others'), and only the sensors on the
    rods' own elements: a kept tendon that shares a rod's name keeps its sensor. A rod pinned
    to the world closes no loop within the robot and stays (then refused as a ball joint)."""
    text = _with_rods(humanoids["plain"].read_text())
    extra = (
        '<tendon><spatial name="pull"><site site="rod_end_l"/><site site="hip_site_l"/>'
        '<site site="rod_end_r"/></spatial>'
        '<fixed name="rod_l"><joint joint="knee_l" coef="1"/></fixed></tendon>'
        '<actuator><motor name="on_tendon" tendon="pull"/><motor name="on_site" site="rod_end_l"/>'
        '<motor name="on_knee" joint="knee_r"/></actuator>'
        '<sensor><tendonpos name="kept" tendon="rod_l"/></sensor>'
        '<keyframe><key ctrl="1 2 3"/></keyframe>'
    )
    text = text.replace(
        '<body name="shin_l"', '<site name="hip_site_l" pos="0 0.05 0"/><body name="shin_l"', 1
    )
    path = tmp_path / "acted.xml"
    path.write_text(text.replace("</mujoco>", f"{extra}\n</mujoco>", 1))
    model = compile_robot(path)
    assert [model.actuator(a).name for a in range(model.nu)] == ["on_knee"]
    np.testing.assert_array_equal(model.key_ctrl[0], [3.0])
    assert [model.tendon(t).name for t in range(model.ntendon)] == ["rod_l"]
    assert "kept" in [model.sensor(i).name for i in range(model.nsensor)]
    pinned = tmp_path / "pinned.xml"
    pinned.write_text(
        _with_rods(humanoids["plain"].read_text(), tied=False).replace(
            "</mujoco>",
            '<equality><connect body1="rod_l" body2="world" anchor="0 0 -0.38"/></equality></mujoco>',
            1,
        )
    )
    spec = mujoco.MjSpec.from_file(str(pinned))
    assert drop_closed_chain_rods(spec) == []
