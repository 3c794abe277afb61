"""The whole-sequence solver's span batching and the exact lowest point of mesh geoms.

The local refinement solves several spans of frames as one problem; each span must come out
exactly as if it had been solved alone (its own step acceptance, stopping and damping). The
floor lift finds the lowest point of a mesh from its convex hull; it must equal the minimum
over every vertex.
"""

from __future__ import annotations

from dataclasses import replace

import mujoco
import numpy as np
import pytest

from controlmm.frames import HumanToWorld
from controlmm.motion import Motion
from retarget.metrics import geom_lowest_z, replay
from retarget.problem import Problem
from retarget.robot_model import load_robot
from retarget.solver import CONSTRAINT_TOLERANCE, _solve, solve, violation_spans
from retarget.solver_config import SolverConfig
from retarget.targets import build_targets, take_frames


@pytest.mark.parametrize("patience", [None, 2])
def test_spans_solved_together_equal_spans_solved_alone(sample_features, patience):
    # H1 on the real clip: after a short full solve, frames with the hip-yaw capsules
    # overlapping remain; their spans are what the local refinement solves, and some of
    # them refuse steps the others accept.
    # (H1's own mapping stiffens its self-clearance and the limbs follow the human's joints;
    # with the soft clearance and the robot-proportioned limbs the overlaps remain. The light
    # acceleration term lets the spans differ: with 5, every span of today's targets stops
    # after one iteration.)
    robot = load_robot("h1")
    joints = Motion.from_features(sample_features).joints.astype(np.float64)
    config = replace(
        SolverConfig(**robot.mapping.solver),
        w_self=100.0,
        human_leg_share=0.0,
        human_arm_share=0.0,
        w_acc_joint=2.0,
    )
    targets = build_targets(robot, joints, 20.0, HumanToWorld(scale=robot.scale), config)
    sol = solve(robot, targets, replace(config, extra_iterations=0, pin_iterations=0))
    prob = Problem(robot, targets, config)
    idx, pinned, span = violation_spans(
        prob.frame_violation(prob.evaluate(sol.root_pos, sol.root_rot, sol.q)) > CONSTRAINT_TOLERANCE
    )
    assert span.max() >= 2  # at least three spans
    config = replace(config, max_iterations=6)
    ref = prob.ref_x[:, :3]
    lam = np.maximum(sol.damping, 1e-4)

    alone = []
    for s in range(span.max() + 1):
        r = idx[span == s]
        alone.append(
            _solve(
                robot,
                take_frames(targets, r, targets.fps),
                config,
                (sol.root_pos[r], sol.root_rot[r], sol.q[r]),
                pinned=pinned[span == s],
                ref_pos=ref[r],
                damping=lam[r],
                patience=patience,
            )[0]
        )
    together, _ = _solve(
        robot,
        take_frames(targets, idx, targets.fps),
        config,
        (sol.root_pos[idx], sol.root_rot[idx], sol.q[idx]),
        pinned=pinned,
        ref_pos=ref[idx],
        span=span,
        damping=lam[idx],
        patience=patience,
    )

    # the spans really behave differently: different iteration counts, some steps refused
    assert len({a.iterations for a in alone}) > 1
    assert any(len(a.history) - 1 < a.iterations for a in alone)
    assert together.iterations == max(a.iterations for a in alone)
    for s, a in enumerate(alone):
        rows = span == s
        # rounding only: a different accept/refuse decision would differ by orders of magnitude more
        np.testing.assert_allclose(together.q[rows], a.q, atol=1e-6)
        np.testing.assert_allclose(together.root_pos[rows], a.root_pos, atol=1e-6)
        np.testing.assert_allclose(together.root_rot[rows], a.root_rot, atol=1e-6)
        np.testing.assert_allclose(together.damping[rows], a.damping, rtol=1e-9)
    assert together.cost == pytest.approx(sum(a.cost for a in alone), rel=1e-7)
    # pinned frames stay (to the precision of their 1e9 pinning weight)
    np.testing.assert_allclose(together.q[pinned], sol.q[idx][pinned], atol=1e-6)


def test_mesh_lowest_point_from_hull_equals_every_vertex():
    robot = load_robot("g1")
    m = robot.model
    meshes = [g for g in range(m.ngeom) if m.geom_type[g] == mujoco.mjtGeom.mjGEOM_MESH]
    assert meshes
    rng = np.random.default_rng(0)
    qpos = np.tile(m.qpos0, (12, 1))
    qpos[:, 7:] += rng.uniform(-0.5, 0.5, (12, m.nq - 7))
    qpos[:, 3:7] = rng.normal(size=(12, 4))
    qpos[:, 3:7] /= np.linalg.norm(qpos[:, 3:7], axis=1, keepdims=True)
    rep = replay(m, qpos)
    low = geom_lowest_z(m, rep, meshes)
    for i, g in enumerate(meshes):
        mid = m.geom_dataid[g]
        verts = m.mesh_vert[m.mesh_vertadr[mid] : m.mesh_vertadr[mid] + m.mesh_vertnum[mid]]
        world_z = rep.geom_xpos[:, g, 2:3] + np.einsum("tk,vk->tv", rep.geom_xmat[:, g, 2, :], verts)
        np.testing.assert_allclose(low[:, i], world_z.min(axis=1), atol=1e-12)
