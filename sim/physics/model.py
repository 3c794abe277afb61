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
collisions between the robot's own links. It is the compiled executed model with those
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


def without_self_collision(model: mujoco.MjModel, robot_geoms: np.ndarray) -> bool:
    """Stop the robot's geoms from colliding with each other in ``model`` (in place); every
    other pair (robot-scene, scene-scene) collides as before. Returns False (and changes
    nothing) when the collision bitmasks use more than 15 bits.

    MuJoCo collides two geoms when ``contype_a & conaffinity_b or contype_b & conaffinity_a``.
    A robot geom keeps its contype in the low 16 bits and gets its conaffinity in the high 16;
    every other geom gets both halves. Robot-robot: low & high = 0; all other pairs: the same
    test as before, once in each half. Explicit ``<pair>`` elements are not affected.
    """
    contype = model.geom_contype.astype(np.int64)
    conaffinity = model.geom_conaffinity.astype(np.int64)
    if contype.max(initial=0) >= 1 << 15 or conaffinity.max(initial=0) >= 1 << 15:
        return False
    robot = np.zeros(model.ngeom, dtype=bool)
    robot[np.asarray(robot_geoms, dtype=np.int64)] = True
    model.geom_contype[:] = np.where(robot, contype, contype | contype << 16)
    model.geom_conaffinity[:] = np.where(robot, conaffinity << 16, conaffinity | conaffinity << 16)
    return True


def planning_model(executed: mujoco.MjModel, substeps: int, robot_geoms: np.ndarray) -> mujoco.MjModel:
    """The planning copy of the executed model (which has the cost's sensors:
    :func:`add_plan_sensors`): ``substeps`` x its timestep, no joint or tendon friction loss,
    and no collisions between the robot's own geoms (about 15 % of a G1 rollout step: its
    links are convex meshes; the executed model keeps both). Motors are turned into servos
    afterwards (:func:`sim.physics.actuation.servo_planning`).

    A copy of the compiled model with some of its fields changed: no second compile.
    """
    plan = copy.copy(executed)
    plan.opt.timestep = substeps * float(executed.opt.timestep)
    plan.dof_frictionloss[:] = 0.0
    plan.tendon_frictionloss[:] = 0.0
    without_self_collision(plan, robot_geoms)
    return plan


def plan_sensor_start(model: mujoco.MjModel) -> int:
    """Index in ``sensordata`` of the cost's sensors (:func:`add_plan_sensors`)."""
    sid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SENSOR, PLAN_SENSOR_PREFIX + "com")
    if sid < 0:
        raise ControlMMError("the planning model has no centre-of-mass sensor")
    return int(model.sensor_adr[sid])
