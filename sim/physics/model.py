"""The models of the physics check: the executed one (saved as one MJCF file) and the planning copy.

*Executed model.* The robot + scene is written as one self-contained MJCF string by MuJoCo
(``MjSpec.to_xml``): every mesh file is replaced by its vertices and faces, so the file needs
nothing beside it. The simulation runs on the model compiled **from that string**, so loading
``physics_model.xml`` and stepping it with the recorded controls reproduces the recorded states
exactly (same MuJoCo version). Vertices are taken from the compiled model and moved back into
the mesh file's frame (``mesh_pos``, ``mesh_quat``), so that the compiler derives the same mesh
frames and geom poses as for the original files.

*Planning model.* The rollouts use a copy of the same inline spec with a longer timestep
(``plan_substeps`` x the model's), sensors for the centre of mass, its velocity and the feet,
motor actuators turned into the position servos the controller emulates
(:mod:`sim.physics.actuation`), and no dry friction in the joints and tendons
(``frictionloss``: one constraint row per joint that made each rollout step about 1.4x as
expensive on G1, for 0.3 N m against servo torques of tens of N m and their damping). It is
compiled from the same inline spec as the saved MJCF (no second parse of the saved text).
"""

from __future__ import annotations

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


def planning_spec(
    inline: mujoco.MjSpec, timestep: float, root_body: str, foot_bodies: list[str]
) -> mujoco.MjSpec:
    """The planning copy's spec: a copy of the executed model's spec (``inline``, meshes inline:
    :func:`inline_meshes`) with a longer timestep, no joint or tendon friction loss, and the
    cost's sensors.

    Sensors (in this order, after the model's own): centre of mass of the robot (subtree of
    the root body, 3), its linear velocity (3), the world position of each foot body (3 each).
    """
    spec = inline.copy()
    spec.option.timestep = timestep
    for joint in spec.joints:
        joint.frictionloss = 0.0
    for tendon in spec.tendons:
        tendon.frictionloss = 0.0
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
    return spec


def plan_sensor_start(model: mujoco.MjModel) -> int:
    """Index in ``sensordata`` of the planning sensors (:func:`planning_spec`)."""
    sid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SENSOR, PLAN_SENSOR_PREFIX + "com")
    if sid < 0:
        raise ControlMMError("the planning model has no centre-of-mass sensor")
    return int(model.sensor_adr[sid])
