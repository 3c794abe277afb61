"""Robot MJCF files: from a robot argument to its MJCF, its MjSpec and its compiled model.

A robot argument (``--robot`` everywhere) is a packaged name (``g1``), the path of a humanoid
MJCF (``robot.xml``, mapped automatically: :mod:`retarget.automap`) or a mapping ``.json``
that names the MJCF. :func:`robot_mjcf_path` resolves any of them to the MJCF file,
:func:`load_robot_spec` loads it as a ``mujoco.MjSpec`` ready to be attached to a scene and
:func:`compile_robot` compiles it, with one-line errors for a missing or broken file.

Collision geometry: every consumer (the retargeter's feet and clearance terms, the scene's
collision checks) reads the geoms whose ``contype`` or ``conaffinity`` is set. Some MJCFs
declare none and collide through explicit ``<pair>`` elements of their scene file instead
(Menagerie's Apptronik Apollo). For those, :func:`declare_collisions` turns the geoms of
Menagerie's collision group (3) into colliders that touch the floor and obstacles but not
each other (``contype`` 1, ``conaffinity`` 0), and adds the robot-robot pairs that the
packaged robot's own scene declares (thighs, shins, arms against the pelvis). A scene file
given as the robot keeps its robot-robot pairs but not those naming its own floor
(:func:`drop_floor_pairs`).

Bodies whose collision geoms already overlap in the robot's rest pose (``qpos0``; for example
convex hulls of meshes around a knee and the ankle two links below it) are a property of the
model, not of a motion: :func:`exclude_rest_contacts` excludes those body pairs, as MuJoCo
excludes a parent and its child, so that the checks see the contacts a motion makes.
"""

from __future__ import annotations

import functools
from pathlib import Path

import mujoco
import numpy as np

from controlmm.errors import ControlMMError, InputFileError
from retarget.kinematics import check_joint_types
from retarget.mapping import load_mapping
from retarget.robots import is_packaged, robot_mjcf, robot_scene

COLLISION_GROUP = 3
"""Geom group of collision geoms in MuJoCo Menagerie models (visual geoms: groups 1-2)."""


def _resolve(robot: str | Path) -> tuple[Path, str | None]:
    """(MJCF path, packaged robot name or None) of a robot argument."""
    text = str(robot).strip()
    if text.lower().endswith(".xml"):
        path = Path(text).expanduser()
        if not path.is_file():
            raise InputFileError(f"robot MJCF '{text}' does not exist")
        return path.resolve(), None
    if text.lower().endswith(".json"):
        mapping = load_mapping(text)
        if mapping.robot.lower().endswith(".xml"):
            return Path(mapping.robot), None
        return robot_mjcf(mapping.robot), mapping.robot.lower()
    if not is_packaged(text):
        load_mapping(text)  # raises the one-line "unknown robot" error with the known names
    return robot_mjcf(text), text.lower()


def robot_mjcf_path(robot: str | Path) -> Path:
    """The MJCF file of a robot argument: packaged name, MJCF path or mapping ``.json``."""
    return _resolve(robot)[0]


def _one_line(exc: Exception) -> str:
    text = "; ".join(part.strip() for part in str(exc).splitlines() if part.strip())
    return text or type(exc).__name__


def ancestors(model: mujoco.MjModel, body: int) -> list[int]:
    """``body`` and its ancestors up to (without) the world body."""
    out = []
    while body > 0:
        out.append(body)
        body = int(model.body_parentid[body])
    return out


def free_root(model: mujoco.MjModel) -> int | None:
    """The body holding the model's floating base (a free joint on a child of the world), or None.

    With several, the one whose subtree holds the most joints (the robot, not a loose prop).
    """
    best, most = None, -1
    for j in range(model.njnt):
        body = int(model.jnt_bodyid[j])
        if model.jnt_type[j] != mujoco.mjtJoint.mjJNT_FREE or model.body_parentid[body] != 0:
            continue
        count = int(sum(model.body_rootid[model.jnt_bodyid[k]] == body for k in range(model.njnt)))
        if count > most:
            best, most = body, count
    return best


def read_robot_mjcf(path: str | Path) -> mujoco.MjSpec:
    """A robot MJCF file's ``mujoco.MjSpec`` with a floating base written as joints made a free
    joint (:func:`free_floating_base`) and bodies that only hold joints beside the robot
    removed (:func:`drop_placeholder_bodies`).

    Raises:
        InputFileError: the file does not parse.
    """
    try:
        spec = mujoco.MjSpec.from_file(str(path))
    except ValueError as exc:
        raise InputFileError(f"robot MJCF '{path}' does not load: {_one_line(exc)}") from None
    free_floating_base(spec)
    drop_placeholder_bodies(spec)
    return spec


def _six_dof(joints: list[mujoco.MjsJoint]) -> bool:
    """Whether a body's ``joints`` move it freely: three slides along independent axes and a
    ball, or three hinges whose consecutive axes are not parallel (Euler angles)."""
    kind = mujoco.mjtJoint
    slides = [np.asarray(j.axis, dtype=float) for j in joints if j.type == kind.mjJNT_SLIDE]
    hinges = [np.asarray(j.axis, dtype=float) for j in joints if j.type == kind.mjJNT_HINGE]
    balls = sum(j.type == kind.mjJNT_BALL for j in joints)
    if len(joints) != 6 - 2 * balls or len(slides) != 3 or (balls, len(hinges)) not in ((1, 0), (0, 3)):
        return False
    unit = [a / max(float(np.linalg.norm(a)), 1e-12) for a in slides + hinges]
    if abs(float(np.linalg.det(np.array(unit[:3])))) < 1e-3:
        return False
    return all(float(np.linalg.norm(np.cross(a, b))) > 1e-3 for a, b in zip(unit[3:], unit[4:], strict=False))


def _remove_joints(
    spec: mujoco.MjSpec, model: mujoco.MjModel, joints: list[int], root: int | None = None
) -> list[tuple[mujoco.MjsKey, np.ndarray, np.ndarray, np.ndarray]]:
    """Prepare the removal of ``joints`` (ids in ``model``, the spec compiled) from ``spec``:
    delete the actuators and sensors on them and empty the keyframes, returning each one's
    (key, qpos, qvel, ctrl) without those joints' entries; with ``root`` (a body id) its qpos
    starts with that body's world pose (x y z, w x y z) and its qvel with 6 zeros, the layout
    of the free joint that replaces ``joints``. The caller deletes the joints (or their
    bodies), then sets the keyframes (:func:`_set_keys`)."""
    names = {model.joint(j).name for j in joints}
    size = {int(mujoco.mjtJoint.mjJNT_BALL): (4, 3), int(mujoco.mjtJoint.mjJNT_FREE): (7, 6)}
    qdrop: list[int] = []
    vdrop: list[int] = []
    for j in joints:
        nq, nv = size.get(int(model.jnt_type[j]), (1, 1))
        qdrop.extend(range(model.jnt_qposadr[j], model.jnt_qposadr[j] + nq))
        vdrop.extend(range(model.jnt_dofadr[j], model.jnt_dofadr[j] + nv))
    on = [
        i
        for i, a in enumerate(spec.actuators)
        if a.trntype == mujoco.mjtTrn.mjTRN_JOINT and a.target in names
    ]
    data = mujoco.MjData(model)
    keys = []
    for key in spec.keys:
        qpos, qvel, ctrl = (np.asarray(x, dtype=float) for x in (key.qpos, key.qvel, key.ctrl))
        if len(qpos) == model.nq:
            kept = np.delete(qpos, qdrop)
            if root is not None:
                data.qpos[:] = qpos
                mujoco.mj_kinematics(model, data)
                kept = np.concatenate([data.xpos[root], data.xquat[root], kept])
            qpos = kept
        if len(qvel) == model.nv:
            qvel = np.concatenate([np.zeros(6 if root is not None else 0), np.delete(qvel, vdrop)])
        if len(ctrl) == model.nu:
            ctrl = np.delete(ctrl, on)
        keys.append((key, qpos, qvel, ctrl))
        key.qpos, key.qvel, key.ctrl = [], [], []
    for item in [spec.actuators[i] for i in on] + [
        x for x in spec.sensors if x.objtype == mujoco.mjtObj.mjOBJ_JOINT and x.objname in names
    ]:
        spec.delete(item)
    return keys


def _set_keys(keys: list[tuple[mujoco.MjsKey, np.ndarray, np.ndarray, np.ndarray]]) -> None:
    for key, qpos, qvel, ctrl in keys:
        key.qpos, key.qvel, key.ctrl = qpos, qvel, ctrl


def free_floating_base(spec: mujoco.MjSpec) -> str | None:
    """Write a floating base given as joints as one free joint named ``floating_base`` (in place).

    Some humanoid MJCFs move their root body with three slides and a ball (humanoid-gym's
    XBot-L) or three slides and three hinges (loco-mujoco's Talos and Atlas) instead of a
    ``<freejoint/>``. Where no body of the world has a free joint and exactly one has such
    joints (and only those), they are replaced by a free joint, the body placed where those
    joints put it in ``qpos0``; keyframes are converted (the root's pose from their joints,
    its velocity zero), actuators and sensors on the removed joints dropped. Trajectories
    then use the free joint's layout (position, quaternion w x y z, then the other joints).
    Returns the body's name, or None where nothing changed (a file that does not compile
    is left as it is: :func:`compile_robot` reports it).
    """
    bodies = list(spec.worldbody.bodies)
    if any(j.type == mujoco.mjtJoint.mjJNT_FREE for b in bodies for j in b.joints):
        return None
    roots = [b for b in bodies if _six_dof(list(b.joints))]
    if len(roots) != 1:
        return None
    body = roots[0]
    body.name = body.name or "floating_base_body"
    try:
        model = spec.compile()
    except ValueError:
        return None
    bid = model.body(body.name).id
    data = mujoco.MjData(model)
    mujoco.mj_kinematics(model, data)
    keys = _remove_joints(spec, model, [j for j in range(model.njnt) if int(model.jnt_bodyid[j]) == bid], bid)
    for joint in list(body.joints):
        spec.delete(joint)
    body.pos, body.quat = data.xpos[bid].copy(), data.xquat[bid].copy()
    body.add_freejoint(name="floating_base")
    _set_keys(keys)
    return body.name


def drop_placeholder_bodies(spec: mujoco.MjSpec) -> list[str]:
    """Delete the bodies of the world that hold joints but no geometry, beside a robot with a
    free joint (in place): Unitree's ``g1_23dof.xml`` keeps the 29-DoF G1's six missing waist
    and wrist joints on massless bodies 20 m above the world, so that its actuators keep the
    29-DoF layout; they move nothing of the robot. Their actuators, sensors and keyframe
    entries go with them. Returns their names."""
    bodies = list(spec.worldbody.bodies)
    if not any(j.type == mujoco.mjtJoint.mjJNT_FREE for b in bodies for j in b.joints):
        return []

    def tree(body: mujoco.MjsBody) -> list[mujoco.MjsBody]:
        return [body, *[d for c in body.bodies for d in tree(c)]]

    loose = [
        b
        for b in bodies
        if not any(j.type == mujoco.mjtJoint.mjJNT_FREE for j in b.joints)
        and any(len(list(d.joints)) for d in tree(b))
        and not any(len(list(d.geoms)) for d in tree(b))
    ]
    if not loose:
        return []
    try:
        model = spec.compile()
    except ValueError:
        return []
    ids = {model.body(d.name).id for b in loose for d in tree(b) if d.name}
    if len(ids) != sum(len(tree(b)) for b in loose):  # an unnamed body among them: leave them
        return []
    keys = _remove_joints(spec, model, [j for j in range(model.njnt) if int(model.jnt_bodyid[j]) in ids])
    names = [b.name for b in loose]
    for body in loose:
        spec.delete(body)
    _set_keys(keys)
    return names


def load_robot_spec(robot: str | Path) -> mujoco.MjSpec:
    """The robot's ``mujoco.MjSpec`` (its options, keyframes and names unchanged), colliders declared.

    Raises:
        ControlMMError: unknown robot, missing file, an MJCF that does not parse or compile.
    """
    path, packaged = _resolve(robot)
    spec = read_robot_mjcf(path)
    declare_collisions(spec, robot_scene(packaged) if packaged else None)
    drop_floor_pairs(spec)
    if packaged is None:  # the packaged robots have none (tests/test_robots_automap.py checks it)
        stat = path.stat()
        for name1, name2 in _rest_contacts(str(path), stat.st_mtime_ns, stat.st_size):
            spec.add_exclude(bodyname1=name1, bodyname2=name2)
    return spec


@functools.lru_cache(maxsize=16)
def _rest_contacts(path: str, mtime_ns: int, size: int) -> tuple[tuple[str, str], ...]:
    """The rest-contact body pairs of a robot MJCF file, once per file version and process."""
    spec = read_robot_mjcf(path)
    declare_collisions(spec)
    return tuple(exclude_rest_contacts(spec))


def exclude_rest_contacts(spec: mujoco.MjSpec) -> list[tuple[str, str]]:
    """Exclude the body pairs whose collision geoms overlap in the rest pose (in place).

    The spec is compiled and its contacts found in ``qpos0``; each pair of named bodies other
    than the world in contact with negative distance gets an ``<exclude>``. A spec that does
    not compile is left unchanged (:func:`compile_robot` reports it). Returns the pairs.
    """
    try:
        model = spec.compile()
    except ValueError:
        return []
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    pairs: set[tuple[str, str]] = set()
    for contact in data.contact[: data.ncon]:
        if contact.dist >= 0:
            continue
        b1, b2 = (int(model.geom_bodyid[g]) for g in (contact.geom1, contact.geom2))
        names = (model.body(b1).name, model.body(b2).name)
        if b1 and b2 and b1 != b2 and all(names):
            pairs.add((min(names), max(names)))
    for name1, name2 in sorted(pairs):
        spec.add_exclude(bodyname1=name1, bodyname2=name2)
    return sorted(pairs)


def drop_floor_pairs(spec: mujoco.MjSpec) -> int:
    """Delete the ``<pair>`` elements that name a geom of the world body (a scene file's floor,
    passed as the robot: Menagerie's ``scene.xml`` of the Apollo, the G1's ``scene_mjx.xml``).
    Only the robot's body tree is attached to a scene, whose floor the retargeter and the
    checks find themselves; an explicit pair (no margin) would hide the feet's contacts with
    it from the checks' near-contact sensing (``controlmm validate`` then reads a standing
    robot as floating). Returns how many were deleted."""
    world = {g.name for g in spec.worldbody.geoms if g.name}
    floor = [p for p in spec.pairs if p.geomname1 in world or p.geomname2 in world]
    for pair in floor:
        spec.delete(pair)
    return len(floor)


def declare_collisions(spec: mujoco.MjSpec, scene: Path | None = None) -> bool:
    """Give an MJCF without colliders its collision group's geoms as colliders (in place).

    Only when no geom of the robot (the world body's own, a scene's floor, do not count) has
    ``contype``/``conaffinity`` set: the geoms of group ``COLLISION_GROUP`` get ``contype`` 1
    and ``conaffinity`` 0 (they touch the floor and the obstacles, whose ``conaffinity`` is
    set, but not each other), and the robot-robot ``<pair>`` elements of ``scene`` (the robot's
    own scene MJCF) are added. Returns whether anything changed.
    """
    geoms = [g for g in spec.geoms if g.parent != spec.worldbody]
    if any(g.contype or g.conaffinity for g in geoms) or not geoms:
        return False
    group = [g for g in geoms if g.group == COLLISION_GROUP]
    if not group:
        return False
    for g in group:
        g.contype, g.conaffinity = 1, 0
    if scene is not None and scene.is_file():
        names = {g.name for g in group if g.name}
        have = {(p.geomname1, p.geomname2) for p in spec.pairs}
        try:
            scene_spec = mujoco.MjSpec.from_file(str(scene))
        except ValueError:  # the scene is optional: without its pairs the robot has no self-collision
            return True
        for pair in scene_spec.pairs:
            key = (pair.geomname1, pair.geomname2)
            if key[0] in names and key[1] in names and key not in have:
                spec.add_pair(geomname1=key[0], geomname2=key[1], condim=pair.condim)
    return True


def compile_robot(robot: str | Path) -> mujoco.MjModel:
    """Compile a robot argument's MJCF (colliders declared) with one-line errors.

    Raises:
        ControlMMError: unknown robot, a missing file, an MJCF that does not compile, a model
            without a free joint on a child of the world body (a floating base), or with a joint
            below it that is neither a hinge nor a slide.
    """
    spec = load_robot_spec(robot)
    path = robot_mjcf_path(robot)
    try:
        model = spec.compile()
    except ValueError as exc:
        raise InputFileError(f"robot MJCF '{path}' does not compile: {_one_line(exc)}") from None
    root = free_root(model)
    if root is None:
        raise ControlMMError(
            f"robot MJCF '{path.name}' has no free joint on a body of the world: a humanoid needs a "
            "floating base (<freejoint/> in its root body, or three slides and a ball or three hinges)"
        )
    free = [
        model.body(int(model.jnt_bodyid[j])).name
        for j in range(model.njnt)
        if model.jnt_type[j] == mujoco.mjtJoint.mjJNT_FREE
    ]
    if len(free) > 1:
        raise ControlMMError(
            f"robot MJCF '{path.name}' has {len(free)} free joints (on {', '.join(free)}): a retargeting "
            "robot has one floating base; pass the robot's own MJCF, not a scene with loose bodies"
        )
    check_joint_types(model, root)
    return model
