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
packaged robot's own scene declares (thighs, shins, arms against the pelvis). Geoms that a
file leaves at ``contype`` and ``conaffinity`` 0 but names in its own ``<pair>`` elements
(PNDbotics' Adam SP: its feet meet the floor through pairs alone) are colliders the same way.
A scene file given as the robot keeps its robot-robot pairs but not those naming its own floor
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

from controlmm.errors import ControlMMError, InputFileError
from retarget.kinematics import check_joint_types
from retarget.mapping import load_mapping
from retarget.robots import is_packaged, robot_mjcf, robot_scene
from retarget.spec_edits import (
    drop_closed_chain_rods,
    drop_placeholder_bodies,
    free_floating_base,
    servo_ranges,
)

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


def jointed_link(model: mujoco.MjModel, body: int) -> int:
    """The link ``body`` belongs to: ``body`` or, through bodies without joints (welded to their
    parents: a foot's cleats or sole plates), the nearest ancestor with one (the world body 0
    when none has)."""
    while body > 0 and model.body_jntnum[body] == 0:
        body = int(model.body_parentid[body])
    return body


def welded_below(model: mujoco.MjModel, body: int) -> list[int]:
    """The bodies below ``body`` joined to it without a joint (directly or through such bodies)."""
    out: list[int] = []
    for b in range(body + 1, model.nbody):  # children have larger ids than their parents
        parent = int(model.body_parentid[b])
        if model.body_jntnum[b] == 0 and (parent == body or parent in out):
            out.append(b)
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
    joint, bodies that only hold joints beside the robot removed, the passive rods of closed
    chains removed and joints without a range given their position servo's
    (:mod:`retarget.spec_edits`).

    Raises:
        InputFileError: the file does not parse, or does not compile where an edit compiles it
            (MuJoCo raises a failed compile's error again at the spec's next use).
    """
    try:
        spec = mujoco.MjSpec.from_file(str(path))
    except ValueError as exc:
        raise InputFileError(f"robot MJCF '{path}' does not load: {_one_line(exc)}") from None
    try:
        free_floating_base(spec)
        drop_placeholder_bodies(spec)
        drop_closed_chain_rods(spec)
        servo_ranges(spec)
    except ValueError as exc:
        raise InputFileError(f"robot MJCF '{path}' does not compile: {_one_line(exc)}") from None
    return spec


def load_robot_spec(robot: str | Path) -> mujoco.MjSpec:
    """The robot's ``mujoco.MjSpec`` (its options, keyframes and names unchanged), colliders declared.

    Raises:
        ControlMMError: unknown robot, missing file, an MJCF that does not parse or compile.
    """
    path, packaged = _resolve(robot)
    spec = read_robot_mjcf(path)
    declare_collisions(spec, robot_scene(packaged) if packaged else None)
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
    passed as the robot: Menagerie's ``scene.xml`` of the Apollo, the G1's ``scene_mjx.xml``)
    or a geom the file does not have (the floor of the scene file that includes it: PNDbotics'
    ``adam_sp.xml``, which does not compile alone). Only the robot's body tree is attached to a
    scene, whose floor the retargeter and the checks find themselves; an explicit pair (no
    margin) would hide the feet's contacts with it from the checks' near-contact sensing
    (``controlmm validate`` then reads a standing robot as floating). Returns how many were
    deleted."""
    world = {g.name for g in spec.worldbody.geoms if g.name}
    robot = {g.name for g in spec.geoms if g.name} - world
    floor = [p for p in spec.pairs if not {p.geomname1, p.geomname2} <= robot]
    for pair in floor:
        spec.delete(pair)
    return len(floor)


def declare_collisions(spec: mujoco.MjSpec, scene: Path | None = None) -> bool:
    """Give an MJCF's colliders that it leaves to explicit ``<pair>`` elements their
    ``contype`` (in place).

    Where no geom of the robot (the world body's own, a scene's floor, do not count) has
    ``contype``/``conaffinity`` set, the geoms of group ``COLLISION_GROUP`` get ``contype`` 1
    and ``conaffinity`` 0 (they touch the floor and the obstacles, whose ``conaffinity`` is
    set, but not each other), and the robot-robot ``<pair>`` elements of ``scene`` (the robot's
    own scene MJCF) are added. Then any geom that the file's own ``<pair>`` elements name but
    whose ``contype`` and ``conaffinity`` are 0 gets the same (PNDbotics' Adam SP sets both to 0
    for every geom but its pelvis, its feet colliding with the floor through pairs alone).
    Last, the pairs naming a geom that is not the robot's go (:func:`drop_floor_pairs`: read
    first, they named colliders). Returns whether anything changed.
    """
    geoms = [g for g in spec.geoms if g.parent != spec.worldbody]
    if not geoms:
        return drop_floor_pairs(spec) > 0
    changed = False
    if not any(g.contype or g.conaffinity for g in geoms):
        group = [g for g in geoms if g.group == COLLISION_GROUP]
        for g in group:
            g.contype, g.conaffinity = 1, 0
        changed = bool(group)
        if group and scene is not None and scene.is_file():
            _add_scene_pairs(spec, scene, {g.name for g in group if g.name})
    paired = {name for p in spec.pairs for name in (p.geomname1, p.geomname2)}
    for g in geoms:
        if g.name and g.name in paired and not (g.contype or g.conaffinity):
            g.contype, g.conaffinity = 1, 0
            changed = True
    return drop_floor_pairs(spec) > 0 or changed


def _add_scene_pairs(spec: mujoco.MjSpec, scene: Path, names: set[str]) -> None:
    """Add the robot-robot ``<pair>`` elements of the robot's own ``scene`` MJCF between geoms
    ``names`` (the scene is optional: without its pairs the robot has no self-collision)."""
    have = {(p.geomname1, p.geomname2) for p in spec.pairs}
    try:
        scene_spec = mujoco.MjSpec.from_file(str(scene))
    except ValueError:
        return
    for pair in scene_spec.pairs:
        key = (pair.geomname1, pair.geomname2)
        if key[0] in names and key[1] in names and key not in have:
            spec.add_pair(geomname1=key[0], geomname2=key[1], condim=pair.condim)


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
