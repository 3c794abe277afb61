"""Batched forward kinematics and Jacobians of a MuJoCo body tree (NumPy, float64).

The tree is read from a compiled ``mujoco.MjModel``: a floating base (a free joint on a
child of the world body) and hinge or slide joints below it, any number per body. Every
joint becomes one *node* (a frame with a fixed offset from its parent node and at most one
joint), so that all frames of one depth are computed together for every time step at once:

    R_node = R_parent @ R_fixed @ Rot(axis, q - qpos0)
    p_node = anchor - R_node @ jnt_pos,   anchor = p_parent + R_parent @ p_fixed + R_parent R_fixed @ jnt_pos

which is MuJoCo's ``mj_kinematics`` rule (checked against it to 1e-12 in the tests).

Generalised coordinates of a frame: ``root_pos (3,)``, ``root_rot (3, 3)`` (world from
root body) and ``q (nj,)`` (the hinge/slide joints in qpos order). Velocity coordinates
used by the Jacobians: ``[dp (3), dtheta (3), dq (nj)]`` with ``dtheta`` a world-frame
rotation about the root body's origin.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import mujoco
import numpy as np

from controlmm.errors import ControlMMError

_HINGE = int(mujoco.mjtJoint.mjJNT_HINGE)
_SLIDE = int(mujoco.mjtJoint.mjJNT_SLIDE)


def quat_to_mat(quat: np.ndarray) -> np.ndarray:
    """Quaternions (..., 4) wxyz -> rotation matrices (..., 3, 3)."""
    q = np.asarray(quat, dtype=np.float64)
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    w, x, y, z = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    return np.stack(
        [
            np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
            np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
            np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1),
        ],
        -2,
    )


def cross3(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Cross products (..., 3) of broadcastable vector arrays (..., 3); ~5x faster than
    ``np.cross`` on the solver's (T, P, 3) arrays (no temporaries per component)."""
    out = np.empty(np.broadcast_shapes(a.shape, b.shape))
    for i in range(3):
        j, k = (i + 1) % 3, (i + 2) % 3
        np.multiply(a[..., j], b[..., k], out=out[..., i])
        out[..., i] -= a[..., k] * b[..., j]
    return out


def skew(v: np.ndarray) -> np.ndarray:
    """Cross-product matrices (..., 3, 3) of vectors (..., 3)."""
    z = np.zeros_like(v[..., 0])
    return np.stack(
        [
            np.stack([z, -v[..., 2], v[..., 1]], -1),
            np.stack([v[..., 2], z, -v[..., 0]], -1),
            np.stack([-v[..., 1], v[..., 0], z], -1),
        ],
        -2,
    )


def so3_exp(w: np.ndarray) -> np.ndarray:
    """Rotation vectors (..., 3) -> rotation matrices (..., 3, 3) (Rodrigues)."""
    theta = np.linalg.norm(w, axis=-1)[..., None, None]
    k = skew(w)
    small = theta < 1e-8
    safe = np.where(small, 1.0, theta)
    a = np.where(small, 1.0, np.sin(safe) / safe)
    b = np.where(small, 0.5, (1 - np.cos(safe)) / (safe * safe))
    return np.eye(3) + a * k + b * (k @ k)


def so3_log(r: np.ndarray) -> np.ndarray:
    """Rotation matrices (..., 3, 3) -> rotation vectors (..., 3), angle in [0, pi]."""
    cos = np.clip((np.trace(r, axis1=-2, axis2=-1) - 1) / 2, -1.0, 1.0)
    theta = np.arccos(cos)
    v = np.stack([r[..., 2, 1] - r[..., 1, 2], r[..., 0, 2] - r[..., 2, 0], r[..., 1, 0] - r[..., 0, 1]], -1)
    sin = np.sin(theta)
    small = sin < 1e-6
    out = v * np.where(small, 0.5, theta / (2 * np.where(small, 1.0, sin)))[..., None]
    near_pi = small & (cos < 0)
    if np.any(near_pi):  # theta ~ pi: axis from the diagonal
        rr = r[near_pi]
        diag = np.clip((np.diagonal(rr, axis1=-2, axis2=-1) + 1) / 2, 0, None)
        axis = np.sqrt(diag)
        i = np.argmax(diag, axis=-1)
        sgn = np.sign(np.take_along_axis((rr + np.swapaxes(rr, -1, -2)) / 2, i[:, None, None], -2)[:, 0])
        sgn[sgn == 0] = 1
        axis = axis * sgn
        axis /= np.linalg.norm(axis, axis=-1, keepdims=True)
        out[near_pi] = axis * theta[near_pi][:, None]
    return out


@dataclass
class Poses:
    """Forward-kinematics result for T frames.

    Attributes:
        rot: (T, N, 3, 3) world rotation of every node.
        pos: (T, N, 3) world position (m) of every node.
        axis: (T, nj, 3) world joint axes.
        anchor: (T, nj, 3) world joint anchors (m).
        root_pos: (T, 3) root body position.
    """

    rot: np.ndarray
    pos: np.ndarray
    axis: np.ndarray
    anchor: np.ndarray
    root_pos: np.ndarray

    def take(self, frames: np.ndarray) -> Poses:
        """The poses of some frames (indices (F,) into the T frames)."""
        return Poses(
            self.rot[frames], self.pos[frames], self.axis[frames], self.anchor[frames], self.root_pos[frames]
        )


def check_joint_types(model: mujoco.MjModel, root_body: int) -> None:
    """Raise ControlMMError (one line) for the first joint below the floating base's body
    ``root_body`` that is neither a hinge nor a slide (a ball shoulder; the ball-jointed rods of
    closed chains are dropped before: :func:`retarget.spec_edits.drop_closed_chain_rods`)."""
    for j in range(model.njnt):
        b = int(model.jnt_bodyid[j])
        if (
            b != root_body
            and model.body_rootid[b] == root_body
            and int(model.jnt_type[j]) not in (_HINGE, _SLIDE)
        ):
            kind = mujoco.mjtJoint(model.jnt_type[j]).name
            raise ControlMMError(
                f"joint '{model.joint(j).name}' is a {kind} joint; the retargeter "
                "supports hinge and slide joints below the floating base"
            )


class KinematicTree:
    """The body tree of a MuJoCo model with a floating base, as arrays for batched FK."""

    def __init__(self, model: mujoco.MjModel) -> None:
        self.model = model
        free = [j for j in range(model.njnt) if int(model.jnt_type[j]) == int(mujoco.mjtJoint.mjJNT_FREE)]
        if len(free) != 1:
            raise ControlMMError(
                f"a retargeting robot needs exactly one free joint (floating base); the model has {len(free)}"
            )
        self.root_body = int(model.jnt_bodyid[free[0]])
        if model.body_parentid[self.root_body] != 0 or model.jnt_qposadr[free[0]] != 0:
            raise ControlMMError(
                "the free joint must be the first joint and sit on a child of the world body"
            )
        # Nodes: one per (body, joint) plus one per joint-less body; node 0 is the root body.
        node_parent, node_fpos, node_fquat, node_joint, node_body = [], [], [], [], []
        body_last_node = {self.root_body: 0}
        node_parent.append(-1)
        node_fpos.append(np.zeros(3))
        node_fquat.append(np.array([1.0, 0, 0, 0]))
        node_joint.append(-1)
        node_body.append(self.root_body)
        hinge_ids: list[int] = []
        check_joint_types(model, self.root_body)
        for b in range(1, model.nbody):
            if b == self.root_body:
                continue
            if model.body_rootid[b] != self.root_body:
                continue  # another tree (a scene object): not part of the robot
            parent = int(model.body_parentid[b])
            if parent not in body_last_node:
                raise ControlMMError(f"body '{model.body(b).name}' is not below the robot's root body")
            joints = list(range(model.body_jntadr[b], model.body_jntadr[b] + model.body_jntnum[b]))
            prev = body_last_node[parent]
            if not joints:
                joints = [-1]
            for k, j in enumerate(joints):
                node_parent.append(prev)
                node_fpos.append(model.body_pos[b].copy() if k == 0 else np.zeros(3))
                node_fquat.append(model.body_quat[b].copy() if k == 0 else np.array([1.0, 0, 0, 0]))
                node_joint.append(len(hinge_ids) if j >= 0 else -1)
                node_body.append(b)
                if j >= 0:
                    hinge_ids.append(j)
                prev = len(node_parent) - 1
            body_last_node[b] = prev
        self.joint_ids = np.array(hinge_ids, dtype=int)
        """MuJoCo joint ids of the coordinates ``q``, in qpos order."""
        order = np.argsort(model.jnt_qposadr[self.joint_ids])
        if not np.all(order == np.arange(len(order))):
            raise ControlMMError("joint order of the model's tree differs from its qpos order")
        self.nj = len(hinge_ids)
        self.nv = 6 + self.nj
        if model.nq != 7 + self.nj:
            raise ControlMMError(
                f"the robot's qpos has {model.nq} entries; expected 7 + {self.nj} "
                "(free joint + hinge/slide joints)"
            )
        self.node_parent = np.array(node_parent)
        self.node_joint = np.array(node_joint)
        self.node_body = np.array(node_body)
        self.body_node = body_last_node
        n = len(node_parent)
        self.fixed_pos = np.array(node_fpos)
        self.fixed_rot = quat_to_mat(np.array(node_fquat))
        jid = np.where(self.node_joint >= 0, self.joint_ids[np.maximum(self.node_joint, 0)], -1)
        has = self.node_joint >= 0
        self.is_hinge = has & (np.where(has, model.jnt_type[np.maximum(jid, 0)], -1) == _HINGE)
        self.is_slide = has & ~self.is_hinge
        self.jnt_axis = np.where(has[:, None], model.jnt_axis[np.maximum(jid, 0)], [0.0, 0.0, 1.0])
        self.jnt_pos = np.where(has[:, None], model.jnt_pos[np.maximum(jid, 0)], 0.0)
        self.qpos0 = model.qpos0[7:].copy()
        self.lower = np.where(model.jnt_limited[self.joint_ids], model.jnt_range[self.joint_ids, 0], -np.inf)
        self.upper = np.where(model.jnt_limited[self.joint_ids], model.jnt_range[self.joint_ids, 1], np.inf)
        self.joint_names = [model.joint(j).name for j in self.joint_ids]
        # Depth levels for batched evaluation.
        depth = np.zeros(n, dtype=int)
        for i in range(1, n):
            depth[i] = depth[self.node_parent[i]] + 1
        self.levels = [np.flatnonzero(depth == d) for d in range(1, depth.max() + 1)]
        axis_skew = skew(self.jnt_axis)
        self._fixed_k0 = self.fixed_rot.copy()
        self._fixed_k1 = self.fixed_rot @ axis_skew
        self._fixed_k2 = self.fixed_rot @ (axis_skew @ axis_skew)
        self._fixed_axis = (self.fixed_rot @ self.jnt_axis[..., None])[..., 0]
        self._fixed_jpos = self.fixed_pos + (self.fixed_rot @ self.jnt_pos[..., None])[..., 0]
        self._node_jidx = np.maximum(self.node_joint, 0)
        self._node_has = (self.node_joint >= 0).astype(float)
        self._any_jpos = bool(np.any(self.jnt_pos != 0))
        self._any_slide = bool(np.any(self.is_slide))
        self._level_pairs = [(idx, self.node_parent[idx]) for idx in self.levels]
        self._joint_node = np.array(
            [int(np.flatnonzero(self.node_joint == j)[0]) for j in range(self.nj)], dtype=int
        )
        # ancestor[node, joint]: the joint moves the node.
        anc = np.zeros((n, self.nj), dtype=bool)
        for i in range(1, n):
            anc[i] = anc[self.node_parent[i]]
            if self.node_joint[i] >= 0:
                anc[i, self.node_joint[i]] = True
        self.ancestor = anc
        self.num_nodes = n

    def node_of_body(self, body_id: int) -> int:
        """The node whose frame is the body's frame (after all its joints)."""
        if body_id not in self.body_node:
            raise ControlMMError(f"body '{self.model.body(body_id).name}' is not part of the robot")
        return self.body_node[body_id]

    def forward(self, root_pos: np.ndarray, root_rot: np.ndarray, q: np.ndarray) -> Poses:
        """FK for T frames: root_pos (T, 3), root_rot (T, 3, 3), q (T, nj) -> :class:`Poses`.

        Computed node-major ((N, T, ...) arrays: a level's parents are contiguous blocks);
        the returned arrays are (T, N, ...) views of them.
        """
        t = q.shape[0]
        n = self.num_nodes
        # Local transforms of every node at once: fixed offset, then the joint's motion.
        val = ((q - self.qpos0)[:, self._node_jidx] * self._node_has).T  # (N, T)
        ang = val * self.is_hinge[:, None]
        local_rot = np.sin(ang)[..., None, None] * self._fixed_k1[:, None]  # fixed_rot @ Rot(axis, ang)
        local_rot += (1 - np.cos(ang))[..., None, None] * self._fixed_k2[:, None]
        local_rot += self._fixed_k0[:, None]
        general = self._any_jpos or self._any_slide
        if general:
            local_pos = np.broadcast_to(self.fixed_pos[:, None], (n, t, 3))
            if self._any_jpos:  # rotate about the anchor: p = anchor - R @ jnt_pos
                local_pos = self._fixed_jpos[:, None] - np.einsum("ntij,nj->nti", local_rot, self.jnt_pos)
            if self._any_slide:
                local_pos = local_pos + self._fixed_axis[:, None] * (val * self.is_slide[:, None])[..., None]
        rot = np.empty((n, t, 3, 3))
        pos = np.empty((n, t, 3))
        rot[0] = root_rot
        pos[0] = root_pos
        for idx, par in self._level_pairs:
            rp = rot[par]
            rot[idx] = rp @ local_rot[idx]
            if general:
                pos[idx] = pos[par] + np.einsum("mtij,mtj->mti", rp, local_pos[idx])
            else:
                pos[idx] = pos[par] + np.einsum("mtij,mj->mti", rp, self.fixed_pos[idx])
        jn = self._joint_node
        # The joint axis is fixed in the node's frame (a rotation about it leaves it unchanged).
        axis = np.einsum("jtab,jb->jta", rot[jn], self.jnt_axis[jn])
        if general:
            jp = self.node_parent[jn]
            anchor = pos[jp] + np.einsum("jtab,jb->jta", rot[jp], self._fixed_jpos[jn])
        else:
            anchor = pos[jn]  # no joint offset, no slide: the anchor is the node's origin
        return Poses(
            rot=rot.transpose(1, 0, 2, 3),
            pos=pos.transpose(1, 0, 2),
            axis=axis.transpose(1, 0, 2),
            anchor=anchor.transpose(1, 0, 2),
            root_pos=np.asarray(root_pos),
        )

    def points(self, poses: Poses, nodes: np.ndarray, offsets: np.ndarray) -> np.ndarray:
        """World positions (T, K, 3) of points fixed in node frames (offsets (K, 3), metres)."""
        return poses.pos[:, nodes] + np.einsum("tkij,kj->tki", poses.rot[:, nodes], offsets)

    def point_jacobian(
        self, poses: Poses, nodes: np.ndarray, points: np.ndarray, rows: tuple[int, ...] = (0, 1, 2)
    ) -> np.ndarray:
        """d(points)/d(velocity coords): (T, K, len(rows), 6 + nj) for world points (T, K, 3) on ``nodes``.

        ``rows`` picks the world axes (x, y, z = 0, 1, 2) to differentiate.
        """
        t, k = points.shape[:2]
        jac = np.zeros((t, k, len(rows), self.nv))
        rel = points - poses.root_pos[:, None, :]
        kk, jj = np.nonzero(self.ancestor[nodes])  # (point, joint) pairs where the joint moves the point
        col = cross3(poses.axis[:, jj], points[:, kk, :] - poses.anchor[:, jj])  # (T, P, 3): axis x lever
        slide = self.is_slide_joint[jj]
        if self._any_slide and np.any(slide):
            col[:, slide] = poses.axis[:, jj[slide]]
        for i, row in enumerate(rows):
            a, b = (row + 1) % 3, (row + 2) % 3
            jac[:, :, i, row] = 1.0
            # d p / d theta = theta x rel  ->  row: (theta_a rel_b - theta_b rel_a)
            jac[:, :, i, 3 + a] = rel[..., b]
            jac[:, :, i, 3 + b] = -rel[..., a]
            jac[:, kk, i, 6 + jj] = col[..., row]
        return jac

    def directional_jacobian(
        self, poses: Poses, frames: np.ndarray, nodes: np.ndarray, points: np.ndarray, direction: np.ndarray
    ) -> np.ndarray:
        """d(direction . point)/d(velocity coords), (E, 6 + nj), for E scattered entries.

        Entry e is the world point ``points[e]`` (3,) fixed on node ``nodes[e]`` at frame
        ``frames[e]``, projected on the world vector ``direction[e]`` (3,): one row of a
        point Jacobian per entry, without materialising the (3, n) blocks.
        """
        e_len = len(frames)
        jac = np.empty((e_len, self.nv))
        u = direction
        jac[:, 0:3] = u
        jac[:, 3:6] = cross3(points - poses.root_pos[frames], u)  # u . (w x r) = w . (r x u)
        lever = points[:, None, :] - poses.anchor[frames]  # (E, nj, 3)
        ax = poses.axis[frames]
        col = np.einsum("ejk,ejk->ej", ax, cross3(lever, u[:, None, :]))  # u . (a x l) = a . (l x u)
        if self._any_slide:
            slide = self.is_slide_joint
            col[:, slide] = np.einsum("ejk,ek->ej", ax[:, slide], u)
        jac[:, 6:] = col * self.ancestor[nodes]
        return jac

    def rotation_jacobian(self, poses: Poses, nodes: np.ndarray) -> np.ndarray:
        """d(world angular displacement of nodes)/d(velocity coords): (T, K, 3, 6 + nj)."""
        t, k = poses.pos.shape[0], len(nodes)
        jac = np.zeros((t, k, 3, self.nv))
        jac[:, :, :, 3:6] = np.eye(3)
        col = poses.axis[:, None] * (self.ancestor[nodes] & self.is_hinge_joint[None, :])[None, :, :, None]
        jac[:, :, :, 6:] = np.swapaxes(col, -1, -2)
        return jac

    @functools.cached_property
    def is_slide_joint(self) -> np.ndarray:
        """(nj,) True for slide joints."""
        out = np.zeros(self.nj, dtype=bool)
        out[self.node_joint[self.is_slide]] = True
        return out

    @functools.cached_property
    def is_hinge_joint(self) -> np.ndarray:
        """(nj,) True for hinge joints."""
        return ~self.is_slide_joint


def axes_centre(anchors: np.ndarray, axes: np.ndarray) -> np.ndarray:
    """The point (3,) nearest (least squares) to the lines through ``anchors`` (J, 3) along ``axes``.

    Among equally near points (parallel axes, one axis) the one nearest the anchors' mean.
    """
    anchors, axes = np.atleast_2d(anchors), np.atleast_2d(axes)
    mean = anchors.mean(axis=0)
    proj = np.eye(3)[None] - axes[:, :, None] * axes[:, None, :]  # (J, 3, 3) onto the normal planes
    a = proj.sum(axis=0)
    b = np.einsum("jab,jb->a", proj, anchors - mean)
    delta = np.linalg.lstsq(a, b, rcond=1e-6)[0]
    return mean + delta
