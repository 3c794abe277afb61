"""Self-clearance halfway between the solver's frames (:mod:`retarget.midpoints`).

On the real H1 and a generated sit-down (corpus plan 000012) whose hands, solved at 20 fps
with the frames' pairs alone, sweep through the hips between two frames: the averaged
capsules find it, MuJoCo's geoms of the in-between output frames confirm it, the midpoint
term's linearisation matches finite differences of its own cost, and the solver with the
term keeps the in-between frames clear.
"""

from __future__ import annotations

from dataclasses import fields, replace

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from controlmm.corpus import CorpusConfig, make_clip
from controlmm.corpus.dataset import plan_clips
from controlmm.frames import HumanToWorld
from retarget import load_robot
from retarget.costs import Configuration, MidpointClearanceCost, NormalEquations
from retarget.costs.self_clearance import MidpointClearanceValue
from retarget.kinematics import so3_exp
from retarget.midpoints import MIDPOINT_SLACK, MidpointPairs, midpoint_pairs
from retarget.resample import resample_qpos
from retarget.robot_model import RobotModel
from retarget.selfcheck import OTHER_DEPTH, penetration_depths
from retarget.selfcollision import capsule_distances
from retarget.solver import Solution, solve
from retarget.solver_config import SolverConfig
from retarget.targets import Targets, build_targets

EPS = 1e-6


@pytest.fixture(scope="module")
def sit_down() -> tuple[RobotModel, Targets]:
    """H1 and the targets of the generated sit-down 000012 (20 fps), its knees and feet kept
    in the robot's own proportions (its hips 0.4 m apart: the hands pass close by them)."""
    spec = plan_clips(CorpusConfig(clips=9800, seed=0))[12]
    assert spec.family == "sit_down"
    _, joints, _, _ = make_clip(spec)
    robot = load_robot("h1")
    world = HumanToWorld(scale=robot.scale)
    return robot, build_targets(robot, joints.astype(np.float64), 20.0, world, _config(robot, False))


def _config(robot: RobotModel, midpoints: bool) -> SolverConfig:
    return SolverConfig(**robot.mapping.solver, self_midpoints=midpoints, human_leg_share=0.0)


@pytest.fixture(scope="module")
def solved(sit_down) -> dict[bool, Solution]:
    """The solutions without and with the midpoint term."""
    robot, targets = sit_down
    return {on: solve(robot, targets, _config(robot, on)) for on in (False, True)}


def _qpos(sol: Solution) -> np.ndarray:
    quat = Rotation.from_matrix(sol.root_rot).as_quat()[:, [3, 0, 1, 2]]
    return np.concatenate([sol.root_pos, quat, sol.q], axis=1)


def _tunnels(robot: RobotModel, sol: Solution) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(frame t, pair, distance) of the capsule pairs apart at t and t + 1 (by more than the
    slack) but overlapping more than 1 cm halfway."""
    sc = robot.self_clearance
    poses = robot.tree.forward(sol.root_pos, sol.root_rot, sol.q)
    mid = midpoint_pairs(poses, sc, np.ones(len(sol.q) - 1, dtype=bool))
    deep = (mid.limit > 0) & (mid.dist < -0.01)
    return mid.frame[deep], mid.pair[deep], mid.dist[deep]


def test_the_hands_pass_through_the_hips_between_frames_without_the_term(sit_down, solved):
    robot, _ = sit_down
    sc = robot.self_clearance
    frames, pairs, _ = _tunnels(robot, solved[False])
    assert frames.size
    names = {robot.model.body(int(robot.capsules.body[sc.second[p]])).name for p in pairs}
    assert any("hip" in name for name in names), names
    # MuJoCo's geoms in the output frames halfway (40 fps: every other frame) overlap too
    qpos = _qpos(solved[False])
    halfway = resample_qpos(qpos, 20.0, 40.0, robot.lower, robot.upper)[2 * frames + 1]
    tunnel = sc.select_pairs(np.isin(np.arange(sc.num_pairs), pairs))
    assert penetration_depths(robot.model, robot.tree, halfway, tunnel).max() > OTHER_DEPTH
    # ... where the solver's own frames keep them apart
    assert penetration_depths(robot.model, robot.tree, qpos, tunnel).max() <= OTHER_DEPTH


def test_the_term_keeps_the_frames_in_between_clear(sit_down, solved):
    robot, _ = sit_down
    sol = solved[True]
    assert not _tunnels(robot, sol)[0].size
    between = resample_qpos(_qpos(sol), 20.0, 40.0, robot.lower, robot.upper)
    assert penetration_depths(robot.model, robot.tree, between, robot.self_clearance).max() <= OTHER_DEPTH


def test_only_pairs_that_keep_their_margin_at_both_frames_count(sit_down, solved):
    """Where a frame's own term acts, the midpoint is left alone (its gradient, one direction
    for both frames, could push the nearer frame's capsule into the other)."""
    robot, _ = sit_down
    sol, sc = solved[False], robot.self_clearance
    poses = robot.tree.forward(sol.root_pos, sol.root_rot, sol.q)
    mid = midpoint_pairs(poses, sc, np.ones(len(sol.q) - 1, dtype=bool))
    dist, _, _ = capsule_distances(poses, sc)
    assert mid.frame.size and np.any(dist < sc.margin)  # some pairs come inside their margin
    ends = np.minimum(dist[mid.frame, mid.pair], dist[mid.frame + 1, mid.pair])
    np.testing.assert_array_less(sc.margin[mid.pair] - 1e-12, ends)
    np.testing.assert_allclose(mid.limit, np.minimum(sc.margin[mid.pair], ends - MIDPOINT_SLACK))


def test_a_pair_that_does_not_move_between_frames_adds_nothing(sit_down, solved):
    """The same pose twice: the averaged capsules are the pose's own, and the limit (the ends'
    distance less the slack) is never reached, whatever the frame term says."""
    robot, _ = sit_down
    sol = solved[False]
    t = int(_tunnels(robot, sol)[0][0])
    poses = robot.tree.forward(sol.root_pos[[t, t]], sol.root_rot[[t, t]], sol.q[[t, t]])
    assert midpoint_pairs(poses, robot.self_clearance, np.array([True])).frame.size == 0
    assert midpoint_pairs(poses, robot.self_clearance, np.array([False])).frame.size == 0


@pytest.fixture(scope="module")
def window(sit_down, solved) -> tuple[MidpointClearanceCost, Configuration]:
    """The midpoint term on the deepest tunnelling pair alone with a margin of 0, over the 4
    frames around it: its limit there is that margin (the ends are further apart)."""
    robot, _ = sit_down
    sol = solved[False]
    frames, pairs, dist = _tunnels(robot, sol)
    deepest = int(np.argmin(dist))
    t, pair = int(frames[deepest]), int(pairs[deepest])
    w = np.arange(t - 1, t + 3)
    sc = robot.self_clearance.select_pairs(np.arange(robot.self_clearance.num_pairs) == pair)
    sc = replace(sc, margin=np.zeros(1), safe_margin=None)
    term = MidpointClearanceCost(sc, 100.0, np.zeros(len(w), dtype=int))
    cfg = Configuration.at(robot, sol.root_pos[w].copy(), sol.root_rot[w].copy(), sol.q[w].copy())
    close = term.evaluate(cfg).close
    assert close.frame.size and np.all(close.limit == sc.margin[close.pair])
    return term, cfg


def _moved(cfg: Configuration, d: np.ndarray) -> Configuration:
    return Configuration.at(
        cfg.robot, cfg.root_pos + d[:, 0:3], so3_exp(d[:, 3:6]) @ cfg.root_rot, cfg.q + d[:, 6:]
    )


def test_the_midpoint_gradient_matches_finite_differences(window):
    term, cfg = window
    value = term.evaluate(cfg)
    eq = NormalEquations(len(cfg.q), cfg.robot.tree.nv)
    term.linearise(cfg, value, eq)
    h, g = eq.finish(cfg)
    fd = np.zeros_like(g)
    for f in range(g.shape[0]):  # the term couples frames: one coordinate of one frame at a time
        for i in range(g.shape[1]):
            d = np.zeros_like(g)
            d[f, i] = EPS
            fd[f, i] = (
                term.evaluate(_moved(cfg, d)).cost.sum() - term.evaluate(_moved(cfg, -d)).cost.sum()
            ) / (4 * EPS)
    assert np.abs(fd).max() > 0
    np.testing.assert_allclose(g, fd, atol=1e-5 * np.abs(fd).max(), rtol=1e-3)


def test_the_frames_blocks_bound_the_coupled_gauss_newton_block(window):
    """Each frame's block is 2 w (J_f / 2)^T (J_f / 2): the block diagonal is at least the
    coupled Gauss-Newton Hessian w J^T J of the two frames (J = (J_t, J_t+1) / 2)."""
    term, cfg = window
    value = term.evaluate(cfg)
    close = value.close
    e = 0
    t = int(close.frame[e])
    eq = NormalEquations(len(cfg.q), cfg.robot.tree.nv)
    only = MidpointPairs(*(getattr(close, f.name)[[e]] for f in fields(MidpointPairs)))
    term.linearise(cfg, MidpointClearanceValue(value.cost, only), eq)
    h, _ = eq.finish(cfg)
    n = cfg.robot.tree.nv
    jac = np.zeros(2 * n)  # d(dist)/d(coordinates of t and t + 1), by finite differences
    for k in range(2 * n):
        d = np.zeros((len(cfg.q), n))
        d[t + k // n, k % n] = EPS
        dist = [midpoint_pairs(_moved(cfg, s * d).poses, term.clearance, term.coupled) for s in (1, -1)]
        hit = [m.dist[m.frame == t][0] for m in dist]
        jac[k] = (hit[0] - hit[1]) / (2 * EPS)
    coupled = term.weight * np.outer(jac, jac)
    block = np.zeros((2 * n, 2 * n))
    block[:n, :n], block[n:, n:] = h[t], h[t + 1]
    assert np.linalg.eigvalsh(block - coupled).min() > -1e-6 * np.abs(coupled).max()
    np.testing.assert_allclose(np.trace(block), 2 * np.trace(coupled), rtol=1e-3)
