"""``retarget_motion``: a human motion (HumanML3D joints, Y up) -> a robot qpos trajectory.

Pipeline: place the human in the world with :class:`controlmm.frames.HumanToWorld` (uniform
scale :func:`robot_scale`), build targets (:mod:`retarget.targets`), solve all frames at the
motion's rate (:mod:`retarget.solver`), resample to the requested rate
(:mod:`retarget.resample`) with pinned feet held between the solver's frames, lift frames
whose feet would touch below the floor, check the arms' self-clearance on the real geoms and
solve again with safe margins where they touch (:mod:`retarget.selfcheck`), solve again where
a joint turns faster than its speed limit (:mod:`retarget.speed_rungs`), solve again with the
body moved where the stance ankles' motors cannot hold the zero-moment point
(:mod:`retarget.balance`), and measure the result with MuJoCo (:mod:`retarget.metrics`).
"""

from __future__ import annotations

import functools
import time
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np
from scipy.ndimage import gaussian_filter1d, maximum_filter1d
from scipy.spatial.transform import Rotation
from threadpoolctl import ThreadpoolController

from controlmm.errors import ControlMMError, ShapeError
from controlmm.frames import HumanToWorld
from controlmm.motion import load_motion
from controlmm.motion.container import Motion, resample
from controlmm.motion.skeleton import FPS, NUM_JOINTS, check_metre_scale
from retarget.actuators import damped_speed_limits, joint_speed_limits
from retarget.balance import (
    FIT_GIVE as BALANCE_FIT_GIVE,
    GOAL as BALANCE_GOAL,
    HELD_BY_MODEL,
    SLIDE_SPEED as BALANCE_SLIDE_SPEED,
    ankle_hinges,
    ankle_load,
    balance_shift,
    floor_slide,
    shift_human,
)
from retarget.calibrated_margins import CALIBRATED_SOLVES, calibrated_margins
from retarget.feet import hold_feet_between_frames
from retarget.human import size_ratio
from retarget.mapping import Mapping
from retarget.metrics import Replay, foot_steps, geom_lowest_z, replay, replay_keypoints, trajectory_metrics
from retarget.mink_ik import solve_mink
from retarget.resample import resample_qpos
from retarget.robot_model import RobotModel, load_robot
from retarget.selfcheck import (
    BALL_MARGIN,
    CHECK_DEPTH,
    EXACT_SELF,
    EXACT_TIGHTENINGS,
    OTHER_DEPTH,
    OUTPUT_FAR_DEPTH,
    OUTPUT_FIT_GIVE,
    OUTPUT_LIFT,
    OUTPUT_NEAR_GIVE,
    OUTPUT_SELF,
    OUTPUT_SLIP,
    OUTPUT_SPEED,
    RELAX_FRACTION,
    RELAX_MOST,
    RELAXED_SOLVES,
    RETRY_DEPTH,
    contact_balls,
    overlap_frames,
    overlap_gaps,
    penetration_depths,
    unpaired_overlaps,
)
from retarget.selfcollision import SelfClearance
from retarget.solver import Solution, solve
from retarget.solver_config import SolverConfig
from retarget.speed_rungs import SPEED_SOLVES, speed_gain, speed_ratios
from retarget.swing_lift import lift_swing_feet
from retarget.targets import Targets, build_targets, stiffer_locks
from retarget.trajectory import RobotTrajectory

SOLVERS = ("batched", "mink")
FPS_RANGE = (1.0, 1000.0)
"""Allowed output frame rates (Hz)."""

RobotSpec = str | Path | Mapping | RobotModel


def robot_scale(robot: RobotSpec = "g1") -> float:
    """The uniform human -> robot scale used to place the human in the world.

    Use it as ``HumanToWorld(scale=robot_scale(robot), yaw=..., translation=(x, y, 0))``.
    It is the robot's rest hip height above its soles divided by the HumanML3D skeleton's
    standing hip height (0.876 m), unless the mapping file fixes ``scale``.
    """
    return float(load_robot(robot).scale)


def _motion_arrays(
    motion: Motion | np.ndarray | str | Path, check_scale: bool = True
) -> tuple[np.ndarray, float, dict[str, Any]]:
    """(joints (T, 22, 3) float64, fps, source info) from a Motion, an array or a file."""
    if isinstance(motion, (str, Path)):
        path = str(motion)
        motion = load_motion(motion)
        info: dict[str, Any] = {"path": path}
    else:
        info = {}
    if isinstance(motion, Motion):
        joints, fps = motion.joints, motion.fps
        info.setdefault("path", motion.metadata.get("source"))
        if motion.text:
            info["text"] = motion.text
    else:
        joints, fps = np.asarray(motion), float(FPS)
    joints = np.asarray(joints)
    if joints.ndim != 3 or joints.shape[1:] != (NUM_JOINTS, 3):
        raise ShapeError(f"motion joints must have shape (T, {NUM_JOINTS}, 3); got {joints.shape}")
    if joints.shape[0] < 1:
        raise ShapeError("the motion has no frames")
    if not np.all(np.isfinite(joints)):
        raise ShapeError("motion joints contain NaN/inf values")
    if check_scale:
        check_metre_scale(joints, f"motion '{info['path']}'" if info.get("path") else "motion")
    if not (np.isfinite(fps) and fps > 0):
        raise ShapeError(f"motion fps must be a positive number; got {fps}")
    info.update({"fps": float(fps), "frames": int(joints.shape[0])})
    return joints.astype(np.float64), float(fps), info


def check_fps(fps: float) -> float:
    """The output rate as float, or a one-line error naming the allowed range."""
    try:
        value = float(fps)
    except (TypeError, ValueError):
        raise ControlMMError(f"fps must be a number; got {fps!r}") from None
    lo, hi = FPS_RANGE
    if not (np.isfinite(value) and lo <= value <= hi):
        raise ControlMMError(f"fps {fps} is out of range; allowed {lo:g} to {hi:g} frames per second")
    return value


def lift_above_floor(robot: RobotModel, qpos: np.ndarray, fps: float) -> tuple[np.ndarray, Replay, float]:
    """Raise the root where the lowest collision point (feet, knees, hands) is below z = 0.

    The needed lift is max-filtered then smoothed over ~0.1 s (a smoothed max-filter never
    falls below the need), so the correction is smooth. Returns (qpos, its MuJoCo replay,
    largest lift in m).
    """
    rep = replay(robot.model, qpos)
    m = robot.model
    geoms = robot.feet["left"].geoms + robot.feet["right"].geoms
    # Every other collision geom whose bounding sphere reaches below the floor in some frame
    # (a kneeling knee, a hand on the ground): the solver keeps them SolverConfig.body_clearance
    # above it with a stiff but finite weight, and the spline resampling may dip between frames.
    others = [
        g
        for g in range(m.ngeom)
        if g not in geoms
        and (m.geom_contype[g] or m.geom_conaffinity[g])
        and m.body_rootid[m.geom_bodyid[g]] == m.body_rootid[robot.tree.node_body[robot.feet["left"].node]]
        and np.any(rep.geom_xpos[:, g, 2] - m.geom_rbound[g] < 0.0)
    ]
    need = np.maximum(-geom_lowest_z(m, rep, list(geoms) + others).min(axis=1), 0.0)
    if not np.any(need > 0):
        return qpos, rep, 0.0
    r = max(1, int(round(0.05 * fps)))
    lift = maximum_filter1d(need, size=4 * r + 1, mode="nearest")
    lift = gaussian_filter1d(lift, sigma=r / 2.0, mode="nearest", truncate=4.0)
    lift = np.maximum(lift, need)
    out = qpos.copy()
    out[:, 2] += lift
    # A root translation moves every body and geom by the same amount.
    rep.xpos[..., 2] += lift[:, None]
    rep.geom_xpos[..., 2] += lift[:, None]
    return out, rep, float(lift.max())


def _solve_and_resample(
    rm: RobotModel,
    targets: Targets,
    config: SolverConfig,
    solver: str,
    src_fps: float,
    fps: float,
    init: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None,
) -> tuple[Solution, np.ndarray, np.ndarray, Replay, float, float]:
    """Solve at the motion's rate (from ``init``, (root_pos, root_rot, q) at that rate, where
    given: :func:`retarget.solver.solve`), resample to ``fps`` with pinned feet held, lift swing
    feet and anything below the floor: (solution, its qpos, output qpos, its replay, floor
    lift, swing lift)."""
    sol = solve_mink(rm, targets) if solver == "mink" else solve(rm, targets, config, init)
    quat = Rotation.from_matrix(sol.root_rot).as_quat()[:, [3, 0, 1, 2]]
    qpos_in = np.concatenate([sol.root_pos, quat, sol.q], axis=1)
    qpos = resample_qpos(qpos_in, src_fps, fps, rm.lower, rm.upper)
    if fps != src_fps:
        qpos[:, 7:] = hold_feet_between_frames(rm, targets, src_fps, qpos_in, qpos, fps)
    times = np.arange(len(qpos)) / fps
    src_times = np.arange(len(qpos_in)) / src_fps
    clearance = {side: np.interp(times, src_times, targets.clearance[side]) for side in ("left", "right")}
    root_rot = Rotation.from_quat(qpos[:, [4, 5, 6, 3]]).as_matrix()
    qpos[:, 7:], swing_lift = lift_swing_feet(rm, qpos[:, :3], root_rot, qpos[:, 7:], clearance, fps)
    if rm.couplings is not None:  # the MJCF's joint equalities exactly (the solver kept them closely)
        qpos[:, 7:] = rm.couplings.project(qpos[:, 7:], rm.lower, rm.upper)
    qpos, rep, lift = lift_above_floor(rm, qpos, fps)
    return sol, qpos_in, qpos, rep, lift, swing_lift


def _solve_clear_of_self(
    rm: RobotModel, targets: Targets, config: SolverConfig, solver: str, src_fps: float, fps: float
) -> tuple[Solution, np.ndarray, Replay, float, float, int, SelfClearance | None, SelfClearance | None]:
    """:func:`_solve_and_resample` with the arms' self-clearance relaxed where the robot's
    enclosures are loose (:mod:`retarget.selfcheck`): a first solve lets them come closer,
    MuJoCo checks the real geoms, pairs that overlap get more room for another solve (from
    scratch: one from the last poses can jump where a pair's margin changed); still
    overlapping after RELAXED_SOLVES solves, or deeper than RETRY_DEPTH anywhere, the safe
    margins everywhere (a solve from scratch), checked in turn: pairs still overlapping more
    than OTHER_DEPTH get that much more room for a last solve (:func:`_solve_relaxed`); the
    solve kept is solved again from where it is with its loose pairs' margins calibrated on its
    real geoms (:func:`_calibrated_solve`). A robot without loose enclosures starts from the
    safe margins (selfcheck.EXACT_TIGHTENINGS), and pairs of geoms found overlapping that it
    does not keep apart are added (selfcheck.unpaired_overlaps).
    Returns (solution, output qpos, its replay, floor lift, swing lift, solves, the
    self-clearance in use with any pairs added, None without one, and with exact enclosures
    the clearance the kept solve was tightened to, else None: the room the output check's
    stiffer solves start from)."""
    clearance = _clearance_in_use(rm, config, solver)
    if clearance is None:
        sol, _, qpos, rep, lift, swing_lift = _solve_and_resample(rm, targets, config, solver, src_fps, fps)
        return sol, qpos, rep, lift, swing_lift, 1, clearance, None
    if clearance.looseness is None or not np.any(clearance.looseness > 0):
        # Exact enclosures (capsules, boxes): the safe margins at once; pairs whose geoms still
        # overlap (Apollo's thick thighs in a turn) get that much more room and the clearance
        # a stiffer weight for another solve, EXACT_TIGHTENINGS times at most.
        # A tightened solve that overlaps deeper than the one before (it settled elsewhere:
        # the CMU humanoid crouching 50 cm on the real clip) is not kept.
        # Geoms the anatomy's pairs leave alone but that overlap (a free ball wrist folding a
        # hand into its forearm) get a pair of their own from then on (unpaired_overlaps).
        tight, solves, cfg = clearance, 1, config
        best: tuple[Solution, np.ndarray, Replay, float, float] | None = None
        deepest, best_tight = np.inf, clearance
        while True:
            sol, qpos_in, qpos, rep, lift, swing_lift = _solve_and_resample(
                rm.with_self_clearance(tight), targets, cfg, solver, src_fps, fps
            )
            if solves <= EXACT_TIGHTENINGS:  # a solve follows: pairs found now are kept in it
                first_new, second_new, margin_new = unpaired_overlaps(
                    rm.model, rm.tree, qpos_in, clearance, rm.rest
                )
                if first_new.size:
                    clearance = clearance.with_pairs(first_new, second_new, margin_new)
                    tight = tight.with_pairs(first_new, second_new, margin_new)
                    deepest = np.inf  # the solves before did not count those pairs
            depth = penetration_depths(rm.model, rm.tree, qpos_in, clearance)
            if best is not None and depth.max(initial=0.0) >= deepest:
                return (*best, solves, clearance, best_tight)
            best, deepest, best_tight = (sol, qpos, rep, lift, swing_lift), depth.max(initial=0.0), tight
            if solves > EXACT_TIGHTENINGS or not np.any(depth > OTHER_DEPTH):
                return (*best, solves, clearance, best_tight)
            tight, solves = tight.tightened(depth, OTHER_DEPTH), solves + 1
            cfg = replace(config, w_self=config.w_self * EXACT_SELF)
    sol, qpos_in, qpos, rep, lift, swing_lift, solves, used = _solve_relaxed(
        rm, clearance, targets, config, solver, src_fps, fps
    )
    calibrated, tries = _calibrated_solve(rm, used, sol, qpos_in, targets, config, solver, src_fps, fps)
    if calibrated is not None:
        sol, _, qpos, rep, lift, swing_lift = calibrated
    return sol, qpos, rep, lift, swing_lift, solves + tries, clearance, None


def _solve_relaxed(
    rm: RobotModel,
    clearance: SelfClearance,
    targets: Targets,
    config: SolverConfig,
    solver: str,
    src_fps: float,
    fps: float,
) -> tuple[Solution, np.ndarray, np.ndarray, Replay, float, float, int, SelfClearance]:
    """The solves of :func:`_solve_clear_of_self` for a robot with loose enclosures, from the
    relaxed margins to the safe ones (see there). Returns (solution, its qpos, output qpos,
    its replay, floor lift, swing lift, solves, the self-clearance of the solve kept)."""
    first = clearance.relaxed(RELAX_FRACTION, RELAX_MOST)
    # Pairs brought closer may overlap CHECK_DEPTH; the others as much as with the safe margins.
    assert first.safe_margin is not None
    tolerance = np.where(first.margin < first.safe_margin, CHECK_DEPTH, OTHER_DEPTH)
    for solves in range(1, RELAXED_SOLVES + 1):
        sol, qpos_in, qpos, rep, lift, swing_lift = _solve_and_resample(
            rm.with_self_clearance(first), targets, config, solver, src_fps, fps
        )
        # Checked at the solver's frames (the output's in-between frames move a few mrad).
        depth = penetration_depths(rm.model, rm.tree, qpos_in, first)
        if not np.any(depth > tolerance):
            return sol, qpos_in, qpos, rep, lift, swing_lift, solves, first
        if depth.max() > RETRY_DEPTH:
            break  # arms pressed into the body (hands on the knees): the safe margins at once
        first = first.tightened(depth, tolerance)
    sol, qpos_in, qpos, rep, lift, swing_lift = _solve_and_resample(rm, targets, config, solver, src_fps, fps)
    # The safe margins are soft too: pairs whose geoms still overlap get that much more room.
    depth = penetration_depths(rm.model, rm.tree, qpos_in, clearance)
    if not np.any(depth > OTHER_DEPTH):
        return sol, qpos_in, qpos, rep, lift, swing_lift, RELAXED_SOLVES + 1, clearance
    last = clearance.tightened(depth, OTHER_DEPTH)
    sol, qpos_in, qpos, rep, lift, swing_lift = _solve_and_resample(
        rm.with_self_clearance(last), targets, config, solver, src_fps, fps
    )
    return sol, qpos_in, qpos, rep, lift, swing_lift, RELAXED_SOLVES + 2, last


def _calibrated_solve(
    rm: RobotModel,
    used: SelfClearance,
    sol: Solution,
    qpos_in: np.ndarray,
    targets: Targets,
    config: SolverConfig,
    solver: str,
    src_fps: float,
    fps: float,
) -> tuple[tuple[Solution, np.ndarray, np.ndarray, Replay, float, float] | None, int]:
    """``sol`` (its qpos ``qpos_in`` at the motion's rate, solved with ``used``) solved again
    from where it is with the margins calibrated on its real geoms
    (:mod:`retarget.calibrated_margins`), ``config.calibrated_iterations`` iterations; where
    its geoms overlap deeper than the check allows (at its output frames, the trunk-shoulder
    pairs added where they overlap there), once more with those pairs' safe margins back.
    Returns (what :func:`_solve_and_resample` returns for the solve kept, or None where
    none is kept: none calibrated, overlapping or no lower cost; the solves made)."""
    closer = (
        calibrated_margins(rm.model, rm.tree, qpos_in, used) if config.calibrated_iterations > 0 else None
    )
    if closer is None:
        return None, 0
    cfg = replace(config, max_iterations=config.calibrated_iterations)
    init = (sol.root_pos, sol.root_rot, sol.q)
    for solves in range(1, CALIBRATED_SOLVES + 1):
        out = _solve_and_resample(rm.with_self_clearance(closer), targets, cfg, solver, src_fps, fps, init)
        # Checked at the output frames, with the trunk against the shoulder links where those
        # press together (the safe margins leave those pairs out: G1 with hands sitting down,
        # the shoulder in the torso in 24 output frames, was then solved again by the output
        # check into a motion its wrist motors could not carry).
        closer = _with_relaxed_pairs(rm, out[2], closer)
        if closer.safe_margin is None:  # the robot's own relaxed pairs, at their safe margins
            closer = replace(closer, safe_margin=closer.margin)
        depth = penetration_depths(rm.model, rm.tree, out[2], closer)
        tolerance = np.where(closer.margin < closer.safe_margin, CHECK_DEPTH, OTHER_DEPTH)
        if not np.any(depth > tolerance):
            return (out if out[0].cost < sol.cost else None), solves
        closer = closer.tightened(depth, tolerance)
    return None, CALIBRATED_SOLVES


def _stance_slip(rm: RobotModel, rep: Replay, targets: Targets, fps: float) -> float:
    """Largest horizontal step (m) of a foot's slowest floor point between two output frames
    (``rep``, at ``fps``) in both of which the human stands on that foot (``targets.stance``):
    a foot that stays down may pivot on its heel or toe, not slide."""
    frames = len(rep.xpos)
    near = np.clip(
        np.rint(np.arange(frames) / fps * targets.fps).astype(int), 0, len(targets.stance["left"]) - 1
    )
    worst = 0.0
    for side in ("left", "right"):
        step = foot_steps(rm, rep, side)  # (T - 1,)
        down = targets.stance[side][near]
        both = down[1:] & down[:-1]
        if both.any():
            worst = max(worst, float(step[both].max()))
    return worst


def _clearance_in_use(rm: RobotModel, config: SolverConfig, solver: str) -> SelfClearance | None:
    """The robot's self-clearance where the solve keeps it (None: none, switched off, mink)."""
    return rm.self_clearance if config.self_clearance and solver != "mink" else None


def _with_unpaired(rm: RobotModel, qpos: np.ndarray, clearance: SelfClearance) -> SelfClearance:
    """``clearance`` with a pair for each two geoms found overlapping in ``qpos`` (T, nq) that it
    does not keep apart and that are apart at rest (:func:`retarget.selfcheck.unpaired_overlaps`)."""
    first, second, margin = unpaired_overlaps(rm.model, rm.tree, qpos, clearance, rm.rest)
    return clearance.with_pairs(first, second, margin) if first.size else clearance


def _rung_kept(
    depth: np.ndarray,
    slip: float,
    depth2: np.ndarray,
    slip2: float,
    midpoint: bool,
    speed: np.ndarray | None = None,
    speed2: np.ndarray | None = None,
    frames: int | None = None,
    frames2: int | None = None,
    lift: float | None = None,
    lift2: float | None = None,
) -> bool:
    """Whether the output check keeps a new solve (its pairs' deepest overlaps ``depth2`` (P2,)
    m, its largest planted-foot step ``slip2`` m and its joints' top speeds ``speed2``
    (nj,) rad/s) over the one it has (``depth`` (P,), ``slip``, ``speed``): it overlaps less
    deep, slides no foot further than that one and than ``OUTPUT_SLIP`` and turns no joint
    faster than that one and than ``OUTPUT_SPEED``, and has no more output frames in which
    two geoms overlap deeper than ``OUTPUT_FAR_DEPTH`` (``frames2`` against ``frames``:
    a shallower overlap spread over more frames fails more of ``controlmm validate``;
    Kuavo's thighs on the real clip, 3 frames -> 57), and is lifted off the floor no more
    than that one (``lift2`` against ``lift``, m) and than ``OUTPUT_LIFT``; the midpoint
    solve, which is to remove sweeps between frames, also brings no pair deeper than before
    and than ``OTHER_DEPTH`` (the pairs of both in the same order, those beyond either's last
    counted from 0: each solve's check adds the geoms it finds overlapping unpaired, so the
    new one may have fewer: DRC-Hubo's real clip had ``controlmm retarget`` fail)."""
    kept = depth2.max(initial=0.0) < depth.max(initial=0.0) and slip2 <= max(slip, OUTPUT_SLIP)
    if speed is not None and speed2 is not None:
        kept = kept and bool(np.all((speed2 <= speed) | (speed2 <= OUTPUT_SPEED)))
    if frames is not None and frames2 is not None:
        kept = kept and frames2 <= frames
    if lift is not None and lift2 is not None:
        kept = kept and lift2 <= max(lift, OUTPUT_LIFT)
    if midpoint:
        before = np.zeros(len(depth2))
        common = min(len(depth), len(depth2))
        before[:common] = depth[:common]
        kept = kept and bool(np.all(depth2 <= np.maximum(before, OTHER_DEPTH)))
    return kept


def _joint_speeds(qpos: np.ndarray, fps: float) -> np.ndarray:
    """(nj,) each joint's top speed (rad/s, m/s for a slide) between frames of ``qpos`` (T, nq)."""
    q = np.asarray(qpos)[:, 7:]
    return np.abs(np.diff(q, axis=0)).max(axis=0, initial=0.0) * fps


def _with_contact_balls(
    rm: RobotModel, qpos: np.ndarray, clearance: SelfClearance, inside_rest_overlap: bool = False
) -> SelfClearance:
    """``clearance`` with balls held where two of its pairs' geoms overlap in ``qpos`` (T, nq)
    and an enclosure does not see it (:func:`retarget.selfcheck.contact_balls`)."""
    node, centre, radius, geom = contact_balls(
        rm.model, rm.tree, qpos, clearance, inside_rest_overlap=inside_rest_overlap
    )
    return clearance.with_balls(node, centre, radius, geom, BALL_MARGIN) if len(node) else clearance


def _with_relaxed_pairs(rm: RobotModel, qpos: np.ndarray, clearance: SelfClearance) -> SelfClearance:
    """``clearance`` with the pairs only its relaxed solves keep (the trunk against the shoulder
    links, calibrated on the real geoms: ``relaxed_pairs``) where the output ``qpos`` (T, nq)
    overlaps on one of them deeper than ``OTHER_DEPTH``: the safe margins alone may leave a
    shoulder in the torso (G1 with hands sitting down: 2 cm), and the output check then
    solves again with them. A clearance grown since (balls, pairs added, tightened) no longer
    carries them: the robot's own relaxed pairs that overlap so are added to it, one by one
    (the robot's capsules keep their indices in every clearance grown from its own). Unitree
    R1's upper arm ended 8.9 mm in its torso in a stoop (corpus clip 000000), unseen by the
    rungs, whose ladders had balls."""
    kept = set(zip(clearance.first.tolist(), clearance.second.tolist(), strict=True))
    full = clearance.relaxed_pairs
    own = full is None
    if own:
        full = None if rm.self_clearance is None else rm.self_clearance.relaxed_pairs
    if full is None:
        return clearance
    extra = np.array(
        [pair not in kept for pair in zip(full.first.tolist(), full.second.tolist(), strict=True)]
    )
    depth = penetration_depths(rm.model, rm.tree, qpos, full.select_pairs(extra), every_frame=True)
    if not own:
        return full if np.any(depth > OTHER_DEPTH) else clearance
    deep = np.flatnonzero(extra)[depth > OTHER_DEPTH]
    return (
        clearance.with_pairs(full.first[deep], full.second[deep], full.margin[deep])
        if deep.size
        else clearance
    )


def _output_overlap(rm: RobotModel, qpos: np.ndarray, clearance: SelfClearance | None) -> np.ndarray:
    """(P,) deepest overlap (m, 0 for none) of each pair of the robot's real geoms that
    ``clearance`` keeps apart, over the output frames ``qpos`` (T, nq); empty without one."""
    if clearance is None:
        return np.zeros(0)
    return penetration_depths(rm.model, rm.tree, qpos, clearance, every_frame=True)


@dataclass
class _Solved:
    """A solve as the output check weighs it: its solution, output qpos (T, nq) and replay,
    floor and swing lifts (m), the targets it was solved for, its pairs' deepest overlaps
    (P,) m, its planted feet's largest step (m, :func:`_stance_slip`), its joints' top
    speeds (nj,) rad/s (:func:`_joint_speeds`) and its frames with an overlap deeper than
    OUTPUT_FAR_DEPTH (selfcheck.overlap_frames)."""

    sol: Solution
    qpos: np.ndarray
    rep: Replay
    lift: float
    swing_lift: float
    targets: Targets
    depth: np.ndarray
    slip: float
    speed: np.ndarray
    frames: int


def _weighed(
    rm: RobotModel,
    clearance: SelfClearance,
    sol: Solution,
    qpos: np.ndarray,
    rep: Replay,
    lift: float,
    swing_lift: float,
    targets: Targets,
    fps: float,
) -> tuple[_Solved, SelfClearance]:
    """A rung's solve (output ``qpos`` (T, nq) at ``fps``) as the output check weighs it, and
    the clearance it is measured with: ``clearance`` with the trunk-shoulder pairs and the
    unpaired geoms it overlaps on (:func:`_with_relaxed_pairs`, :func:`_with_unpaired`)."""
    measured = _with_unpaired(rm, qpos, _with_relaxed_pairs(rm, qpos, clearance))
    depth, slip = _output_overlap(rm, qpos, measured), _stance_slip(rm, rep, targets, fps)
    speed, frames = _joint_speeds(qpos, fps), overlap_frames(rm.model, qpos)
    return _Solved(sol, qpos, rep, lift, swing_lift, targets, depth, slip, speed, frames), measured


def _kept_over(best: _Solved, new: _Solved, midpoint: bool, speed: bool = True) -> bool:
    """:func:`_rung_kept` of ``new`` over ``best`` (``speed`` False: its joints' speeds not weighed)."""
    return _rung_kept(
        best.depth,
        best.slip,
        new.depth,
        new.slip,
        midpoint,
        best.speed if speed else None,
        new.speed if speed else None,
        best.frames,
        new.frames,
        best.lift,
        new.lift,
    )


def _gives_up_a_pass(depth: np.ndarray, error: float, error2: float) -> bool:
    """Whether a solve whose keypoints end ``error2`` (m, mean) from their targets would give up
    the motion for the last millimetres of the one kept (``depth`` (P,) m: its pairs' deepest
    overlaps, within OUTPUT_FAR_DEPTH: it passes ``controlmm validate``; ``error`` m): further
    than selfcheck.OUTPUT_NEAR_GIVE beyond it."""
    return depth.max(initial=0.0) <= OUTPUT_FAR_DEPTH and error2 > error + OUTPUT_NEAR_GIVE


def _keypoint_error(rm: RobotModel, rep: Replay, reference: np.ndarray) -> float:
    """Mean distance (m) of the robot's keypoints in the frames of ``rep`` to ``reference``
    (T, K, 3), the targets at the output rate."""
    return float(np.linalg.norm(replay_keypoints(rm, rep) - reference, axis=-1).mean())


def _output_rungs(
    rm: RobotModel,
    config: SolverConfig,
    solver: str,
    transform: HumanToWorld,
    joints: np.ndarray,
    fps: float,
    clearance: SelfClearance,
    best: _Solved,
    solves: int,
    room: SelfClearance | None = None,
) -> tuple[_Solved, int, SelfClearance]:
    """Solve again where the output frames of ``best`` overlap deeper than ``OTHER_DEPTH``:
    first at the motion's rate (``joints`` (T, 22, 3) at ``best.targets.fps``) with the pairs
    kept apart halfway between its frames too (retarget.midpoints: a hand sweeping through a
    hip between two of them; skipped where the solve had that already), then at the output
    rate with a stiffer self-clearance (selfcheck.OUTPUT_SELF), each rung solved with the
    planted feet as they were and, unless that one is kept clear of every pair, with their
    locks as stiff as the self-clearance (:func:`retarget.targets.stiffer_locks`: the arms and
    trunk give way, not the feet). A solve is kept if it overlaps less, slips no more than the
    one kept (selfcheck.OUTPUT_SLIP), is lifted off the floor no more (selfcheck.OUTPUT_LIFT)
    and its keypoints stay within
    selfcheck.OUTPUT_FIT_GIVE of the first solve's distance to the targets; a solve that
    clears every pair but gives up more of the motion is kept only where none clears within
    it and the closer one kept overlaps deeper than selfcheck.OUTPUT_FAR_DEPTH. Pairs that
    still overlap after an output-rate rung get that much more room for the next, counted from
    where their capsules were in the frame of the deepest overlap (selfcheck.overlap_gaps).
    The output frames are replayed in MuJoCo every one (their capsules may be far outside a
    margin calibrated on a sweep where the geoms overlap). With ``room`` (the clearance the
    solves before were tightened to, pairs in the same order), each output-rate rung solves a
    third time, plainly, on a ladder of its own that starts from at least those margins:
    ToddlerBot's elbow, 5.3 mm in its box chest in a carry, came back 25 mm deep from the safe
    margins (28 frames over 5 mm; 0 from that room), while from that room the CMU humanoid's
    feet slid in a crouch that the safe ladder clears. Where two geoms touch while their
    enclosures, which overlap at rest, lie inside their (negative) margin, each output-rate rung
    also solves twice (plainly and with the stiffer locks) on a "held" ladder that keeps balls
    there (selfcheck.contact_balls, ``inside_rest_overlap``) and gives its room to the balls,
    not to those enclosures (``SelfClearance.tightened``, ``keep_seen``): Kuavo's hip
    cylinders in corpus clip 000015, 5.45 mm deep in 9 frames after the safe ladder's three
    rungs, clear on the x30 rung. Returns (the solve kept, solves so far, the self-clearance of
    the safe ladder with any pairs added)."""
    dense = resample(joints, best.targets.fps, fps)
    dense_targets = build_targets(rm, dense, fps, transform, config)  # the output rate's
    if best.targets.speed_gain is not None:  # the speed rungs' gains, at the output's frames
        near = np.clip(np.rint(np.arange(len(dense)) / fps * best.targets.fps).astype(int), 0, None)
        gain = best.targets.speed_gain[np.minimum(near, len(best.targets.speed_gain) - 1)]
        dense_targets = replace(dense_targets, speed_gain=gain)
    reference = dense_targets.kp_pos  # (T, K, 3)
    most_error = _keypoint_error(rm, best.rep, reference) + OUTPUT_FIT_GIVE
    far_but_clear: _Solved | None = None  # kept only if no solve clears within OUTPUT_FIT_GIVE
    too_fast: list[tuple[SolverConfig, Targets, SelfClearance, np.ndarray, bool]] = []
    rungs: list[float | None] = [*([] if config.self_midpoints else [None]), *OUTPUT_SELF]
    # each tightened by its own plain solve, with balls where enclosures miss a contact
    ladders: dict[str, SelfClearance] = {"safe": _with_contact_balls(rm, best.qpos, clearance)}
    if ladders["safe"] is not clearance:  # the balls' pairs count too
        best.depth = _output_overlap(rm, best.qpos, ladders["safe"])
    held = _with_contact_balls(rm, best.qpos, clearance, inside_rest_overlap=True)
    if held.balls > ladders["safe"].balls and held.seen_by_balls().any():  # blind enclosures
        ladders["held"] = held
    plain: dict[str, np.ndarray] = {}
    plain_qpos: dict[str, np.ndarray] = {}
    gaps: dict[str, np.ndarray] = {}
    for stiffness in rungs:
        if stiffness is not None and room is not None:
            roomier, room = _with_room(ladders["safe"], room), None
            if roomier is not None:
                ladders["room"] = roomier
        if stiffness is None:  # the midpoint rung: the motion's own frames
            candidates = [(replace(config, self_midpoints=True), best.targets, "safe", True)]
        else:
            cfg2 = replace(config, w_self=config.w_self * stiffness)
            stiff_targets = stiffer_locks(rm, dense_targets, stiffness)
            candidates = [
                (cfg2, dense_targets, "safe", True),
                (cfg2, stiff_targets, "safe", False),
                *([(cfg2, dense_targets, "room", True)] if "room" in ladders else []),
                *(
                    [(cfg2, dense_targets, "held", True), (cfg2, stiff_targets, "held", False)]
                    if "held" in ladders
                    else []
                ),
            ]
        for cfg2, targets2, ladder, is_plain in candidates:
            sol2, _, qpos2, rep2, lift2, swing_lift2 = _solve_and_resample(
                rm.with_self_clearance(ladders[ladder]), targets2, cfg2, solver, targets2.fps, fps
            )
            solves += 1
            # Pairs found overlapping are kept apart from then on; those the stiff-lock solve
            # finds count in its own check only (the rungs go on as they would without it).
            solved, measured = _weighed(
                rm, ladders[ladder], sol2, qpos2, rep2, lift2, swing_lift2, targets2, fps
            )
            if is_plain:
                ladders[ladder], plain[ladder], plain_qpos[ladder] = measured, solved.depth, qpos2
                gaps[ladder] = overlap_gaps(rm.model, rm.tree, qpos2, measured)
            midpoint = stiffness is None
            kept = _kept_over(best, solved, midpoint)
            if not kept and _kept_over(best, solved, midpoint, speed=False):
                too_fast.append((cfg2, targets2, ladders[ladder], qpos2, midpoint))  # a last resort (below)
            if not kept:
                continue
            clear = solved.depth.max() <= OTHER_DEPTH
            error2 = _keypoint_error(rm, rep2, reference)
            if error2 > most_error:  # gives up the motion
                far_but_clear = far_but_clear or (solved if clear else None)
                continue
            if _gives_up_a_pass(best.depth, _keypoint_error(rm, best.rep, reference), error2):
                continue
            best = solved
            if clear:
                return best, solves, ladders["safe"]
        if stiffness is not None:  # the output-rate rungs go on as they would without it:
            for ladder in ladders:  # the plain solves' pairs get more room (balls, on "held")
                blind = ladder == "held"
                tight = ladders[ladder].tightened(plain[ladder], OTHER_DEPTH, gaps[ladder], keep_seen=blind)
                ladders[ladder] = _with_contact_balls(
                    rm, plain_qpos[ladder], tight, inside_rest_overlap=blind
                )
    # Rungs refused for their speed alone, where every rung left geoms deeper than
    # OUTPUT_FAR_DEPTH in some output frame and none cleared them further from the motion:
    # each solved again with its too-fast joints slower (_slower_rung) and weighed as the
    # rungs are, until one is kept clear.
    last_resort = config.speed_limits and far_but_clear is None
    for cfg2, targets2, ladder_clearance, qpos2, midpoint in too_fast if last_resort else []:
        if best.frames == 0:
            break
        allowed = np.maximum(best.speed, OUTPUT_SPEED)
        slower = _slower_rung(rm, ladder_clearance, targets2, cfg2, solver, fps, qpos2, allowed)
        if slower is None:
            continue
        sol2, qpos2, rep2, lift2, swing_lift2, targets2, n = slower
        solves += n
        solved, _ = _weighed(rm, ladder_clearance, sol2, qpos2, rep2, lift2, swing_lift2, targets2, fps)
        if _kept_over(best, solved, midpoint) and _keypoint_error(rm, rep2, reference) <= most_error:
            best = solved
    clearance = ladders["safe"]
    if far_but_clear is not None and best.depth.max(initial=0.0) > OUTPUT_FAR_DEPTH:
        return far_but_clear, solves, clearance
    return best, solves, clearance


def _solve_checked(
    rm: RobotModel,
    targets: Targets,
    config: SolverConfig,
    solver: str,
    transform: HumanToWorld,
    joints: np.ndarray,
    fps: float,
) -> tuple[_Solved, int]:
    """Solve ``targets`` (at the motion's rate; ``joints`` (T, 22, 3) the motion) clear of self
    (:func:`_solve_clear_of_self`) and, where the output frames still overlap, through the
    output check (:func:`_output_rungs`). Returns (the solve kept, solves made)."""
    src_fps = targets.fps
    sol, qpos, rep, lift, swing_lift, solves, clearance, room = _solve_clear_of_self(
        rm, targets, config, solver, src_fps, fps
    )
    out = _Solved(sol, qpos, rep, lift, swing_lift, targets, np.zeros(0), 0.0, _joint_speeds(qpos, fps), 0)
    if clearance is not None:
        clearance = _with_unpaired(rm, qpos, _with_relaxed_pairs(rm, qpos, clearance))
        out.depth = _output_overlap(rm, qpos, clearance)
        if out.depth.max(initial=0.0) > OTHER_DEPTH:
            out.slip = _stance_slip(rm, rep, targets, fps)
            out.frames = overlap_frames(rm.model, qpos)
            out, solves, _ = _output_rungs(
                rm, config, solver, transform, joints, fps, clearance, out, solves, room
            )
    return out, solves


def _speed_limits(rm: RobotModel) -> np.ndarray:
    """(nj,) each joint's speed limit (rad/s): its published one
    (:func:`retarget.actuators.joint_speed_limits`, which ``controlmm validate`` checks), or the
    speed at which its damping alone takes its whole motor where that is lower (Apollo's torso
    yaw: 0.6 rad/s; past it ``validate`` fails the torque the motion needs)."""
    return np.minimum(joint_speed_limits(rm.tree.joint_names), damped_speed_limits(rm.damping_share))


def _speed_rungs(
    rm: RobotModel,
    targets: Targets,
    config: SolverConfig,
    solver: str,
    transform: HumanToWorld,
    joints: np.ndarray,
    fps: float,
    kept: _Solved,
) -> tuple[_Solved, int]:
    """Solve again where ``kept`` turns a joint past its speed limit between two output frames
    (:mod:`retarget.speed_rungs`): that joint's velocity weight SPEED_STEP times stiffer around
    there, up to SPEED_SOLVES times, each time through the whole self-clearance check
    (:func:`_solve_checked`: a solve with other velocity weights may bring two links together
    that the first one's check kept apart); a solve is kept if it is slower against the
    limits at its worst, has no more output frames with two geoms overlapping deeper than
    OUTPUT_FAR_DEPTH and slides no planted foot further than ``kept`` and OUTPUT_SLIP.
    ``targets``: the motion's, at its rate. Returns (the solve kept, solves made)."""
    limits = _speed_limits(rm)
    ratios = speed_ratios(kept.qpos, fps, limits)
    if ratios.max(initial=0.0) <= 1.0:
        return kept, 0
    frames = overlap_frames(rm.model, kept.qpos)
    slip = _stance_slip(rm, kept.rep, kept.targets, fps)
    gain, solves, last = None, 0, ratios
    for _ in range(SPEED_SOLVES):  # each step from the last solve's speeds, kept or not
        if last.max(initial=0.0) <= 1.0:
            break
        gain = speed_gain(last, fps, len(targets.kp_pos), targets.fps, gain)
        out, n = _solve_checked(rm, replace(targets, speed_gain=gain), config, solver, transform, joints, fps)
        solves += n
        last = speed_ratios(out.qpos, fps, limits)
        frames2, slip2 = overlap_frames(rm.model, out.qpos), _stance_slip(rm, out.rep, out.targets, fps)
        if last.max() >= ratios.max() or frames2 > frames or slip2 > max(slip, OUTPUT_SLIP):
            continue
        kept, ratios, frames, slip = out, last, frames2, slip2
    return kept, solves


def _balanced(
    rm: RobotModel,
    config: SolverConfig,
    solver: str,
    transform: HumanToWorld,
    joints: np.ndarray,
    src_fps: float,
    fps: float,
    kept: _Solved,
) -> tuple[_Solved, int]:
    """Solve again with the body moved where ``kept`` loads its stance ankles past their
    motors (:mod:`retarget.balance`, over TRIGGER): the human's joints (``joints``, at
    ``src_fps``) but the feet moved by the accumulated shift, through the self-clearance and
    speed checks, up to ``config.balance_iterations`` times, each shift from the last solve's
    load while it is over GOAL. A solve is kept if its sustained load is lower, it has no more
    output frames with two geoms overlapping deeper than OUTPUT_FAR_DEPTH, slides no planted
    foot further than ``kept`` and OUTPUT_SLIP, slides no foot on the floor faster than
    ``kept`` and BALANCE_SLIDE_SPEED (:func:`retarget.balance.floor_slide`: the check's stance
    is the robot's own), turns no joint further past its speed limit (unless
    ``config.speed_limits`` is off) and keeps its keypoints within BALANCE_FIT_GIVE of as close
    to the unmoved targets as ``kept``; the first solve stays where the one kept still loads
    the ankles over HELD_BY_MODEL. Returns (the solve kept, solves made)."""
    ankles = ankle_hinges(rm)
    load = ankle_load(rm, ankles, kept.rep, fps)
    shift = balance_shift(rm, load, fps)
    if shift is None:
        return kept, 0
    worst = float(load.sustained.max(initial=0.0))
    limits = _speed_limits(rm)
    speed = max(1.0, float(speed_ratios(kept.qpos, fps, limits).max(initial=0.0)))
    frames = overlap_frames(rm.model, kept.qpos)
    slip = _stance_slip(rm, kept.rep, kept.targets, fps)
    slide = max(floor_slide(rm, kept.rep, load), BALANCE_SLIDE_SPEED / fps)
    reference = build_targets(rm, resample(joints, src_fps, fps), fps, transform, config).kp_pos
    most_error = _keypoint_error(rm, kept.rep, reference) + BALANCE_FIT_GIVE
    total = np.zeros((len(kept.qpos), 2))
    solves = 0
    first = kept
    for i in range(config.balance_iterations):  # each shift from the last solve's load
        shift = balance_shift(rm, load, fps, BALANCE_GOAL) if i else shift
        if shift is None:
            break
        total = total + shift
        moved = shift_human(joints, src_fps, total, fps, transform)
        targets = build_targets(rm, moved, src_fps, transform, config)
        out, n = _solve_checked(rm, targets, config, solver, transform, moved, fps)
        solves += n
        if config.speed_limits:
            out, n = _speed_rungs(rm, targets, config, solver, transform, moved, fps, out)
            solves += n
        load = ankle_load(rm, ankles, out.rep, fps)
        worst2 = float(load.sustained.max(initial=0.0))
        frames2, slip2 = overlap_frames(rm.model, out.qpos), _stance_slip(rm, out.rep, out.targets, fps)
        speed2 = float(speed_ratios(out.qpos, fps, limits).max(initial=0.0))
        if (
            worst2 >= worst
            or frames2 > frames
            or slip2 > max(slip, OUTPUT_SLIP)
            or (config.speed_limits and speed2 > speed)
            or floor_slide(rm, out.rep, load) > slide
            or _keypoint_error(rm, out.rep, reference) > most_error
        ):
            continue
        kept, worst, frames, slip = out, worst2, frames2, slip2
    return (kept if worst <= HELD_BY_MODEL else first), solves


def _slower_rung(
    rm: RobotModel,
    clearance: SelfClearance,
    targets: Targets,
    config: SolverConfig,
    solver: str,
    fps: float,
    qpos: np.ndarray,
    allowed: np.ndarray,
) -> tuple[Solution, np.ndarray, Replay, float, float, Targets, int] | None:
    """A rung's solve (output ``qpos`` (T, nq)) again with the velocity weight of each joint
    faster than ``allowed`` (nj,) rad/s SPEED_STEP times stiffer there (as the speed rungs do,
    :mod:`retarget.speed_rungs`), up to SPEED_SOLVES times, until none is: (solution, output
    qpos, replay, floor lift, swing lift, targets, solves), or None. Apollo lying down (the
    corpus's lie-down 000052 at 30 fps): the x10 rung cleared its thighs (9.9 -> 1.0 mm) but
    turned a hip at 10.6 rad/s and was refused. Tried only once every rung has been, where the
    one kept still fails the check and no rung cleared it further from the motion (G1 with
    hands sitting down, corpus clip 000012, ends with such a one, 6.4 cm from its targets, and
    passes `controlmm validate`; a slower solve 4.4 cm from them left a wrist 1 % past its
    torque limit, which the rungs do not weigh)."""
    gain = targets.speed_gain
    for solves in range(1, SPEED_SOLVES + 1):
        gain = speed_gain(speed_ratios(qpos, fps, allowed), fps, len(targets.kp_pos), targets.fps, gain)
        targets = replace(targets, speed_gain=gain)
        sol, _, qpos, rep, lift, swing_lift = _solve_and_resample(
            rm.with_self_clearance(clearance), targets, config, solver, targets.fps, fps
        )
        if speed_ratios(qpos, fps, allowed).max(initial=0.0) <= 1.0:
            return sol, qpos, rep, lift, swing_lift, targets, solves
    return None


def _with_room(clearance: SelfClearance, room: SelfClearance) -> SelfClearance | None:
    """``clearance`` with each of the pairs it shares with ``room`` (its first pairs, in the
    same order) kept at least as far apart as there; None where that keeps none further apart
    (or the pairs differ): a ladder from it would repeat the safe one."""
    n = len(room.first)
    same = (
        len(clearance.first) >= n
        and np.array_equal(clearance.first[:n], room.first)
        and np.array_equal(clearance.second[:n], room.second)
    )
    if not same or not np.any(room.margin > clearance.margin[:n]):
        return None
    margin = clearance.margin.copy()
    margin[:n] = np.maximum(margin[:n], room.margin)
    return replace(clearance, margin=margin)


def retarget_motion(
    motion: Motion | np.ndarray | str | Path,
    robot: RobotSpec = "g1",
    fps: float = 50.0,
    transform: HumanToWorld | None = None,
    config: SolverConfig | None = None,
    metrics: bool = True,
    solver: str = "batched",
    check_scale: bool = True,
) -> RobotTrajectory:
    """Retarget a human motion to a robot.

    Args:
        motion: a :class:`Motion`, joints (T, 22, 3) (metres, Y up, 20 fps) or a motion file.
        robot: packaged robot name (``g1``, ``h1``), a mapping ``.json`` path or a Mapping.
        fps: output frame rate (Hz), 1 to 1000.
        transform: where the human is placed in the world; default
            ``HumanToWorld(scale=robot_scale(robot) * size_ratio(joints))`` (start at the origin
            facing +X; :func:`retarget.human.size_ratio`: 1 for a human on the HumanML3D
            skeleton, the ratio of the leg lengths for a recorded subject).
        config: solver settings (default: ``SolverConfig`` with the mapping's ``solver`` overrides).
        metrics: measure the result with MuJoCo (see :mod:`retarget.metrics`).
        check_scale: refuse joints that do not look like a person in metres (a centimetre file,
            say) with a one-line error; a generator's own output may skip it.
        solver: ``"batched"`` (default: all frames at once, :mod:`retarget.solver`) or
            ``"mink"`` (per-frame differential IK, :mod:`retarget.mink_ik`; optional packages).

    Returns:
        A :class:`RobotTrajectory` (qpos in MuJoCo order at ``fps``).
    """
    with _blas_controller().limit(limits=1, user_api="blas"):
        return _retarget(motion, robot, fps, transform, config, metrics, solver, check_scale)


@functools.lru_cache(maxsize=1)
def _blas_controller() -> ThreadpoolController:
    return ThreadpoolController()


def _retarget(motion, robot, fps, transform, config, metrics, solver, check_scale) -> RobotTrajectory:
    # Small dense/banded linear algebra: BLAS threads only add synchronisation (and on a
    # busy machine their spinning slows the solve many times), so one thread is used.
    start = time.perf_counter()
    fps = check_fps(fps)
    if solver not in SOLVERS:
        raise ControlMMError(f"unknown solver '{solver}'; allowed: {', '.join(SOLVERS)}")
    rm = load_robot(robot)
    joints, src_fps, info = _motion_arrays(motion, check_scale)
    transform = transform if transform is not None else HumanToWorld(scale=rm.scale * size_ratio(joints))
    config = config if config is not None else SolverConfig(**rm.mapping.solver)
    targets = build_targets(rm, joints, src_fps, transform, config)
    human_world, human_fps = targets.human_world, targets.fps  # the unmoved human (balance)
    out, solves = _solve_checked(rm, targets, config, solver, transform, joints, fps)
    speed_solves = balance_solves = 0
    if solver != "mink" and config.speed_limits:
        out, speed_solves = _speed_rungs(rm, targets, config, solver, transform, joints, fps, out)
    if solver != "mink" and config.balance_iterations > 0:
        out, balance_solves = _balanced(rm, config, solver, transform, joints, src_fps, fps, out)
    sol, qpos, rep, lift, swing_lift, targets = (
        out.sol,
        out.qpos,
        out.rep,
        out.lift,
        out.swing_lift,
        out.targets,
    )
    times = np.arange(len(qpos)) / fps
    near = np.clip(np.rint(times * targets.fps).astype(int), 0, len(targets.stance["left"]) - 1)
    stance = np.stack([targets.stance["left"][near], targets.stance["right"][near]], axis=1)
    method = {
        "batched": "whole-sequence Levenberg-Marquardt (banded)",
        "mink": "mink per-frame differential IK",
    }
    solver_info = {
        "method": method[solver],
        "iterations": sol.iterations,
        "cost": round(sol.cost, 6) if np.isfinite(sol.cost) else None,
        "solve_seconds": round(sol.seconds, 4),
        "floor_lift_max_mm": round(lift * 1000, 3),
        "swing_lift_max_mm": round(swing_lift * 1000, 3),
        "self_clearance_solves": solves,
        "speed_limit_solves": speed_solves,
        "balance_solves": balance_solves,
    }
    traj = RobotTrajectory(
        robot=str(rm.mapping.robot if rm.mapping.source.startswith("packaged:") else rm.mapping.source),
        fps=fps,
        qpos=qpos,
        joint_names=list(rm.tree.joint_names),
        scale=transform.scale,
        transform=transform,
        stance=stance,
        source=info,
        solver=solver_info,
        model=rm,
    )
    if metrics:
        traj.metrics = trajectory_metrics(rm, qpos, fps, human_world, human_fps, rep=rep)
    traj.solver["total_seconds"] = round(time.perf_counter() - start, 4)
    return traj
