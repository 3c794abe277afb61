"""Whole-sequence retargeting solver: box-constrained Levenberg-Marquardt over all frames.

Unknowns: for every frame t the floating base (position p_t, rotation R_t) and the joint
angles q_t. The cost is a sum of squares (metres unless noted), one term per class of
:mod:`retarget.costs` (weights in :class:`~retarget.solver_config.SolverConfig`)::

    sum_t  sum_k w_k(t) |p_k(t) - target_k(t)|^2                      keypoint positions
         + sum_s w_s |(p_child - p_parent)(t) - seg_s(t)|^2            segment vectors
         + sum_o w_o(t) l_rot^2 |a_o * log(R_o(t) R*_o(t)^T)|^2        orientations (a_o: tilt/heading)
         + w_floor sum_foot_points min(0, z - radius - clearance(t))^2   floor (1 mm stance, 16 mm swing)
         + sum_j w_j (l_posture (q_j - q_rest_j))^2                      posture prior
         + w_body sum_bodies min(0, z_lowest - body_clearance)^2         other bodies above the floor
         + w_self sum_pairs min(0, d - margin)^2                         self-clearance of capsule pairs
         + sum_c W_VEL_c |D1 x_c|^2 + W_ACC_c |D2 x_c|^2                 velocity / acceleration

Each iteration linearises every frame with analytic Jacobians (:mod:`retarget.kinematics`),
adds the temporal terms (which couple frame t with t +- 1 and t +- 2) and solves the normal
equations of all frames at once with a banded Cholesky factorisation
(:mod:`retarget.banded`). By default the lag-2 acceleration couplings are moved onto the
diagonal (an upper bound of the Hessian; the gradient stays exact), which halves the
bandwidth to 6 + nj and quarters the factorisation time.

* Joint limits are exact: joints on a bound whose gradient pushes outward are frozen; joints
  whose step would cross a bound are held at the bound and the step is solved again for
  the rest; every step is projected onto the box.
* Damping is per frame: frames are nearly independent, so each frame keeps the step only
  if its own cost drops, and its damping falls or rises on its own.
* Coarse to fine (``SolverConfig.levels``): every 3rd frame first, then all frames (which
  also keep the self-clearance halfway between frames, :mod:`retarget.midpoints`).
* Local refinement: frames where the stiff self-clearance / body-floor terms are still
  violated are solved again in padded spans. The spans form one problem with no temporal
  term between them (independent blocks of the banded system), each span accepting,
  stopping and giving up on its own exactly as if solved alone, at the cost of one
  linearisation and one factorisation per iteration for all of them.
* Stance feet are finally moved onto their locks with the legs' own joints
  (:mod:`retarget.feet`).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field, replace

import numpy as np

from retarget.feet import pin_stance_feet
from retarget.kinematics import so3_exp, so3_log
from retarget.problem import Problem, State
from retarget.reference import initial_guess
from retarget.robot_model import RobotModel
from retarget.solver_config import SolverConfig
from retarget.targets import Targets, take_frames

CONSTRAINT_TOLERANCE = 0.002
"""Capsule overlap or depth below the floor (m) that earns frames a local refinement."""
CROSS_TOLERANCE = 0.01
"""Joint-limit overshoot (rad) of a step above which the step is re-solved with those joints pinned."""


@dataclass
class Solution:
    """Solver output at the targets' frame rate.

    Attributes:
        root_pos: (T, 3); root_rot: (T, 3, 3); q: (T, nj) joint angles (within limits).
        iterations: LM iterations run; cost: final cost; seconds: wall time.
        history: cost per accepted iteration.
        damping: (T,) each frame's final Levenberg-Marquardt damping.
    """

    root_pos: np.ndarray
    root_rot: np.ndarray
    q: np.ndarray
    iterations: int
    cost: float
    seconds: float
    history: list[float] = field(default_factory=list)
    damping: np.ndarray | float = 0.0


def _subsample(targets: Targets, step: int) -> tuple[Targets, np.ndarray]:
    """Every ``step``-th frame of the targets (the last frame always kept)."""
    idx = np.unique(np.r_[np.arange(0, len(targets.kp_pos), step), len(targets.kp_pos) - 1])
    return take_frames(targets, idx, targets.fps / step), idx


def _upsample(
    sol_pos: np.ndarray, sol_rot: np.ndarray, sol_q: np.ndarray, idx: np.ndarray, dst: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Interpolate a solution known at frames ``idx`` to frames ``dst`` (linear / geodesic)."""
    seg = np.clip(np.searchsorted(idx, dst, side="right") - 1, 0, len(idx) - 2)
    w = np.clip((dst - idx[seg]) / (idx[seg + 1] - idx[seg]), 0.0, 1.0)[:, None]
    pos = sol_pos[seg] * (1 - w) + sol_pos[seg + 1] * w
    q = sol_q[seg] * (1 - w) + sol_q[seg + 1] * w
    delta = so3_log(sol_rot[seg + 1] @ np.swapaxes(sol_rot[seg], -1, -2))
    rot = so3_exp(delta * w) @ sol_rot[seg]
    return pos, rot, q


def solve(
    robot: RobotModel,
    targets: Targets,
    config: SolverConfig | None = None,
    init: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None,
) -> Solution:
    """Run the solver on ``targets``; see the module docstring.

    Coarse to fine (``config.levels``, without ``init``): each level solves every k-th frame
    for a few iterations and its interpolation starts the next level; the last level is
    every frame. ``config``: default ``SolverConfig()``.
    """
    config = config if config is not None else SolverConfig()
    start = time.perf_counter()
    n = len(targets.kp_pos)
    levels = [(k, it) for k, it in config.levels if k == 1 or n >= 4 * k] if init is None else []
    if not levels or levels[-1][0] != 1:
        levels.append((1, config.max_iterations))
    total, damping, prev = 0, config.damping, None
    for k, iters in levels:
        small, idx = _subsample(targets, k) if k > 1 else (targets, np.arange(n))
        if prev is not None:
            init = _upsample(*prev, idx)
        last = k == 1
        cfg = replace(
            config,
            max_iterations=iters,
            damping=damping,
            self_midpoints=config.self_midpoints and last,
            body_floor_weight=config.body_floor_weight
            if last
            else min(config.w_body_floor_coarse, config.body_floor_weight),
        )
        sol, final = _solve(robot, small, cfg, init, settle_steps=1 if last else config.coarse_settle_steps)
        total += sol.iterations
        damping = max(config.damping, float(np.median(sol.damping)))
        prev = (sol.root_pos, sol.root_rot, sol.q, idx)
    if config.extra_iterations > 0:
        total += _refine_violations(robot, config, sol, damping, *final)
    sol.iterations = total
    if config.pin_iterations > 0:
        sol.q = pin_stance_feet(robot, targets, sol.root_pos, sol.root_rot, sol.q, config.pin_iterations)
    sol.seconds = time.perf_counter() - start
    return sol


REFINE_PAD = 3
"""Frames added on each side of a violated span for its local refinement (2 of them pinned)."""
REFINE_PATIENCE = 2
"""Refused steps in a row after which a span of the local refinement gives up (a violation
the other terms hold in place, e.g. legs kept crossed by their targets, would otherwise
spend every extra iteration on raising the damping)."""


def violation_spans(bad: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The spans of the local refinement for violating frames ``bad`` (T,) bool: each run of
    them padded by REFINE_PAD, plus two pinned frames on each side (within the sequence).
    Returns (frames (F,), pinned (F,) bool, span id (F,)); empty when nothing is violated."""
    n = len(bad)
    grow = np.convolve(bad, np.ones(2 * REFINE_PAD + 1), mode="same") > 0
    padded = np.concatenate([[False], grow, [False]]).astype(int)
    edges = np.flatnonzero(np.diff(padded))
    spans = [(max(a - 2, 0), min(b + 2, n), a, b) for a, b in zip(edges[::2], edges[1::2], strict=True)]
    if not spans:
        return np.zeros(0, dtype=int), np.zeros(0, dtype=bool), np.zeros(0, dtype=int)
    idx = np.concatenate([np.arange(lo, hi) for lo, hi, _, _ in spans])
    pinned = np.concatenate([(np.arange(lo, hi) < a) | (np.arange(lo, hi) >= b) for lo, hi, a, b in spans])
    span = np.repeat(np.arange(len(spans)), [hi - lo for lo, hi, _, _ in spans])
    return idx, pinned, span


def _refine_violations(
    robot: RobotModel, config: SolverConfig, sol: Solution, damping: float, prob: Problem, st: State
) -> int:
    """More iterations where the stiff terms are still violated, on those frames only.

    Self-clearance and body-floor terms converge more slowly than the rest. The spans of
    frames violating them by more than CONSTRAINT_TOLERANCE (padded by REFINE_PAD) are solved
    again for ``extra_iterations`` iterations, as one small problem: the spans side by side
    with no temporal term between them, the two outer frames of each span pinned so the
    temporal terms join the span to the rest. ``prob``/``st``: the full-rate problem and its
    final state. Updates ``sol`` in place; returns the iterations spent.
    """
    idx, pinned, span = violation_spans(prob.frame_violation(st) > CONSTRAINT_TOLERANCE)
    if not len(idx):
        return 0
    sub = take_frames(prob.targets, idx, prob.targets.fps)
    cfg = replace(config, max_iterations=config.extra_iterations, extra_iterations=0, damping=damping)
    # Each frame starts from its own damping at the end of the full-rate solve.
    lam = np.maximum(np.asarray(sol.damping, dtype=float)[idx], damping)
    out, _ = _solve(
        robot,
        sub,
        cfg,
        (sol.root_pos[idx], sol.root_rot[idx], sol.q[idx]),
        pinned=pinned,
        ref_pos=prob.ref_x[idx, :3],
        span=span,
        damping=lam,
        patience=REFINE_PATIENCE,
        until_resolved=True,
    )
    sol.root_pos[idx], sol.root_rot[idx], sol.q[idx] = out.root_pos, out.root_rot, out.q
    return out.iterations


def _solve(
    robot: RobotModel,
    targets: Targets,
    config: SolverConfig,
    init: tuple[np.ndarray, np.ndarray, np.ndarray] | None,
    pinned: np.ndarray | None = None,
    ref_pos: np.ndarray | None = None,
    span: np.ndarray | None = None,
    damping: np.ndarray | None = None,
    patience: int | None = None,
    until_resolved: bool = False,
    settle_steps: int = 1,
) -> tuple[Solution, tuple[Problem, State]]:
    """Levenberg-Marquardt on one problem; ``pinned`` (T,) bool: frames held fixed;
    ``damping`` (T,): each frame's initial damping (default ``config.damping``);
    ``patience``: refused steps in a row after which a span gives up (default: until its
    damping explodes); ``until_resolved``: a span also stops once none of its frames
    violates the stiff terms by more than CONSTRAINT_TOLERANCE (the local refinement's aim);
    ``settle_steps``: accepted steps in a row that each lower a span's cost by less than
    ``config.tolerance`` after which it stops.

    ``span`` (T,) int: independent spans side by side (see :class:`~retarget.problem.Problem`). Each span
    accepts or refuses its step, stops and gives up on its own, exactly as if it were solved
    alone; the spans still running share the linearisations and banded solves, and the
    problem shrinks to them whenever spans stop. Returns the solution and the final
    (problem, state) of the spans running at the end (all of them when ``span`` is None).
    """
    start = time.perf_counter()
    prob = Problem(robot, targets, config, ref_pos=ref_pos, span=span)
    root_pos, root_rot, q = init if init is not None else initial_guess(robot, targets)
    lower, upper = robot.lower, robot.upper
    st = prob.evaluate(root_pos, root_rot, np.clip(q, lower, upper))
    out_pos, out_rot, out_q = st.root_pos.copy(), st.root_rot.copy(), st.q.copy()
    frames = np.arange(prob.t_len)  # rows of the current problem in the original one
    settled = 0.0  # cost of the spans that stopped
    history = [st.cost]
    # Levenberg-Marquardt with one damping per frame: frames are nearly independent, so
    # each keeps the step only if its own cost drops, and its damping adapts on its own.
    lam = np.full(prob.t_len, config.damping) if damping is None else np.array(damping, dtype=float)
    out_lam = lam.copy()
    hold = np.zeros(prob.t_len, dtype=bool) if pinned is None else np.asarray(pinned, dtype=bool).copy()
    refused = np.zeros(prob.n_spans, dtype=int)  # refused steps in a row, per span
    settling = np.zeros(prob.n_spans, dtype=int)  # accepted steps in a row that gained little
    iterations = 0
    need_linearise = True
    while iterations < config.max_iterations:
        iterations += 1
        sp = prob.span
        if need_linearise:
            h, g = prob.normal_equations(st)
            frozen = np.zeros_like(g, dtype=bool)
            frozen[:, 6:] = ((st.q <= lower + 1e-12) & (g[:, 6:] > 0)) | (
                (st.q >= upper - 1e-12) & (g[:, 6:] < 0)
            )
            frozen[hold] = True
        try:
            ab = prob.band.matrix(h, lam)
            step = prob.band.solve(ab, g, frozen)
            # Joints whose step crosses a limit stop at the limit; the others are solved
            # again with those steps fixed (skipped, per span, when the overshoot is tiny:
            # plain clip; a span left alone gets the same step again, the spans being
            # independent blocks of the system).
            qs = st.q + step[:, 6:]
            over = np.maximum(qs - upper, lower - qs)
            worst = prob.span_max(over.max(axis=1))
            if worst.max() > CROSS_TOLERANCE:
                cross = np.zeros_like(frozen)
                cross[:, 6:] = (over > 0) & (worst > CROSS_TOLERANCE)[sp][:, None]
                fixed_step = np.zeros_like(step)
                fixed_step[:, 6:] = np.clip(qs, lower, upper) - st.q
                step = prob.band.solve(ab, g, frozen | cross, fixed_step)
        except np.linalg.LinAlgError:
            lam *= 10
            need_linearise = False
            continue
        trial = prob.evaluate(
            st.root_pos + step[:, 0:3],
            so3_exp(step[:, 3:6]) @ st.root_rot,
            np.clip(st.q + step[:, 6:], lower, upper),
        )
        better = trial.frame_cost < st.frame_cost
        n_better = np.bincount(sp, better, prob.n_spans)
        n_frames = prob.span_frames
        # A span whose cost rose although some of its frames improved keeps only those frames.
        partial = (trial.span_cost >= st.span_cost) & (n_better > 0) & (n_better < n_frames)
        if partial.any():
            use = better | ~partial[sp]
            trial = prob.evaluate(
                np.where(use[:, None], trial.root_pos, st.root_pos),
                np.where(use[:, None, None], trial.root_rot, st.root_rot),
                np.where(use[:, None], trial.q, st.q),
            )
        accept = trial.span_cost < st.span_cost
        done = np.zeros(prob.n_spans, dtype=bool)
        if accept.any():
            little = accept & ((st.span_cost - trial.span_cost) < config.tolerance * st.span_cost)
            settling = np.where(accept, np.where(little, settling + 1, 0), settling)
            done = settling >= settle_steps
            st = trial if accept.all() else trial.select(accept[sp], st, accept)
            history.append(settled + st.cost)
            lam = np.where(accept[sp], np.where(better, np.maximum(lam / 3, 1e-9), lam * 10), lam * 10)
            need_linearise = True
            if until_resolved:
                done |= accept & (prob.span_max(prob.frame_violation(st), 0.0) <= CONSTRAINT_TOLERANCE)
        else:
            lam *= 10
            need_linearise = False
        # a span whose every frame's damping exploded, or out of patience, gives up
        refused = np.where(accept, 0, refused + 1)
        done |= ~accept & (np.bincount(sp, lam > 1e6, prob.n_spans) == n_frames)
        if patience is not None:
            done |= refused >= patience
        if done.all():
            break
        if done.any():  # go on with the spans still running only
            keep = ~done[sp]
            rows = np.flatnonzero(keep)
            out_pos[frames], out_rot[frames], out_q[frames], out_lam[frames] = (
                st.root_pos,
                st.root_rot,
                st.q,
                lam,
            )
            settled += float(st.span_cost[done].sum())
            _, new_span = np.unique(sp[keep], return_inverse=True)
            prob = Problem(
                robot,
                take_frames(prob.targets, rows, prob.targets.fps),
                config,
                ref_pos=prob.ref_x[rows, :3],
                span=new_span,
            )
            st = prob.evaluate(st.root_pos[rows], st.root_rot[rows], st.q[rows])
            frames, lam, hold, refused, settling = (
                frames[rows],
                lam[rows],
                hold[rows],
                refused[~done],
                settling[~done],
            )
            need_linearise = True
    out_pos[frames], out_rot[frames], out_q[frames], out_lam[frames] = st.root_pos, st.root_rot, st.q, lam
    # re-orthonormalise the root rotations
    u, _, vt = np.linalg.svd(out_rot)
    sol = Solution(
        root_pos=out_pos,
        root_rot=u @ vt,
        q=out_q,
        iterations=iterations,
        cost=settled + st.cost,
        seconds=time.perf_counter() - start,
        history=history,
        damping=out_lam,
    )
    return sol, (prob, st)
