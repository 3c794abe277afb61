"""Edits of a robot's ``mujoco.MjSpec`` that make a humanoid MJCF written otherwise retargetable.

:func:`retarget.robot_files.read_robot_mjcf` applies them to every robot file, in this order:

- :func:`free_floating_base`: a floating base written as three slides and a ball or three
  hinges becomes one free joint;
- :func:`drop_placeholder_bodies`: bodies beside the robot that hold joints but no geometry go;
- :func:`drop_closed_chain_rods`: the passive rods of closed chains (a ball joint at one end,
  an equality constraint at the other) go with their constraints;
- :func:`servo_ranges`: a joint without a range that a position servo drives takes the
  servo's control range.

Each keeps the file's keyframes, actuators and sensors consistent with the joints it removes;
trajectories then use the edited model's ``qpos`` layout (the free joint's position and
quaternion w x y z, then the remaining joints in MJCF order; the JSON beside each trajectory
names them).
"""

from __future__ import annotations

import mujoco
import numpy as np


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


def joint_addresses(model: mujoco.MjModel, j: int) -> tuple[range, range]:
    """The qpos and the dof addresses of joint ``j`` (a free joint 7 and 6, a ball 4 and 3,
    a hinge or slide 1 each)."""
    size = {int(mujoco.mjtJoint.mjJNT_BALL): (4, 3), int(mujoco.mjtJoint.mjJNT_FREE): (7, 6)}
    nq, nv = size.get(int(model.jnt_type[j]), (1, 1))
    qpos, dof = int(model.jnt_qposadr[j]), int(model.jnt_dofadr[j])
    return range(qpos, qpos + nq), range(dof, dof + nv)


def _remove_joints(
    spec: mujoco.MjSpec,
    model: mujoco.MjModel,
    joints: list[int],
    root: int | None = None,
    actuators: tuple[int, ...] = (),
) -> list[tuple[mujoco.MjsKey, np.ndarray, np.ndarray, np.ndarray]]:
    """Prepare the removal of ``joints`` (ids in ``model``, the spec compiled) from ``spec``:
    delete the actuators and sensors on them (and the ``actuators`` given, ids in ``model``)
    and empty the keyframes, returning each one's (key, qpos, qvel, ctrl) without those
    joints' and actuators' entries; with ``root`` (a body id) its qpos
    starts with that body's world pose (x y z, w x y z) and its qvel with 6 zeros, the layout
    of the free joint that replaces ``joints``. The caller deletes the joints (or their
    bodies), then sets the keyframes (:func:`_set_keys`)."""
    names = {model.joint(j).name for j in joints}
    qdrop: list[int] = []
    vdrop: list[int] = []
    for j in joints:
        q_at, v_at = joint_addresses(model, j)
        qdrop.extend(q_at)
        vdrop.extend(v_at)
    on = sorted(
        {
            i
            for i, a in enumerate(spec.actuators)
            if a.trntype == mujoco.mjtTrn.mjTRN_JOINT and a.target in names
        }
        | set(actuators)
    )
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
    then use the free joint's layout (position, quaternion w x y z, then the other joints);
    their NPZ's ``qpos`` is put back in the file's own (:mod:`retarget.file_layout`).
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


def _subtree(body: mujoco.MjsBody) -> list[mujoco.MjsBody]:
    """``body`` and every body below it."""
    return [body, *[d for c in body.bodies for d in _subtree(c)]]


def drop_placeholder_bodies(spec: mujoco.MjSpec) -> list[str]:
    """Delete the bodies of the world that hold joints but no geometry, beside a robot with a
    free joint (in place): Unitree's ``g1_23dof.xml`` keeps the 29-DoF G1's six missing waist
    and wrist joints on massless bodies 20 m above the world, so that its actuators keep the
    29-DoF layout; they move nothing of the robot. Their actuators, sensors and keyframe
    entries go with them. Returns their names."""
    bodies = list(spec.worldbody.bodies)
    if not any(j.type == mujoco.mjtJoint.mjJNT_FREE for b in bodies for j in b.joints):
        return []

    loose = [
        b
        for b in bodies
        if not any(j.type == mujoco.mjtJoint.mjJNT_FREE for j in b.joints)
        and any(len(list(d.joints)) for d in _subtree(b))
        and not any(len(list(d.geoms)) for d in _subtree(b))
    ]
    if not loose:
        return []
    try:
        model = spec.compile()
    except ValueError:
        return []
    ids = {model.body(d.name).id for b in loose for d in _subtree(b) if d.name}
    if len(ids) != sum(len(_subtree(b)) for b in loose):  # an unnamed body among them: leave them
        return []
    keys = _remove_joints(spec, model, [j for j in range(model.njnt) if int(model.jnt_bodyid[j]) in ids])
    names = [b.name for b in loose]
    for body in loose:
        spec.delete(body)
    _set_keys(keys)
    return names


def _equality_bodies(spec: mujoco.MjSpec, eq: mujoco.MjsEquality) -> set[str]:
    """The names of the bodies an equality constraint ties: a ``<connect>`` or ``<weld>``
    through bodies or sites, a ``<joint>`` coupling through its joints' bodies (a tendon
    coupling ties none)."""
    names = [n for n in (eq.name1, eq.name2) if n]
    if eq.type == mujoco.mjtEq.mjEQ_JOINT:
        elements = [spec.joint(n) for n in names]
    elif eq.type in (mujoco.mjtEq.mjEQ_CONNECT, mujoco.mjtEq.mjEQ_WELD):
        if eq.objtype != mujoco.mjtObj.mjOBJ_SITE:
            return set(names)
        elements = [spec.site(n) for n in names]
    else:
        return set()
    return {e.parent.name for e in elements if e is not None}


def drop_closed_chain_rods(spec: mujoco.MjSpec) -> list[str]:
    """Delete the passive rods of the robot's closed kinematic chains (in place).

    Digit's and Cassie's legs close loops through rods: a body hanging on a ball joint whose
    far end an equality constraint (``<connect>``) pins to another link (Digit's achilles and
    toe rods, Cassie's achilles rods). The retargeter moves open chains of hinges and slides:
    such a rod's orientation is not a degree of freedom of the motion but follows from the
    links it joins, and left at rest it would sweep through the shin. Each body below the
    floating base without bodies below it, with a ball joint and an equality tying it to
    another body, is deleted with those equalities, the ``<exclude>`` and ``<pair>`` elements
    and sensors that name it, and its joints' actuators and keyframe entries; the rods' geometry
    then no longer takes part in the collision checks. A ball joint that closes no loop (a ball
    shoulder) stays and is refused by :func:`retarget.kinematics.check_joint_types`. Returns
    the deleted bodies' names.
    """
    roots = [b for b in spec.worldbody.bodies if any(j.type == mujoco.mjtJoint.mjJNT_FREE for j in b.joints)]
    if len(roots) != 1:
        return []
    # A rod pinned to the world closes no loop within the robot.
    ties = [(eq, _equality_bodies(spec, eq) - {"world"}) for eq in spec.equalities]
    rods = [
        body
        for body in _subtree(roots[0])[1:]
        if body.name
        and not list(body.bodies)
        and any(j.type == mujoco.mjtJoint.mjJNT_BALL for j in body.joints)
        and any(body.name in tied and len(tied) > 1 for _, tied in ties)
    ]
    if not rods:
        return []
    try:
        model = spec.compile()
    except ValueError:
        return []
    inside = {b.name for b in rods}
    ids = {model.body(name).id for name in inside}
    joints = [j for j in range(model.njnt) if int(model.jnt_bodyid[j]) in ids]
    site_ids = [s for s in range(model.nsite) if int(model.site_bodyid[s]) in ids]
    geom_ids = [g for g in range(model.ngeom) if int(model.geom_bodyid[g]) in ids]
    # Tendons through the rods (a site or geom on their path, a rod joint in their sum) go
    # too, and so do the actuators that pull on them or on a rod's site.
    through = {(int(mujoco.mjtWrap.mjWRAP_JOINT), j) for j in joints}
    through |= {(int(mujoco.mjtWrap.mjWRAP_SITE), s) for s in site_ids}
    through |= {(int(mujoco.mjtWrap.mjWRAP_SPHERE), g) for g in geom_ids}
    through |= {(int(mujoco.mjtWrap.mjWRAP_CYLINDER), g) for g in geom_ids}
    tendons = [
        t
        for t in range(model.ntendon)
        if any(
            (int(model.wrap_type[w]), int(model.wrap_objid[w])) in through
            for w in range(model.tendon_adr[t], model.tendon_adr[t] + model.tendon_num[t])
        )
    ]
    pulled = {(int(mujoco.mjtTrn.mjTRN_SITE), s) for s in site_ids} | {
        (int(mujoco.mjtTrn.mjTRN_TENDON), t) for t in tendons
    }
    actuators = tuple(
        a
        for a in range(model.nu)
        if (int(model.actuator_trntype[a]), int(model.actuator_trnid[a, 0])) in pulled
    )
    keys = _remove_joints(spec, model, joints, actuators=actuators)
    obj = mujoco.mjtObj
    named = {
        obj.mjOBJ_BODY: inside,
        obj.mjOBJ_XBODY: inside,
        obj.mjOBJ_SITE: {model.site(s).name for s in site_ids} - {""},
        obj.mjOBJ_GEOM: {model.geom(g).name for g in geom_ids} - {""},
        obj.mjOBJ_TENDON: {model.tendon(t).name for t in tendons} - {""},
    }

    def on_rod(kind: mujoco.mjtObj, name: str) -> bool:
        return name in named.get(kind, set())

    doomed: list[object] = [eq for eq, tied in ties if tied & inside]
    doomed += [x for x in spec.excludes if x.bodyname1 in inside or x.bodyname2 in inside]
    doomed += [
        p for p in spec.pairs if on_rod(obj.mjOBJ_GEOM, p.geomname1) or on_rod(obj.mjOBJ_GEOM, p.geomname2)
    ]
    doomed += [x for x in spec.sensors if on_rod(x.objtype, x.objname) or on_rod(x.reftype, x.refname)]
    doomed += [spec.tendons[t] for t in tendons]  # the spec's tendons in the model's order
    for item in doomed + rods:
        spec.delete(item)
    _set_keys(keys)
    return [b.name for b in rods]


def _position_servo(model: mujoco.MjModel, a: int) -> bool:
    """Whether actuator ``a`` is a position servo on one joint (``<position>``: force
    kp * (ctrl - gear * q) - kv * velocity), so that its control is the joint's target."""
    return bool(
        int(model.actuator_trntype[a]) == int(mujoco.mjtTrn.mjTRN_JOINT)
        and int(model.actuator_gaintype[a]) == int(mujoco.mjtGain.mjGAIN_FIXED)
        and int(model.actuator_biastype[a]) == int(mujoco.mjtBias.mjBIAS_AFFINE)
        and model.actuator_gainprm[a, 0] > 0
        and model.actuator_biasprm[a, 0] == 0
        and np.isclose(model.actuator_biasprm[a, 1], -model.actuator_gainprm[a, 0])
    )


def servo_ranges(spec: mujoco.MjSpec) -> list[str]:
    """Give each hinge or slide joint without a range the control range of the position servo
    that drives it (in place).

    Files written for position control (Rhoban's Sigmaban: ``<position ctrlrange=...>`` on
    joints that have no ``range``) keep the joint's reach in the servo: a pose outside the
    control range cannot be commanded, so the retargeter and the checks treat it as the
    joint's range (``ctrlrange`` divided by the gear; the union where several servos drive
    one joint). Joints with a range of their own keep it, and so do those whose rest position
    lies outside the servo's range. Returns the joints given a range.
    """
    kind, limited = mujoco.mjtJoint, mujoco.mjtLimited
    free = {
        j.name
        for j in spec.joints
        if j.type in (kind.mjJNT_HINGE, kind.mjJNT_SLIDE)
        and (
            j.limited == limited.mjLIMITED_FALSE
            or (j.limited == limited.mjLIMITED_AUTO and j.range[0] >= j.range[1])
        )
    }
    if not any(a.trntype == mujoco.mjtTrn.mjTRN_JOINT and a.target in free for a in spec.actuators):
        return []  # nothing to do: no compile (a large robot's takes seconds)
    try:
        model = spec.compile()
    except ValueError:
        return []  # reported by retarget.robot_files.compile_robot
    found: dict[str, tuple[float, float]] = {}
    moving = (int(mujoco.mjtJoint.mjJNT_HINGE), int(mujoco.mjtJoint.mjJNT_SLIDE))
    for a in range(model.nu):
        j = int(model.actuator_trnid[a, 0])
        gear = float(model.actuator_gear[a, 0])
        if not (_position_servo(model, a) and model.actuator_ctrllimited[a] and gear != 0.0):
            continue
        name = model.joint(j).name
        if model.jnt_limited[j] or int(model.jnt_type[j]) not in moving or not name:
            continue
        lo, hi = sorted(float(c) / gear for c in model.actuator_ctrlrange[a])
        if lo <= float(model.qpos0[model.jnt_qposadr[j]]) <= hi and hi > lo:  # the rest pose within
            old = found.get(name, (lo, hi))
            found[name] = (min(old[0], lo), max(old[1], hi))
    for name, (lo, hi) in found.items():
        joint = spec.joint(name)
        scale = 180.0 / np.pi if spec.compiler.degree and joint.type == mujoco.mjtJoint.mjJNT_HINGE else 1.0
        joint.range = [lo * scale, hi * scale]
        joint.limited = mujoco.mjtLimited.mjLIMITED_TRUE
    return sorted(found)
