"""A robot ready for retargeting: MJCF + mapping, checked against each other.

``load_robot("g1")`` (a packaged name, a mapping ``.json`` path or a :class:`Mapping`) loads
the MuJoCo model, resolves every keypoint to a node of the kinematic tree, collects the
feet's collision geometry (the points that touch the floor), evaluates the rest pose
(``qpos0`` with the soles on the floor) and the human -> robot scale.
"""

from __future__ import annotations

import copy
import functools
from pathlib import Path

import mujoco
import numpy as np

from controlmm.errors import ControlMMError, InputFileError
from controlmm.motion.skeleton import JOINT_INDEX, JOINT_NAMES, PARENTS
from retarget.actuators import damping_share
from retarget.automap import auto_mapping
from retarget.bodyfloor import BodyFloor, build_body_floor
from retarget.capsules import Capsules, robot_capsules
from retarget.couplings import JointCouplings, joint_couplings
from retarget.file_layout import FileLayout, file_layout
from retarget.geoms import FloorPoints, collision_geoms, geom_points
from retarget.human import HUMAN_HIP_HEIGHT, HUMAN_PELVIS_HEIGHT
from retarget.kinematics import KinematicTree, Poses, quat_to_mat
from retarget.mapping import Mapping, load_mapping
from retarget.rest_frame import rest_root_quat
from retarget.robot_files import ancestors, compile_robot, robot_mjcf_path
from retarget.selfcollision import SelfClearance, build_self_clearance
from retarget.soles import flat_tilt, lowest_candidates


class RobotModel:
    """An MJCF robot plus a mapping, resolved for the solver.

    Attributes:
        mapping: the :class:`Mapping`.
        model: the compiled ``mujoco.MjModel`` (the robot MJCF, unchanged).
        mjcf: path of the MJCF.
        tree: :class:`KinematicTree`.
        joints: mapped human joint indices (K,), HumanML3D order.
        nodes: (K,) tree node of each keypoint; offsets: (K, 3) in the node frame.
        feet: {"left": FloorPoints, "right": FloorPoints} (the ankles' bodies).
        lower, upper: (nj,) joint ranges the retargeter uses (MJCF ranges narrowed by the
            mapping's ``ranges``).
        rest_q: (nj,) rest joint angles (qpos0 clipped to those ranges).
        damping_share: (nj,) each joint's damping over its torque limit (s/rad, 0 where the
            MJCF has neither: :func:`retarget.actuators.damping_share`).
        rest_root_quat: (4,) wxyz the root's rest orientation: the MJCF's, turned to face +X
            (:func:`retarget.rest_frame.rest_root_quat`; identity for most MJCFs).
        rest: Poses of the rest pose with the root at the world origin in that orientation.
        floor_z: lowest foot point (m) of the rest pose (subtract it to stand on the floor).
        foot_flat_rot: {"left"|"right": (3, 3)} world rotation of each foot's node standing flat
            on its sole, facing as in the rest pose (:func:`retarget.soles.flat_tilt`: the rest
            orientation for feet that are flat in ``qpos0``); foot_flat_height: the node
            origin's height (m) above the floor then.
        scale: the human -> robot uniform scale.
        body_joints: every robot body name -> human joint names it follows.
    """

    def __init__(self, mapping: Mapping) -> None:
        self.mapping = mapping
        path = robot_mjcf_path(mapping.robot)
        self.model = compile_robot(mapping.robot)
        self.mjcf = path
        m = self.model
        self.tree = tree = KinematicTree(m)
        body_names = {m.body(b).name: b for b in range(m.nbody)}
        site_names = {m.site(s).name: s for s in range(m.nsite)}
        where = f"mapping {mapping.source}"
        joints, nodes, offsets = [], [], []
        for kp in mapping.keypoints:
            if kp.body is not None:
                if kp.body not in body_names:
                    raise ControlMMError(
                        f"{where}: body '{kp.body}' (for '{kp.joint}') is not in {path.name}; "
                        f"bodies: {', '.join(n for n in body_names if n and n != 'world')}"
                    )
                node = tree.node_of_body(body_names[kp.body])
                off = np.asarray(kp.offset, dtype=float)
            else:
                if kp.site not in site_names:
                    raise ControlMMError(
                        f"{where}: site '{kp.site}' (for '{kp.joint}') is not in {path.name}; "
                        f"sites: {', '.join(site_names) or 'none'}"
                    )
                s = site_names[kp.site]
                node = tree.node_of_body(int(m.site_bodyid[s]))
                off = m.site_pos[s] + quat_to_mat(m.site_quat[s]) @ np.asarray(kp.offset, dtype=float)
            joints.append(JOINT_INDEX[kp.joint])
            nodes.append(node)
            offsets.append(off)
        self.joints = np.array(joints)
        self.nodes = np.array(nodes)
        self.offsets = np.array(offsets)
        self.keypoint_names = [JOINT_NAMES[j] for j in joints]
        for name in mapping.posture_weights:
            if name != "default" and name not in tree.joint_names:
                raise ControlMMError(
                    f"{where}: posture weight for unknown joint '{name}'; joints: "
                    f"{', '.join(tree.joint_names)}"
                )
        default = mapping.posture_weights.get("default", 0.02)
        self.posture_weights = np.array([mapping.posture_weights.get(n, default) for n in tree.joint_names])
        self.damping_share = damping_share(m, tree.joint_ids)
        # Feet: the bodies of the ankle keypoints and their collision geometry.
        self.feet: dict[str, FloorPoints] = {}
        qpos0 = mujoco.MjData(m)
        mujoco.mj_kinematics(m, qpos0)
        for side in ("left", "right"):
            k = self.keypoint_index(f"{side}_ankle")
            node = int(self.nodes[k])
            body = int(tree.node_body[node])
            geoms, pts, rad = [], [], []
            for b, (pos, rot) in _links_below(m, qpos0, body).items():  # toe links held at rest
                for g in collision_geoms(m, b):
                    p, r = geom_points(m, g)
                    geoms.append(g)
                    pts.append(pos + p @ rot.T)
                    rad.append(r)
            if not geoms or sum(len(p) for p in pts) == 0:
                raise ControlMMError(
                    f"{where}: the {side} foot body '{m.body(body).name}' (body of "
                    f"'{side}_ankle') has no collision geometry to stand on"
                )
            self.feet[side] = FloorPoints(node, np.concatenate(pts), np.concatenate(rad), tuple(geoms))
        # Retargeting ranges: the MJCF's, narrowed by the mapping's human-like ranges.
        self.lower, self.upper = tree.lower.copy(), tree.upper.copy()
        for name, (lo, hi) in mapping.ranges.items():
            if name not in tree.joint_names:
                raise ControlMMError(
                    f"{where}: range for unknown joint '{name}'; joints: {', '.join(tree.joint_names)}"
                )
            j = tree.joint_names.index(name)
            self.lower[j], self.upper[j] = max(self.lower[j], lo), min(self.upper[j], hi)
            if self.lower[j] >= self.upper[j]:
                raise ControlMMError(
                    f"{where}: range {[lo, hi]} of '{name}' does not overlap its MJCF range "
                    f"[{tree.lower[j]:.4g}, {tree.upper[j]:.4g}]"
                )
        # Rest pose: qpos0, root at the origin in its rest orientation (facing +X); the floor
        # is its lowest foot point.
        self.rest_q = np.clip(tree.qpos0, self.lower, self.upper)
        self.rest_root_quat = rest_root_quat(m, int(tree.node_body[0]))
        self.rest = tree.forward(np.zeros((1, 3)), quat_to_mat(self.rest_root_quat)[None], self.rest_q[None])
        for side, f in self.feet.items():  # a finely meshed foot: the points that can touch the floor
            keep = lowest_candidates(f.points, f.radius, self.rest.rot[0, f.node])
            self.feet[side] = FloorPoints(f.node, f.points[keep], f.radius[keep], f.geoms)
        self.floor_z = min(float(self.foot_lowest(self.rest, side)[0]) for side in ("left", "right"))
        self.rest_keypoints = tree.points(self.rest, self.nodes, self.offsets)[0]  # (K, 3)
        # Flat feet: the rest orientation tilted until the sole lies on the floor.
        self.foot_flat_rot: dict[str, np.ndarray] = {}
        self.foot_flat_height: dict[str, float] = {}
        for side, f in self.feet.items():
            rest_rot = self.rest.rot[0, f.node]
            rot = flat_tilt(f.points, f.radius, rest_rot) @ rest_rot
            self.foot_flat_rot[side] = rot
            self.foot_flat_height[side] = float(-((f.points @ rot.T)[:, 2] - f.radius).min())
        self.scale = mapping.scale if mapping.scale is not None else self._auto_scale()
        self.body_joints = self._body_joints()

    @functools.cached_property
    def couplings(self) -> JointCouplings | None:
        """The MJCF's joint equalities between the solver's joints (None without any)."""
        return joint_couplings(self.model, self.tree.joint_ids)

    @functools.cached_property
    def file_layout(self) -> FileLayout | None:
        """How trajectories sit in the MJCF file's own qpos where reading it changed its joints
        (:mod:`retarget.file_layout`); None where the file's qpos is the retargeter's."""
        m = self.model
        followed = {int(self.tree.node_body[node]) for node in self.nodes}
        main = {m.body(b).name for body in followed for b in ancestors(m, body)}
        return file_layout(self.mjcf, m, main)

    @functools.cached_property
    def capsules(self) -> Capsules:
        """Enclosing capsules of the collision geoms (:func:`retarget.capsules.robot_capsules`)."""
        return robot_capsules(self.model, self.tree)

    @functools.cached_property
    def body_floor(self) -> BodyFloor | None:
        """Support points of every body but the feet (:class:`retarget.bodyfloor.BodyFloor`)."""
        return build_body_floor(self.model, self.tree, self.feet)

    @functools.cached_property
    def self_clearance(self) -> SelfClearance | None:
        """Arm self-clearance capsules and pairs (:func:`retarget.selfcollision.build_self_clearance`)."""
        nodes = {name: int(node) for name, node in zip(self.keypoint_names, self.nodes, strict=True)}
        return build_self_clearance(self.model, self.tree, nodes, self.feet, self.capsules, self.rest)

    def with_self_clearance(self, clearance: SelfClearance | None) -> RobotModel:
        """A shallow copy whose solver keeps ``clearance`` (other margins, same pairs) instead
        (the collision geometry built first, so that the copy shares it)."""
        other = copy.copy(self.prepare())
        other.__dict__["self_clearance"] = clearance
        return other

    def prepare(self) -> RobotModel:
        """Build now the collision geometry the solver otherwise builds on first use (capsules,
        body floor, self-clearance): for a process that keeps robots warm between jobs."""
        _ = self.body_floor, self.self_clearance
        return self

    # -- lookups -------------------------------------------------------------------------
    def keypoint_index(self, joint: str) -> int:
        """Index into the keypoint arrays of a mapped human joint."""
        try:
            return self.keypoint_names.index(joint)
        except ValueError:
            raise ControlMMError(f"human joint '{joint}' is not mapped for robot '{self.name}'") from None

    def has_keypoint(self, joint: str) -> bool:
        return joint in self.keypoint_names

    @property
    def name(self) -> str:
        return self.mapping.name

    @property
    def body_names(self) -> list[str]:
        """Robot body names in MuJoCo order, without the world body."""
        return [self.model.body(b).name for b in range(1, self.model.nbody)]

    def foot_lowest(self, poses: Poses, side: str) -> np.ndarray:
        """Lowest z (m) of a foot's collision points per frame, (T,)."""
        return self.feet[side].lowest(poses)[0]

    # -- derived quantities ----------------------------------------------------------------
    def _auto_scale(self) -> float:
        """Rest hip height above the soles divided by the human's (or the pelvis ratio without hips)."""
        hips = [j for j in ("left_hip", "right_hip") if self.has_keypoint(j)]
        if hips:
            z = np.mean([self.rest_keypoints[self.keypoint_index(j), 2] for j in hips]) - self.floor_z
            return float(z / HUMAN_HIP_HEIGHT)
        z = self.rest_keypoints[self.keypoint_index("pelvis"), 2] - self.floor_z
        return float(z / HUMAN_PELVIS_HEIGHT)

    def _body_joints(self) -> dict[str, tuple[str, ...]]:
        """Every body -> human joints: as listed in the mapping, else nearest mapped descendant/ancestor."""
        m = self.model
        names = {m.body(b).name: b for b in range(1, m.nbody)}
        for body in self.mapping.body_joints:
            if body not in names:
                raise ControlMMError(
                    f"mapping {self.mapping.source}: body_joints names body '{body}', "
                    f"which is not in {self.mjcf.name}"
                )
        own: dict[int, list[str]] = {}
        for kp, node in zip(self.keypoint_names, self.nodes, strict=True):
            own.setdefault(int(self.tree.node_body[node]), []).append(kp)
        children: dict[int, list[int]] = {}
        for b in range(1, m.nbody):
            children.setdefault(int(m.body_parentid[b]), []).append(b)
        out: dict[str, tuple[str, ...]] = {}
        for name, b in names.items():
            if name in self.mapping.body_joints:
                out[name] = self.mapping.body_joints[name]
                continue
            found: list[str] = []
            frontier = [b]
            while frontier and not found:  # breadth-first over descendants
                for x in frontier:
                    found += own.get(x, [])
                frontier = [c for x in frontier for c in children.get(x, [])]
            a = b
            while not found and a > 0:
                found = list(own.get(a, []))
                a = int(m.body_parentid[a])
            out[name] = tuple(dict.fromkeys(found)) or ("pelvis",)
        return out

    def human_parent_keypoint(self, k: int) -> int | None:
        """Index of the nearest mapped human ancestor of keypoint k (position-weighted), or None."""
        j = int(PARENTS[self.joints[k]])
        while j >= 0:
            if JOINT_NAMES[j] in self.keypoint_names:
                kk = self.keypoint_names.index(JOINT_NAMES[j])
                kp = self.mapping.keypoints[kk]
                if kp.position_weight > 0 or kp.segment_weight > 0:
                    return kk
            j = int(PARENTS[j])
        return None


@functools.lru_cache(maxsize=16)
def _load_cached(key: str) -> RobotModel:
    return RobotModel(load_mapping(key))


def _links_below(
    model: mujoco.MjModel, data: mujoco.MjData, foot: int
) -> dict[int, tuple[np.ndarray, np.ndarray]]:
    """``foot`` and the links below it (toes) -> their pose in ``foot``'s frame in ``data``
    (kinematics of ``qpos0``): (3,) position, (3, 3) rotation (the foot itself at the origin;
    most robots have no toe links)."""
    rot_f = data.xmat[foot].reshape(3, 3)
    return {
        b: (rot_f.T @ (data.xpos[b] - data.xpos[foot]), rot_f.T @ data.xmat[b].reshape(3, 3))
        for b in range(1, model.nbody)
        if foot in ancestors(model, b)
    }


def load_robot(robot: str | Path | Mapping | RobotModel = "g1") -> RobotModel:
    """A :class:`RobotModel` from a packaged robot name, a mapping file path, a humanoid MJCF path
    (mapped automatically, :mod:`retarget.automap`) or a :class:`Mapping`."""
    if isinstance(robot, RobotModel):
        return robot
    if isinstance(robot, Mapping):
        return RobotModel(robot)
    text = str(robot).strip()
    if text.lower().endswith(".json"):
        path = Path(text).expanduser()
        if path.is_file():
            stat = path.stat()
            return _load_cached_file(str(path.resolve()), stat.st_mtime_ns, stat.st_size)
        return _load_cached(text)  # raises the one-line error
    if text.lower().endswith(".xml"):
        path = Path(text).expanduser()
        if not path.is_file():
            raise InputFileError(f"robot MJCF '{text}' does not exist")
        stat = path.stat()
        return _load_cached_mjcf(str(path.resolve()), stat.st_mtime_ns, stat.st_size)
    return _load_cached(text.lower())


@functools.lru_cache(maxsize=16)
def _load_cached_mjcf(path: str, mtime: int, size: int) -> RobotModel:
    return RobotModel(auto_mapping(path))


@functools.lru_cache(maxsize=16)
def _load_cached_file(path: str, mtime: int, size: int) -> RobotModel:
    return RobotModel(load_mapping(path))
