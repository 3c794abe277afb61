"""The retargeter's batched kinematics against MuJoCo's own mj_kinematics, and its Jacobians."""

import mujoco
import numpy as np
import pytest

from retarget.kinematics import KinematicTree, quat_to_mat, so3_exp, so3_log
from retarget.robots import robot_mjcf

CUSTOM = """
<mujoco><worldbody>
<body name="base" pos="0 0 1"><freejoint/>
  <geom type="sphere" size="0.1"/>
  <body name="a" pos="0.1 0.2 -0.1" quat="0.9 0.1 0.3 0.2">
    <joint name="a1" type="hinge" axis="1 0 0" pos="0.05 0 0" range="-1 1"/>
    <joint name="a2" type="hinge" axis="0 1 1" pos="0 0.03 0.02" ref="0.3"/>
    <geom type="capsule" size="0.02 0.1"/>
    <body name="b" pos="0 0 -0.2">
      <joint name="b1" type="slide" axis="0 0 1" range="-0.1 0.1"/>
      <joint name="b2" type="hinge" axis="0 0 1" pos="0.01 0.02 0.03"/>
      <geom type="box" size="0.02 0.03 0.04"/>
      <body name="c" pos="0.1 0 0"><geom type="sphere" size="0.01"/></body>
    </body>
  </body>
</body></worldbody></mujoco>"""


def _models():
    yield "g1", mujoco.MjModel.from_xml_path(str(robot_mjcf("g1")))
    yield "h1", mujoco.MjModel.from_xml_path(str(robot_mjcf("h1")))
    yield "custom", mujoco.MjModel.from_xml_string(CUSTOM)


def _random_state(tree: KinematicTree, t: int, rng):
    lo = np.maximum(tree.lower, -2.5)
    hi = np.minimum(tree.upper, 2.5)
    q = rng.uniform(lo, hi, size=(t, tree.nj))
    quat = rng.normal(size=(t, 4))
    quat /= np.linalg.norm(quat, axis=1, keepdims=True)
    return rng.normal(size=(t, 3)), quat, q


@pytest.mark.parametrize("name,model", list(_models()))
def test_forward_kinematics_matches_mujoco(name, model):
    tree = KinematicTree(model)
    data = mujoco.MjData(model)
    rng = np.random.default_rng(0)
    pos, quat, q = _random_state(tree, 12, rng)
    poses = tree.forward(pos, quat_to_mat(quat), q)
    for t in range(len(q)):
        data.qpos[:] = np.concatenate([pos[t], quat[t], q[t]])
        mujoco.mj_kinematics(model, data)
        for b in range(1, model.nbody):
            node = tree.node_of_body(b)
            np.testing.assert_allclose(poses.pos[t, node], data.xpos[b], atol=1e-12)
            np.testing.assert_allclose(poses.rot[t, node], data.xmat[b].reshape(3, 3), atol=1e-12)
        for j, jid in enumerate(tree.joint_ids):
            np.testing.assert_allclose(poses.anchor[t, j], data.xanchor[jid], atol=1e-12)
            np.testing.assert_allclose(poses.axis[t, j], data.xaxis[jid], atol=1e-12)


@pytest.mark.parametrize("name,model", list(_models())[::2])
def test_jacobians_match_finite_differences(name, model):
    tree = KinematicTree(model)
    rng = np.random.default_rng(1)
    pos, quat, q = _random_state(tree, 3, rng)
    rot = quat_to_mat(quat)
    nodes = np.arange(1, tree.num_nodes)
    offsets = rng.normal(size=(len(nodes), 3)) * 0.1
    poses = tree.forward(pos, rot, q)
    pts = tree.points(poses, nodes, offsets)
    jp = tree.point_jacobian(poses, nodes, pts)
    jz = tree.point_jacobian(poses, nodes, pts, rows=(2,))
    jr = tree.rotation_jacobian(poses, nodes)
    np.testing.assert_allclose(jz[:, :, 0], jp[:, :, 2])
    eps = 1e-7
    for i in range(tree.nv):
        d = np.zeros(tree.nv)
        d[i] = eps
        p2 = tree.forward(pos + d[:3], so3_exp(np.tile(d[3:6], (3, 1))) @ rot, q + d[6:])
        num = (tree.points(p2, nodes, offsets) - pts) / eps
        np.testing.assert_allclose(jp[..., i], num, atol=2e-6)
        num_r = so3_log(p2.rot[:, nodes] @ np.swapaxes(poses.rot[:, nodes], -1, -2)) / eps
        np.testing.assert_allclose(jr[..., i], num_r, atol=2e-6)


def test_so3_log_exp_round_trip_including_half_turns():
    rng = np.random.default_rng(2)
    w = rng.normal(size=(50, 3))
    w *= (rng.uniform(0, np.pi - 1e-3, size=50) / np.linalg.norm(w, axis=1))[:, None]
    np.testing.assert_allclose(so3_log(so3_exp(w)), w, atol=1e-9)
    half = so3_exp(np.array([[np.pi, 0, 0], [0, 0, np.pi]]))
    np.testing.assert_allclose(so3_exp(so3_log(half)), half, atol=1e-9)
