"""The models of the physics check: the executed one (saved as one MJCF file) and the planning copy.

*Executed model.* The robot + scene is written as one self-contained MJCF string by MuJoCo
(``MjSpec.to_xml``): every mesh file is replaced by its vertices and faces, so the file needs
nothing beside it. The simulation runs on the model compiled **from that string**, so loading
``physics_model.xml`` and stepping it with the recorded controls reproduces the recorded states
exactly (same MuJoCo version). Vertices are taken from the compiled model and moved back into
the mesh file's frame (``mesh_pos``, ``mesh_quat``), so that the compiler derives the same mesh
frames and geom poses as for the original files.

Both carry the cost's sensors (centre of mass, its velocity, the feet): they read the state
and change nothing of the dynamics.

*Planning model.* The rollouts use a copy of the executed model with a longer timestep
(``plan_substeps`` x the model's), motor actuators turned into the position servos the
controller emulates (:mod:`sim.physics.actuation`), no dry friction in the joints and tendons
(``frictionloss``: one constraint row per joint that made each rollout step about 1.4x as
expensive on G1, for 0.3 N m against servo torques of tens of N m and their damping) and no
collisions between links that its joints keep apart anyway. It is the compiled executed model with those
fields changed (no second compile of the meshes).
"""

from __future__ import annotations

import copy

import mujoco
import numpy as np

from controlmm.errors import ControlMMError

PLAN_SENSOR_PREFIX = "controlmm_plan_"
"""Names of the sensors the planning model adds."""


def inline_meshes(spec: mujoco.MjSpec, model: mujoco.MjModel) -> mujoco.MjSpec:
    """A copy of ``spec`` whose meshes hold their vertices and faces instead of file names.

    ``model`` is ``spec`` compiled (it gives the decoded, scaled vertices). Textures that come
    from image files are dropped (visual only); their materials keep their colours.
    """
    out = spec.copy()
    for mesh in out.meshes:
        mid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_MESH, mesh.name)
        if mid < 0:
            raise ControlMMError(f"mesh '{mesh.name}' is not in the compiled model")
        va, vn = int(model.mesh_vertadr[mid]), int(model.mesh_vertnum[mid])
        fa, fn = int(model.mesh_faceadr[mid]), int(model.mesh_facenum[mid])
        rot = np.zeros(9)
        mujoco.mju_quat2Mat(rot, np.asarray(model.mesh_quat[mid], dtype=np.float64))
        verts = np.asarray(model.mesh_vert[va : va + vn], dtype=np.float64)
        verts = verts @ rot.reshape(3, 3).T + model.mesh_pos[mid]  # back into the file's frame
        mesh.file = ""
        mesh.uservert = verts.ravel()
        mesh.userface = np.asarray(model.mesh_face[fa : fa + fn]).ravel()
        mesh.scale = [1.0, 1.0, 1.0]
    for texture in list(out.textures):
        if texture.file or any(texture.cubefiles):
            for material in out.materials:
                material.textures = ["" if t == texture.name else t for t in material.textures]
            out.delete(texture)
    return out


def compile_xml(xml: str) -> mujoco.MjModel:
    """Compile an MJCF string (one-line error when MuJoCo refuses it)."""
    try:
        return mujoco.MjModel.from_xml_string(xml)
    except ValueError as exc:
        raise ControlMMError(
            f"MuJoCo cannot compile the physics model: {' '.join(str(exc).split())}"
        ) from None


def check_same_layout(original: mujoco.MjModel, copy: mujoco.MjModel) -> None:
    """Raise when the saved model's state layout differs from the original's."""
    for name in ("nq", "nv", "nu", "na", "nbody", "njnt", "ngeom", "nmocap"):
        a, b = int(getattr(original, name)), int(getattr(copy, name))
        if a != b:
            raise ControlMMError(f"the saved physics model has {name}={b}, the scene model {a}")


def add_plan_sensors(spec: mujoco.MjSpec, root_body: str, foot_bodies: list[str]) -> None:
    """Append the cost's sensors to ``spec`` (in place).

    In this order, after the model's own: centre of mass of the robot (subtree of the root
    body, 3), its linear velocity (3), the world position of each foot body (3 each). Sensors
    only read the state: the executed model carries them too (so that the planning copy is a
    copy of it, :func:`planning_model`), and they change none of its dynamics.
    """
    spec.add_sensor(
        name=PLAN_SENSOR_PREFIX + "com",
        type=mujoco.mjtSensor.mjSENS_SUBTREECOM,
        objtype=mujoco.mjtObj.mjOBJ_BODY,
        objname=root_body,
    )
    spec.add_sensor(
        name=PLAN_SENSOR_PREFIX + "com_vel",
        type=mujoco.mjtSensor.mjSENS_SUBTREELINVEL,
        objtype=mujoco.mjtObj.mjOBJ_BODY,
        objname=root_body,
    )
    for foot in foot_bodies:
        spec.add_sensor(
            name=PLAN_SENSOR_PREFIX + "foot_" + foot,
            type=mujoco.mjtSensor.mjSENS_FRAMEPOS,
            objtype=mujoco.mjtObj.mjOBJ_XBODY,
            objname=foot,
        )


NEAR_DEPTH = 3
"""Links from the start of a limb that count as its proximal segment (G1: hip pitch, roll, yaw)."""


def _segments(model: mujoco.MjModel, bodies: np.ndarray) -> tuple[list[int], list[bool], dict[int, int]]:
    """Per body in ``bodies``: its limb (the first body below the nearest branching ancestor;
    the robot's root is a limb of its own) and whether it is distal (``NEAR_DEPTH`` or more links
    down its limb); and per limb, the limb it branches from (-1 for the root's)."""
    nchild = np.bincount(model.body_parentid[1:], minlength=model.nbody)

    def limb_of(b: int) -> tuple[int, int]:
        cur, depth = b, 0
        while True:
            p = int(model.body_parentid[cur])
            if p == 0 or nchild[p] >= 2:
                return cur, depth
            cur, depth = p, depth + 1

    limb, distal, parent = [], [], {}
    for b in bodies:
        root, depth = limb_of(int(b))
        limb.append(root)
        distal.append(depth >= NEAR_DEPTH)
        above = int(model.body_parentid[root])
        parent[root] = limb_of(above)[0] if above != 0 else -1
    return limb, distal, parent


def near_pairs_apart(model: mujoco.MjModel, robot_geoms: np.ndarray) -> bool:
    """Stop collisions (in place) between the robot's links that its joints keep apart, where
    MuJoCo would otherwise test mesh pairs that are always a few millimetres apart at every
    step: links of one limb, and a limb's first ``NEAR_DEPTH`` links with the limb it branches
    from (G1: pelvis and hip links, torso and shoulder links, wrist links). Every other pair
    collides as before: left with right, arms with legs, a hand with the pelvis or torso, a knee
    with the torso, the robot with the scene.

    Needs every pair of robot collision geoms to collide in ``model`` and bitmasks of at most
    8 bits; otherwise (or with more than 15 segments) nothing changes and False is returned.
    MuJoCo collides two geoms when ``contype_a & conaffinity_b or contype_b & conaffinity_a``:
    bits 0-7 carry robot contype x scene conaffinity, bits 8-15 scene contype x robot
    conaffinity (scene geoms get both), bits 16-30 one bit per segment (limb, proximal or
    distal) with each segment's conaffinity the set of segments it may touch.
    """
    geoms = np.asarray(robot_geoms, dtype=np.int64)
    contype = model.geom_contype.astype(np.int64)
    conaffinity = model.geom_conaffinity.astype(np.int64)
    ct, ca = contype[geoms], conaffinity[geoms]
    if max(contype.max(initial=0), conaffinity.max(initial=0)) >= 1 << 8 or geoms.size < 2:
        return False
    if not (((ct[:, None] & ca[None, :]) | (ct[None, :] & ca[:, None])) != 0).all():
        return False
    limb, distal, limb_parent = _segments(model, model.geom_bodyid[geoms])
    keys = sorted(set(zip(limb, distal, strict=True)))  # (limb, distal) segments
    if len(keys) > 15:
        return False
    index = {k: i for i, k in enumerate(keys)}
    segment = [index[k] for k in zip(limb, distal, strict=True)]

    def apart(s: int, t: int) -> bool:
        (ls, ds), (lt, dt) = keys[s], keys[t]
        return ls == lt or (not ds and limb_parent[ls] == lt) or (not dt and limb_parent[lt] == ls)

    allowed = [sum(1 << (16 + t) for t in range(len(keys)) if not apart(s, t)) for s in range(len(keys))]
    new_ct = contype | contype << 8
    new_ca = conaffinity | conaffinity << 8
    new_ct[geoms] = ct | np.array([1 << (16 + s) for s in segment])
    new_ca[geoms] = ca << 8 | np.array([allowed[s] for s in segment])
    model.geom_contype[:] = new_ct
    model.geom_conaffinity[:] = new_ca
    return True


def planning_model(executed: mujoco.MjModel, substeps: int, robot_geoms: np.ndarray) -> mujoco.MjModel:
    """The planning copy of the executed model (which has the cost's sensors:
    :func:`add_plan_sensors`): ``substeps`` x its timestep, no joint or tendon friction loss,
    and no collisions between links that the joints keep apart (:func:`near_pairs_apart`;
    the executed model keeps both). Motors are turned into servos afterwards
    (:func:`sim.physics.actuation.servo_planning`).

    A copy of the compiled model with some of its fields changed: no second compile.
    """
    plan = copy.copy(executed)
    plan.opt.timestep = substeps * float(executed.opt.timestep)
    plan.dof_frictionloss[:] = 0.0
    plan.tendon_frictionloss[:] = 0.0
    near_pairs_apart(plan, robot_geoms)
    return plan


def plan_sensor_start(model: mujoco.MjModel) -> int:
    """Index in ``sensordata`` of the cost's sensors (:func:`add_plan_sensors`)."""
    sid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SENSOR, PLAN_SENSOR_PREFIX + "com")
    if sid < 0:
        raise ControlMMError("the planning model has no centre-of-mass sensor")
    return int(model.sensor_adr[sid])
