"""The solver's cost terms one by one, on a real G1 model and a real kneeling motion.

Each term's analytic linearisation must match finite differences of its own cost: the
gradient ``J^T r`` (half the cost's gradient) for every term, the Gauss-Newton block
``J^T J`` against the finite-difference Jacobian of the term's weighted residuals, and the
temporal terms' constant banded Hessian against the exact Hessian of their quadratic cost.
The solver's cost must be the sum of its terms. The configuration is the solved kneel clip
around the knee touching down, where every term is active (feet and knee near the floor,
arms close to the thighs).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from controlmm.corpus import make_clip
from controlmm.corpus.dataset import ClipSpec
from controlmm.frames import HumanToWorld
from controlmm.motion import Motion
from retarget.costs import (
    AccelerationCost,
    BodyFloorCost,
    Configuration,
    CostTerm,
    FloorCost,
    KeypointCost,
    MidpointClearanceCost,
    NormalEquations,
    OrientationCost,
    PostureCost,
    SegmentCost,
    SelfClearanceCost,
    TermValue,
    VelocityCost,
)
from retarget.kinematics import so3_exp, so3_log
from retarget.problem import Problem
from retarget.robot_model import RobotModel, load_robot
from retarget.solver import _solve, solve
from retarget.solver_config import SolverConfig
from retarget.targets import Targets, build_targets, take_frames

FRAMES = np.arange(26, 42)
"""Frames of the kneel clip where the knee reaches the floor and the arms come close to the legs."""
EPS = 1e-6


@pytest.fixture(scope="module")
def kneel() -> tuple[RobotModel, Targets, tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """G1, the targets of the corpus' kneel clip and its solved configuration."""
    robot = load_robot("g1")
    feats, _, _, _ = make_clip(ClipSpec(0, "000000", "kneel", "train", seed=31))
    motion = Motion.from_features(feats)
    targets = build_targets(
        robot, motion.joints.astype(np.float64), motion.fps, HumanToWorld(scale=robot.scale)
    )
    sol = solve(robot, targets, SolverConfig(pin_iterations=0))
    return robot, targets, (sol.root_pos, sol.root_rot, sol.q)


@pytest.fixture(scope="module")
def window(kneel) -> tuple[Problem, Configuration]:
    """The problem of FRAMES and its configuration (the solution, joints nudged off their limits)."""
    robot, targets, (pos, rot, q) = kneel
    sub = take_frames(targets, FRAMES, targets.fps)
    prob = Problem(robot, sub, SolverConfig())
    rng = np.random.default_rng(0)
    q = np.clip(q[FRAMES] + rng.normal(0.0, 0.02, q[FRAMES].shape), robot.lower + 0.01, robot.upper - 0.01)
    return prob, Configuration.at(robot, pos[FRAMES].copy(), rot[FRAMES].copy(), q)


def moved(cfg: Configuration, d: np.ndarray) -> Configuration:
    """``cfg`` moved by velocity coordinates d (T, n), as the solver applies a step."""
    return Configuration.at(
        cfg.robot, cfg.root_pos + d[:, 0:3], so3_exp(d[:, 3:6]) @ cfg.root_rot, cfg.q + d[:, 6:]
    )


def linearised(term: CostTerm, cfg: Configuration) -> tuple[TermValue, np.ndarray, np.ndarray]:
    """The term's value and its own blocks h (T, n, n) and gradient g (T, n) at ``cfg``."""
    value = term.evaluate(cfg)
    eq = NormalEquations(len(cfg.q), cfg.robot.tree.nv)
    term.linearise(cfg, value, eq)
    h, g = eq.finish(cfg)
    return value, h, g


def weighted_residual(term: CostTerm, cfg: Configuration, value: TermValue) -> np.ndarray:
    """(T, m) the residuals whose squares make the term's per-frame cost."""
    t = len(cfg.q)
    if isinstance(term, KeypointCost):
        return (np.sqrt(term.weight)[..., None] * value.res).reshape(t, -1)
    if isinstance(term, SegmentCost):
        return (np.sqrt(term.weight)[None, :, None] * value.res).reshape(t, -1)
    if isinstance(term, FloorCost):
        return value.res.reshape(t, -1)
    if isinstance(term, PostureCost):
        return np.sqrt(term.weight) * (cfg.q - term.rest)
    if isinstance(term, BodyFloorCost):
        return np.sqrt(term.weight) * value.low
    raise TypeError(type(term).__name__)


def frame_terms(prob: Problem) -> list[CostTerm]:
    return [term for term in prob.terms if not term.couples_frames]


def test_the_window_activates_every_term(window):
    prob, cfg = window
    names = [term.name for term in prob.terms]
    assert names == [
        "keypoints",
        "segments",
        "orientations",
        "floor",
        "posture",
        "body_floor",
        "self_clearance",
        "velocity",
        "acceleration",
    ]
    for term in prob.terms:
        value = term.evaluate(cfg)
        assert value.cost.shape == (len(FRAMES),)
        assert value.cost.sum() > 0, term.name
    assert np.any(prob.terms[3].evaluate(cfg).active)  # feet below their clearance
    assert (prob.terms[5].evaluate(cfg).low < 0).sum() >= 2  # a knee or a shin on the floor
    assert prob.terms[6].evaluate(cfg).close.frame.size >= 2  # capsule pairs within their margin


def test_frame_term_gradients_match_finite_differences(window):
    prob, cfg = window
    t, n = len(cfg.q), cfg.robot.tree.nv
    for term in frame_terms(prob):
        if isinstance(term, OrientationCost):
            # Gauss-Newton on SO(3): the error's Jacobian is taken at zero error (d log(R R*^T)
            # = d theta), so the gradient is exact for small errors: move the targets close.
            rng = np.random.default_rng(1)
            current = cfg.poses.rot[:, term.nodes]
            near = so3_exp(rng.normal(0.0, 1e-4, current.shape[:-1])) @ current
            term = OrientationCost(cfg.robot, replace(prob.targets, ori_rot=near), prob.config.l_rot)
        _, _, g = linearised(term, cfg)
        fd = np.zeros((t, n))
        for i in range(n):  # frame terms do not couple frames: one coordinate in every frame at once
            d = np.zeros((t, n))
            d[:, i] = EPS
            fd[:, i] = (term.evaluate(moved(cfg, d)).cost - term.evaluate(moved(cfg, -d)).cost) / (4 * EPS)
        scale = np.abs(fd).max()
        np.testing.assert_allclose(g, fd, atol=1e-5 * scale, rtol=1e-3, err_msg=term.name)


def test_frame_term_blocks_are_jacobian_products(window):
    prob, cfg = window
    t, n = len(cfg.q), cfg.robot.tree.nv
    for term in frame_terms(prob):
        if isinstance(term, SelfClearanceCost):  # its rows come and go with the close pairs
            continue
        value, h, g = linearised(term, cfg)
        if isinstance(term, OrientationCost):
            # the residual's Jacobian at zero error: the weighted angular displacement of the nodes
            r = value.res.reshape(t, -1)

            def residual(c: Configuration, term: OrientationCost = term) -> np.ndarray:
                turn = c.poses.rot[:, term.nodes] @ np.swapaxes(cfg.poses.rot[:, term.nodes], -1, -2)
                return (term.sqrt_weight * so3_log(turn)).reshape(t, -1)
        else:
            r = weighted_residual(term, cfg, value)

            def residual(c: Configuration, term: CostTerm = term) -> np.ndarray:
                return weighted_residual(term, c, term.evaluate(c))

        np.testing.assert_allclose(np.sum(r * r, axis=1), value.cost, rtol=1e-12, err_msg=term.name)
        jac = np.zeros((t, r.shape[1], n))
        for i in range(n):
            d = np.zeros((t, n))
            d[:, i] = EPS
            jac[:, :, i] = (residual(moved(cfg, d)) - residual(moved(cfg, -d))) / (2 * EPS)
        jt = np.swapaxes(jac, 1, 2)
        scale = np.abs(h).max()
        np.testing.assert_allclose(h, jt @ jac, atol=1e-5 * scale, rtol=1e-4, err_msg=term.name)
        np.testing.assert_allclose(
            g, (jt @ r[..., None])[..., 0], atol=1e-5 * np.abs(g).max(), err_msg=term.name
        )


def test_self_clearance_rows_match_capsule_distances(window):
    prob, cfg = window
    term = next(term for term in prob.terms if isinstance(term, SelfClearanceCost))
    value, _, g = linearised(term, cfg)
    close = value.close
    # one close entry per frame: its gradient row is sqrt(w) J times its residual
    frames, counts = np.unique(close.frame, return_counts=True)
    single = frames[counts == 1]
    assert single.size
    for f in single:
        e = int(np.flatnonzero(close.frame == f)[0])
        pair = int(close.pair[e])
        res = close.dist[e] - term.clearance.margin[pair]
        fd = np.zeros(g.shape[1])
        for i in range(g.shape[1]):
            d = np.zeros_like(g)
            d[f, i] = EPS
            dists = []
            for sign in (1, -1):
                near = term.evaluate(moved(cfg, sign * d)).close
                hit = (near.frame == f) & (near.pair == pair)
                dists.append(float(near.dist[hit][0]))
            fd[i] = (dists[0] - dists[1]) / (2 * EPS)
        np.testing.assert_allclose(g[f], term.weight * res * fd, atol=1e-6 * np.abs(g[f]).max())


def temporal_x(cfg: Configuration) -> np.ndarray:
    return np.concatenate([cfg.root_pos, cfg.root_unwrapped, cfg.q], axis=1)


def with_x(cfg: Configuration, x: np.ndarray) -> Configuration:
    """``cfg`` with its temporal values x (T, n) replaced (the temporal terms read only x)."""
    return replace(cfg, root_pos=x[:, :3], root_unwrapped=x[:, 3:6], q=x[:, 6:])


@pytest.mark.parametrize("exact", [True, False])
def test_temporal_terms_gradient_and_band(window, exact):
    prob, cfg = window
    t, n = len(cfg.q), cfg.robot.tree.nv
    span = np.repeat([0, 1], [t // 2, t - t // 2])  # two independent spans: no coupling across
    terms = [
        VelocityCost(prob.ref_x, span, 20.0, 0.5, 0.1),
        AccelerationCost(prob.ref_x, span, 20.0, 100.0, 5.0, exact=exact),
    ]
    x0 = temporal_x(cfg)
    for term in terms:
        _, h, g = linearised(term, cfg)
        assert not h.any()  # their Hessian is the constant band
        fd = np.zeros((t, n))
        hess = np.zeros((t * n, t * n))
        for k in range(t * n):
            d = np.zeros(t * n)
            d[k] = EPS
            cost = [term.evaluate(with_x(cfg, x0 + s * d.reshape(t, n))).cost.sum() for s in (1, -1)]
            fd.reshape(-1)[k] = (cost[0] - cost[1]) / (4 * EPS)
            grads = []
            for s in (1, -1):
                eq = NormalEquations(t, n)
                term.linearise(with_x(cfg, x0 + s * d.reshape(t, n)), TermValue(np.zeros(t)), eq)
                grads.append(eq.g.reshape(-1))
            hess[:, k] = (grads[0] - grads[1]) / (2 * EPS)
        np.testing.assert_allclose(g, fd, atol=1e-6 * np.abs(fd).max(), err_msg=term.name)
        d0, d1, d2 = np.zeros((t, n)), np.zeros((t - 1, n)), np.zeros((t - 2, n))
        term.add_band(d0, d1, d2)
        band = np.diag(d0.reshape(-1)) + np.diag(d1.reshape(-1), n) + np.diag(d1.reshape(-1), -n)
        if term.lag == 2:
            band += np.diag(d2.reshape(-1), 2 * n) + np.diag(d2.reshape(-1), -2 * n)
        assert np.all(hess[: t // 2 * n, t // 2 * n :] == 0)  # the spans do not couple
        if exact or isinstance(term, VelocityCost):
            np.testing.assert_allclose(band, hess, atol=1e-6 * np.abs(hess).max(), err_msg=term.name)
        else:  # lag-2 couplings moved onto the diagonal: an upper bound of the Hessian
            assert term.lag == 1
            assert not np.allclose(band, hess)
            assert np.linalg.eigvalsh(band - hess).min() > -1e-6 * np.abs(hess).max()


def test_solver_cost_is_the_sum_of_its_terms(kneel):
    robot, targets, _ = kneel
    config = SolverConfig(levels=(), max_iterations=3, extra_iterations=0, pin_iterations=0)
    sol, (prob, st) = _solve(robot, targets, config, None)
    per_term = prob.term_costs(st)
    assert set(per_term) == {term.name for term in prob.terms}
    assert sol.cost == pytest.approx(sum(per_term.values()), rel=1e-12)
    frame_part = sum(v.cost for term, v in zip(prob.terms, st.values, strict=True) if not term.couples_frames)
    np.testing.assert_allclose(st.frame_cost, frame_part, rtol=1e-12)
    assert st.span_cost.sum() == pytest.approx(st.cost, rel=1e-12)
    again = Problem(robot, targets, config).evaluate(sol.root_pos, sol.root_rot, sol.q)
    assert again.cost == pytest.approx(sol.cost, rel=1e-9)
    # the normal equations are the sum of each term's own contribution
    h, g = prob.normal_equations(st)
    h_sum, g_sum = np.zeros_like(h), np.zeros_like(g)
    for term in prob.terms:
        _, h_t, g_t = linearised(term, st.cfg)
        h_sum += h_t
        g_sum += g_t
    np.testing.assert_allclose(h, h_sum, rtol=1e-10, atol=1e-10 * np.abs(h).max())
    np.testing.assert_allclose(g, g_sum, rtol=1e-10, atol=1e-10 * np.abs(g).max())


def test_config_weights_reach_the_terms(kneel):
    robot, targets, _ = kneel
    base = Problem(robot, targets, SolverConfig())
    heavy = Problem(
        robot,
        targets,
        SolverConfig(w_floor=400.0, l_rot=0.4, w_self=25.0, body_floor=False, self_midpoints=True),
    )
    names = [term.name for term in heavy.terms]
    assert "body_floor" not in names
    by_name = {term.name: term for term in base.terms}
    heavy_by_name = {term.name: term for term in heavy.terms}
    assert heavy_by_name["floor"].root_weight == pytest.approx(2 * by_name["floor"].root_weight)
    np.testing.assert_allclose(
        heavy_by_name["orientations"].sqrt_weight, 2 * by_name["orientations"].sqrt_weight
    )
    assert heavy_by_name["self_clearance"].weight == 25.0
    assert heavy_by_name["self_clearance_midpoints"].weight == 25.0
    assert isinstance(heavy_by_name["self_clearance_midpoints"], MidpointClearanceCost)
    assert "self_clearance_midpoints" not in by_name  # only where asked for (retarget_motion's output check)
