"""Balance (``retarget/balance.py``): the ankle hinges and their motors on the packaged robots,
the cart-table shift, the human moved by it, and H1 on a generated step-over, whose push-offs
load its 40 N m ankles past their motors in ``controlmm validate`` until the body is moved."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from controlmm.corpus import CorpusConfig, make_clip, plan_clips
from controlmm.frames import HumanToWorld
from controlmm.motion import Motion
from controlmm.motion.skeleton import JOINT_INDEX
from retarget import load_robot, retarget_motion
from retarget.balance import G, ankle_hinges, ankle_load, balance_shift, shift_human
from retarget.compare import similarity_fit
from retarget.metrics import geom_lowest_z, replay
from retarget.solver_config import SolverConfig
from scenes import load_scene
from sim import check_trajectory

FPS = 30.0


@pytest.fixture(scope="module")
def step_over() -> np.ndarray:
    """The default corpus's third clip (a step over, 20 fps), HumanML3D joints (T, 22, 3)."""
    spec = next(itertools.islice(plan_clips(CorpusConfig(clips=9800, seed=0)), 2, None))
    assert spec.family == "step_over"
    return make_clip(spec)[1].astype(np.float64)


@pytest.mark.parametrize(("robot", "limits"), [("g1", [50.0, 50.0]), ("h1", [40.0]), ("t1", [20.0, 15.0])])
def test_the_ankle_hinges_are_found_with_their_motors(robot, limits):
    """G1's and T1's ankles have a pitch and a roll hinge, H1's a pitch only (its knee, 40 cm
    up, is not one of them); their limits are the MJCF's motors."""
    rm = load_robot(robot)
    ankles = ankle_hinges(rm)
    for side in ("left", "right"):
        names = [rm.model.joint(int(j)).name.lower() for j in ankles.joints[side]]
        assert all("ankle" in n for n in names), names
        np.testing.assert_allclose(sorted(ankles.limits[side]), sorted(limits))


def test_the_shift_moves_the_zero_moment_point_by_the_excess(step_over):
    """On H1's unbalanced step-over the load is over the trigger; the cart-table shift
    ``d - (z / g) d''`` cancels most of the excess over the supported frames; standing still
    (its reference pose on the floor) it needs none."""
    h1 = load_robot("h1")
    qpos = retarget_motion(
        Motion(joints=step_over.astype(np.float32), fps=20.0),
        "h1",
        fps=FPS,
        metrics=False,
        config=SolverConfig(**{**h1.mapping.solver, "balance_iterations": 0}),
    ).qpos
    load = ankle_load(h1, ankle_hinges(h1), replay(h1.model, qpos), FPS)
    assert load.sustained.max() > 1.0
    shift = balance_shift(h1, load, FPS)
    assert shift is not None and shift.shape == (len(qpos), 2)
    moved = shift.copy()
    moved[1:-1] -= (load.height / G) * (shift[2:] - 2 * shift[1:-1] + shift[:-2]) * FPS**2
    need = np.linalg.norm(load.excess, axis=1) > 0
    before = np.linalg.norm(load.excess[need], axis=1).mean()
    after = np.linalg.norm(moved[need] - load.excess[need], axis=1).mean()
    assert after < 0.5 * before, (before, after)

    still = np.tile(h1.model.qpos0, (20, 1))
    feet = list(h1.feet["left"].geoms) + list(h1.feet["right"].geoms)
    still[:, 2] -= geom_lowest_z(h1.model, replay(h1.model, still[:1]), feet).min() - 0.002
    standing = ankle_load(h1, ankle_hinges(h1), replay(h1.model, still), FPS)
    assert standing.supported.all() and standing.sustained.max() < 0.5
    assert balance_shift(h1, standing, FPS) is None


def test_the_human_is_moved_but_its_feet():
    """The shift moves the pelvis by itself in the world, the knees by half and the ankles and
    toes not at all, through the transform's scale and yaw."""
    rng = np.random.default_rng(0)
    joints = rng.normal(size=(10, 22, 3))
    transform = HumanToWorld(scale=0.8, yaw=0.7, translation=(1.0, 2.0, 0.0))
    shift = rng.normal(size=(10, 2)) * 0.05
    moved = shift_human(joints, 20.0, shift, 20.0, transform)
    delta = np.asarray(transform.to_world(moved)) - np.asarray(transform.to_world(joints))
    np.testing.assert_allclose(delta[:, JOINT_INDEX["pelvis"], :2], shift, atol=1e-12)
    np.testing.assert_allclose(delta[:, JOINT_INDEX["pelvis"], 2], 0.0, atol=1e-12)
    np.testing.assert_allclose(delta[:, JOINT_INDEX["left_knee"], :2], shift / 2, atol=1e-12)
    for name in ("left_ankle", "right_ankle", "left_foot", "right_foot"):
        np.testing.assert_allclose(delta[:, JOINT_INDEX[name]], 0.0, atol=1e-12)


def test_h1_balanced_passes_the_torque_check(step_over):
    """H1 on the step-over: unbalanced, ``controlmm validate``'s inverse dynamics (sim) needs
    more than its ankle motors for half a second; balanced, it passes, within a centimetre of
    the unbalanced fit to the human."""
    h1 = load_robot("h1")
    motion = Motion(joints=step_over.astype(np.float32), fps=20.0)
    runs = {}
    for iterations in (0, SolverConfig().balance_iterations):
        config = SolverConfig(**{**h1.mapping.solver, "balance_iterations": iterations})
        traj = retarget_motion(motion, "h1", fps=FPS, metrics=False, config=config)
        report = check_trajectory(load_scene("empty", robot="h1"), traj.qpos, FPS)
        fit = similarity_fit(h1, traj.qpos, FPS, step_over, 20.0).mean
        runs[iterations] = (report, fit, traj.solver["balance_solves"])
    (before, fit0, solves0), (after, fit1, solves1) = runs.values()
    assert solves0 == 0 and solves1 > 0
    assert before.stats["max_sustained_torque_ratio"] > 1.0
    assert "torque_limit" in before.stats["error_kinds"]
    assert after.stats["max_sustained_torque_ratio"] <= 1.0
    assert after.passed, after.stats["error_kinds"]
    assert fit1 < fit0 + 0.01
