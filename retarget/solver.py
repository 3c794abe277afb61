"""Whole-sequence retargeting solver: box-constrained Levenberg-Marquardt over all frames.

Unknowns: for every frame t the floating base (position p_t, rotation R_t) and the joint
angles q_t. The cost is a sum of squares (metres unless noted)::

    sum_t  sum_k w_k(t) |p_k(t) - target_k(t)|^2                      keypoint positions
         + sum_s w_s |(p_child - p_parent)(t) - seg_s(t)|^2            segment vectors
         + sum_o w_o(t) L_ROT^2 |a_o * log(R_o(t) R*_o(t)^T)|^2        orientations (a_o: tilt/heading)
         + W_FLOOR sum_feet points min(0, z - radius - clearance(t))^2   floor (1 mm in stance, 16 mm in swing)
         + sum_j w_j (L_POSTURE (q_j - q_rest_j))^2                      posture prior
         + sum_c W_VEL_c |D1 x_c|^2 + W_ACC_c |D2 x_c|^2                 velocity / acceleration

Each iteration linearises every frame with analytic Jacobians (:mod:`retarget.kinematics`),
adds the temporal terms (which couple frame t with t +- 1 and t +- 2) and solves the normal
equations of all frames at once with a banded Cholesky factorisation
(``scipy.linalg.solveh_banded``). By default the lag-2 acceleration couplings are moved onto
the diagonal (an upper bound of the Hessian; the gradient stays exact), which halves the
bandwidth to 6 + nj and quarters the factorisation time.

* Joint limits are exact: joints on a bound whose gradient pushes outward are frozen; joints
  whose step would cross a bound are held at the bound and the step is solved again for
  the rest; every step is projected onto the box.
* Damping is per frame: frames are nearly independent, so each frame keeps the step only
  if its own cost drops, and its damping falls or rises on its own.
* Coarse to fine (``SolverConfig.levels``): every 3rd frame first, then all frames.
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
import scipy.linalg
from scipy.ndimage import gaussian_filter1d

from retarget.bodyfloor import lowest_points
from retarget.kinematics import Poses, so3_exp, so3_log
from retarget.robot_model import RobotModel
from retarget.selfcollision import ClosePairs, clearance_normal_equations, close_pairs
from retarget.targets import Targets

L_ROT = 0.2
"""Metres per radian of orientation error (an error of 1 rad costs like 0.2 m)."""
L_POSTURE = 0.1
"""Metres per radian of posture error."""
W_FLOOR = 100.0
"""Weight of the floor/clearance term (per foot collision point)."""
BODY_CLEARANCE = 0.002
"""Metres the collision geometry of the non-foot bodies keeps above the floor (knees, hands)."""
W_BODY_FLOOR = 100.0
"""Weight of that term: stiff, a knee must not sink while the locked feet pull the legs."""
W_SELF = 100.0
"""Weight of the arms' self-clearance term (per capsule pair, :mod:`retarget.selfcollision`)."""
CONSTRAINT_TOLERANCE = 0.002
"""Capsule overlap or depth below the floor (m) that earns frames a local refinement."""
REF_SMOOTH_SECONDS = 0.05
"""Gaussian sigma (s) of the human pelvis reference of the root's temporal terms."""
PIN = 1e9
"""Diagonal weight that pins a coordinate to a prescribed step (active joint limits)."""
CROSS_TOLERANCE = 0.01
"""Joint-limit overshoot (rad) of a step above which the step is re-solved with those joints pinned."""


@dataclass(frozen=True)
class SolverConfig:
    """Solver settings; the weights multiply the per-keypoint weights of the mapping.

    Temporal weights apply to differences at 20 fps and are rescaled for other rates so that
    the same physical velocity/acceleration costs the same.
    """

    max_iterations: int = 25
    """Iterations when ``levels`` is empty (one level, all frames)."""
    tolerance: float = 0.01
    """Stop a level when an iteration lowers the cost by less than this fraction."""
    damping: float = 1e-4
    """Initial Levenberg-Marquardt damping (per frame)."""
    w_vel_root: float = 0.5
    w_vel_joint: float = 0.1
    w_acc_root: float = 100.0
    w_acc_joint: float = 5.0
    exact_acceleration: bool = False
    """Keep the lag-2 acceleration couplings in the banded matrix (2x bandwidth, ~4x solve time)."""
    levels: tuple[tuple[int, int], ...] = ((3, 5), (1, 2))
    """Coarse-to-fine schedule: (solve every k-th frame, iterations); () solves all frames with max_iterations."""
    extra_iterations: int = 6
    """Iterations of the local refinement of frames where the self-clearance or body-floor
    terms are still violated by more than CONSTRAINT_TOLERANCE (stiff terms converge more
    slowly); only those frames are solved again."""
    body_floor: bool = True
    """Keep every body's collision geometry above the floor, not only the feet (kneeling)."""
    body_floor_weight: float = 10.0 * W_BODY_FLOOR
    """Weight of that term at the last (full-rate) level; coarser levels use W_BODY_FLOOR (a
    stiff floor from the start would lift a straight-legged initial guess off the ground)."""
    self_clearance: bool = True
    """Keep the arms clear of the trunk, the legs and each other (:mod:`retarget.selfcollision`)."""
    pin_iterations: int = 1
    """Gauss-Newton steps that move stance feet onto their locked targets afterwards (0: off)."""


@dataclass
class Solution:
    """Solver output at the targets' frame rate.

    Attributes:
        root_pos: (T, 3); root_rot: (T, 3, 3); q: (T, nj) joint angles (within limits).
        iterations: LM iterations run; cost: final cost; seconds: wall time.
        history: cost per accepted iteration.
    """

    root_pos: np.ndarray
    root_rot: np.ndarray
    q: np.ndarray
    iterations: int
    cost: float
    seconds: float
    history: list[float] = field(default_factory=list)
    damping: np.ndarray | float = 0.0


@dataclass
class _State:
    """One configuration of all frames with its kinematics, residuals and cost."""

    root_pos: np.ndarray
    root_rot: np.ndarray
    q: np.ndarray
    poses: Poses
    pts: np.ndarray
    active: np.ndarray
    kp_res: np.ndarray
    seg_res: np.ndarray
    ori_res: np.ndarray
    floor_res: np.ndarray
    body_low: np.ndarray | None
    body_low_end: np.ndarray | None
    self_close: ClosePairs | None
    x: np.ndarray
    cost: float
    frame_cost: np.ndarray
    span_cost: np.ndarray

    def select(self, use: np.ndarray, other: _State, spans: np.ndarray) -> _State:
        """Frames ``use`` (T,) from this state, the others from ``other``, where ``use`` takes
        whole independent spans (``spans``: (S,) bool, the spans taken): no re-evaluation,
        since no term couples frames of different spans (``x`` may then be off by a constant
        per span, which the temporal terms, acting on differences within spans, never see)."""

        def pick(a, b):
            return None if a is None else np.where(use.reshape(-1, *([1] * (a.ndim - 1))), a, b)

        close = None
        if self.self_close is not None:
            mine, theirs = use[self.self_close.frame], ~use[other.self_close.frame]
            close = ClosePairs(
                *(
                    np.concatenate([getattr(self.self_close, k)[mine], getattr(other.self_close, k)[theirs]])
                    for k in ("frame", "pair", "dist", "pa", "pb")
                )
            )
        poses = Poses(
            *(
                pick(getattr(self.poses, k), getattr(other.poses, k))
                for k in ("rot", "pos", "axis", "anchor", "root_pos")
            )
        )
        span_cost = np.where(spans, self.span_cost, other.span_cost)
        return _State(
            pick(self.root_pos, other.root_pos),
            pick(self.root_rot, other.root_rot),
            pick(self.q, other.q),
            poses,
            pick(self.pts, other.pts),
            pick(self.active, other.active),
            pick(self.kp_res, other.kp_res),
            pick(self.seg_res, other.seg_res),
            pick(self.ori_res, other.ori_res),
            pick(self.floor_res, other.floor_res),
            pick(self.body_low, other.body_low),
            pick(self.body_low_end, other.body_low_end),
            close,
            pick(self.x, other.x),
            float(span_cost.sum()),
            pick(self.frame_cost, other.frame_cost),
            span_cost,
        )


class _Problem:
    """Residuals, Jacobians and the banded normal equations of one retargeting problem."""

    def __init__(
        self,
        robot: RobotModel,
        targets: Targets,
        config: SolverConfig,
        ref_pos: np.ndarray | None = None,
        span: np.ndarray | None = None,
    ) -> None:
        """``ref_pos`` (T, 3): the root's temporal reference (default: the smoothed pelvis of
        ``targets``); ``span`` (T,) int: independent spans of frames side by side (no
        velocity/acceleration term couples frames of different spans; default: one span)."""
        self.robot, self.targets, self.config = robot, targets, config
        tree = robot.tree
        self.tree = tree
        self.t_len = targets.kp_pos.shape[0]
        self.n = tree.nv
        feet = [robot.feet["left"], robot.feet["right"]]
        self.foot_nodes = np.concatenate([np.full(len(f.points), f.node) for f in feet])
        self.foot_points = np.concatenate([f.points for f in feet])
        self.foot_radius = np.concatenate([f.radius for f in feet])
        self.foot_clearance = np.concatenate(
            [
                np.repeat(targets.clearance[side][:, None], len(f.points), axis=1)
                for side, f in zip(("left", "right"), feet)
            ],
            axis=1,
        )  # (T, P)
        self.k_len = len(robot.nodes)
        self.point_nodes = np.concatenate([robot.nodes, self.foot_nodes])
        self.point_offsets = np.concatenate([robot.offsets, self.foot_points])
        self.ori_nodes = robot.nodes[targets.ori_kp]
        self.sqrt_kp = np.sqrt(targets.kp_weight)
        self.sqrt_seg = np.sqrt(targets.seg_weight)
        self.sqrt_ori = (
            np.sqrt(targets.ori_weight)[..., None] * L_ROT * np.sqrt(targets.ori_axis_weight)[None]
        )  # (T, O, 3)
        self.posture = robot.posture_weights * L_POSTURE**2
        self.self_clearance = robot.self_clearance if config.self_clearance else None
        self.body_floor = robot.body_floor if config.body_floor else None
        self.w_body_floor = config.body_floor_weight
        # Temporal weights per velocity coordinate, rescaled to the frame rate.
        r = targets.fps / 20.0
        c = config
        w_vel = np.concatenate([np.full(6, c.w_vel_root), np.full(tree.nj, c.w_vel_joint)]) * r**2
        w_acc = np.concatenate([np.full(6, c.w_acc_root), np.full(tree.nj, c.w_acc_joint)]) * r**4
        self.span = np.zeros(self.t_len, dtype=int) if span is None else np.asarray(span, dtype=int)
        self.n_spans = int(self.span.max()) + 1 if self.t_len else 1
        self.span_frames = np.bincount(self.span, minlength=self.n_spans)  # (S,) frames per span
        coupled = self.span[1:] == self.span[:-1]
        # Weights per frame pair (T - 1, n) and per frame triple (T - 2, n).
        self.w_vel = coupled[:, None] * w_vel
        self.w_acc = (coupled[:-1] & coupled[1:])[:, None] * w_acc
        self._banded_indices()
        if ref_pos is None:
            ref_pos = reference_root(robot, targets)
        self.ref_x = np.zeros((len(ref_pos), self.n))
        self.ref_x[:, :3] = ref_pos
        # Segment s pulls keypoints child(+) and parent(-): incidence (K, S) and sum_s w_s d d^T.
        inc = np.zeros((self.k_len, len(targets.seg_child)))
        inc[targets.seg_child, np.arange(inc.shape[1])] = 1.0
        inc[targets.seg_parent, np.arange(inc.shape[1])] = -1.0
        self._incidence = inc
        self._seg_matrix = (inc * targets.seg_weight) @ inc.T
        self._kp_matrix = self._seg_matrix + targets.kp_weight[:, :, None] * np.eye(self.k_len)  # (T, K, K)

    # -- cost and linearisation ---------------------------------------------------------------
    def evaluate(self, root_pos, root_rot, q) -> _State:
        """Forward kinematics, residuals and cost at one configuration of all frames."""
        tree, tg = self.tree, self.targets
        poses: Poses = tree.forward(root_pos, root_rot, q)
        pts = tree.points(poses, self.point_nodes, self.point_offsets)
        kp = pts[:, : self.k_len]
        foot = pts[:, self.k_len :]
        kp_res = kp - tg.kp_pos
        seg_res = kp[:, tg.seg_child] - kp[:, tg.seg_parent] - tg.seg_vec
        ori_res = self.sqrt_ori * so3_log(poses.rot[:, self.ori_nodes] @ np.swapaxes(tg.ori_rot, -1, -2))
        low = foot[..., 2] - self.foot_radius - self.foot_clearance
        active = low < 0
        floor_res = np.sqrt(W_FLOOR) * np.where(active, low, 0.0)
        body_low = body_end = close = None
        extra_cost = np.zeros(len(q))
        if self.body_floor is not None:
            body_z, body_end = lowest_points(poses, self.body_floor, BODY_CLEARANCE)
            body_low = np.minimum(body_z - BODY_CLEARANCE, 0.0)
            extra_cost += self.w_body_floor * np.sum(body_low**2, axis=1)
        if self.self_clearance is not None:
            close = close_pairs(poses, self.self_clearance)
            np.add.at(
                extra_cost, close.frame, W_SELF * (close.dist - self.self_clearance.margin[close.pair]) ** 2
            )
        frame_cost = extra_cost + (
            np.sum(tg.kp_weight * np.sum(kp_res**2, axis=-1), axis=1)
            + np.sum(tg.seg_weight * np.sum(seg_res**2, axis=-1), axis=1)
            + np.sum(ori_res**2, axis=(1, 2))
            + np.sum(floor_res**2, axis=1)
            + np.sum(self.posture * (q - self.robot.rest_q) ** 2, axis=1)
        )
        x = self.temporal_values(root_pos, root_rot, q)
        d1, d2 = np.diff(x, axis=0), np.diff(x, n=2, axis=0)
        sp, ns = self.span, self.n_spans
        span_cost = (
            np.bincount(sp, frame_cost, ns)
            + np.bincount(sp[:-1], np.sum(self.w_vel * d1 * d1, axis=1), ns)
            + np.bincount(sp[:-2], np.sum(self.w_acc * d2 * d2, axis=1), ns)
        )
        return _State(
            root_pos,
            root_rot,
            q,
            poses,
            pts,
            active,
            kp_res,
            seg_res,
            ori_res,
            floor_res,
            body_low,
            body_end,
            close,
            x,
            float(span_cost.sum()),
            frame_cost,
            span_cost,
        )

    def span_max(self, values: np.ndarray, floor: float = -np.inf) -> np.ndarray:
        """(S,) the largest of per-frame ``values`` (T,) in each span (``floor`` if none is larger)."""
        out = np.full(self.n_spans, floor)
        np.maximum.at(out, self.span, values)
        return out

    def frame_violation(self, st: _State) -> np.ndarray:
        """(T,) how deep (m) the enclosing capsules overlap each other, a body's support points
        reach below the floor or a swing foot comes below half its clearance, per frame (the
        margins are only the terms' soft zone: the check sees an overlap of the real
        geometry, which the capsules enclose)."""
        worst = np.zeros(self.t_len)
        # swing feet more than halfway down to the floor from their clearance
        swing = self.foot_clearance > 0.005
        if swing.any():
            height = st.pts[:, self.k_len :, 2] - self.foot_radius
            worst = np.maximum(
                worst, np.max(np.where(swing, 0.5 * self.foot_clearance - height, 0.0), axis=1)
            )
        if st.body_low is not None and st.body_low.size:
            worst = np.maximum(worst, -(st.body_low.min(axis=1) + BODY_CLEARANCE))
        if st.self_close is not None and st.self_close.frame.size:
            np.maximum.at(worst, st.self_close.frame, -st.self_close.dist)
        return worst

    def normal_equations(self, st: _State) -> tuple[np.ndarray, np.ndarray]:
        """Gauss-Newton blocks H (T, n, n) and gradient g (T, n) of the per-frame terms.

        Keypoint and segment terms share one Jacobian: with W(t) = diag(w_k(t)) + sum_s w_s
        (e_child - e_parent)(e_child - e_parent)^T, their Hessian is J^T (W (x) I3) J.
        """
        tree, tg = self.tree, self.targets
        t, n, k = self.t_len, self.n, self.k_len
        jk = tree.point_jacobian(st.poses, self.robot.nodes, st.pts[:, :k])  # (T, K, 3, n)
        flat = jk.reshape(t, 3 * k, n)
        b = (self._kp_matrix @ jk.reshape(t, k, 3 * n)).reshape(t, 3 * k, n)
        jt = np.swapaxes(flat, 1, 2)
        h = jt @ b
        u = tg.kp_weight[..., None] * st.kp_res + self._incidence @ (tg.seg_weight[:, None] * st.seg_res)
        g = (jt @ u.reshape(t, 3 * k, 1))[..., 0]
        jr = (self.sqrt_ori[..., None] * tree.rotation_jacobian(st.poses, self.ori_nodes)).reshape(t, -1, n)
        jrt = np.swapaxes(jr, 1, 2)
        h += jrt @ jr
        g += (jrt @ st.ori_res.reshape(t, -1, 1))[..., 0]
        if st.active.any():
            jf = tree.point_jacobian(st.poses, self.foot_nodes, st.pts[:, k:], rows=(2,))[:, :, 0]
            jf *= (np.sqrt(W_FLOOR) * st.active)[..., None]
            jft = np.swapaxes(jf, 1, 2)
            h += jft @ jf
            g += (jft @ st.floor_res[..., None])[..., 0]
        rows = []
        if st.body_low is not None:
            fr, b = np.nonzero(st.body_low < 0)
            if fr.size:
                up = np.broadcast_to(np.array([0.0, 0.0, 1.0]), (fr.size, 3))
                jb = tree.directional_jacobian(
                    st.poses, fr, self.body_floor.node[b], st.body_low_end[fr, b], up
                )
                root = np.sqrt(self.w_body_floor)
                rows.append((fr, root * jb, root * st.body_low[fr, b]))
        if st.self_close is not None and st.self_close.frame.size:
            rows.append(
                clearance_normal_equations(tree, st.poses, self.self_clearance, st.self_close, W_SELF)
            )
        if rows:  # sparse rows: accumulate J^T J and J^T r per frame (padded, batched matmul)
            fr = np.concatenate([r[0] for r in rows])
            jr = np.concatenate([r[1] for r in rows])
            res = np.concatenate([r[2] for r in rows])
            order = np.argsort(fr, kind="stable")
            fr, jr, res = fr[order], jr[order], res[order]
            first = np.searchsorted(fr, fr, side="left")
            slot = np.arange(len(fr)) - first  # rank of each row within its frame
            pad = np.zeros((t, int(slot.max()) + 1, n))
            pad[fr, slot] = jr
            rpad = np.zeros((t, pad.shape[1]))
            rpad[fr, slot] = res
            padt = np.swapaxes(pad, 1, 2)
            h += padt @ pad
            g += (padt @ rpad[..., None])[..., 0]
        return h, g

    @staticmethod
    def _unwrap(root_rot: np.ndarray) -> np.ndarray:
        """(T, 3) root rotation unwrapped as a world-frame rotation vector (cumulative steps)."""
        steps = so3_log(root_rot[1:] @ np.swapaxes(root_rot[:-1], -1, -2))
        return np.concatenate([np.zeros((1, 3)), np.cumsum(steps, axis=0)])

    def temporal_values(self, root_pos, root_rot, q) -> np.ndarray:
        """(T, n) sequences the temporal terms act on: the root's position relative to the
        human pelvis reference, its unwrapped rotation and the joint angles."""
        return np.concatenate([root_pos, self._unwrap(root_rot), q], axis=1) - self.ref_x

    def gradient_temporal(self, x: np.ndarray) -> np.ndarray:
        """Gradient (T, n) of the velocity and acceleration terms."""
        g = np.zeros_like(x)
        if len(x) > 1:
            g -= np.diff(np.pad(np.diff(x, axis=0) * self.w_vel, ((1, 1), (0, 0))), axis=0)
        if len(x) > 2:
            g += np.diff(np.pad(np.diff(x, n=2, axis=0) * self.w_acc, ((2, 2), (0, 0))), n=2, axis=0)
        return g

    # -- banded normal equations -------------------------------------------------------------
    def _banded_indices(self) -> None:
        t, n = self.t_len, self.n
        self.kd = 2 * n if (t > 2 and self.config.exact_acceleration) else n
        a, b = np.triu_indices(n)
        self._tri = (a, b)
        self._rows = np.broadcast_to(self.kd + a - b, (t, len(a)))
        self._cols = np.arange(t)[:, None] * n + b[None, :]
        # Temporal diagonals (same coordinate, lags 0, 1, 2), per frame and coordinate.
        d0 = np.zeros((t, n))
        d1 = np.zeros((max(t - 1, 0), n))
        d2 = np.zeros((max(t - 2, 0), n))
        if t > 1:
            d0[:-1] += self.w_vel
            d0[1:] += self.w_vel
            d1 -= self.w_vel
        if t > 2:
            d0[:-2] += self.w_acc
            d0[1:-1] += 4 * self.w_acc
            d0[2:] += self.w_acc
            d1[:-1] -= 2 * self.w_acc
            d1[1:] -= 2 * self.w_acc
            d2 += self.w_acc
            if not self.config.exact_acceleration:
                # Drop the lag-2 couplings from the matrix (bandwidth n instead of 2n) and
                # add their absolute value to the diagonal: the matrix stays an upper bound of
                # the true Hessian, the gradient stays exact, so LM still converges to the
                # same optimum.
                d0[:-2] += self.w_acc
                d0[2:] += self.w_acc
        self._d0, self._d1, self._d2 = d0, d1, d2

    def normal_matrix(self, h: np.ndarray, lam: np.ndarray) -> np.ndarray:
        """Upper banded storage (kd + 1, T * n) of H + temporal + diag(lam_t) (H: (T, n, n) blocks, lam: (T,))."""
        t, n, kd = self.t_len, self.n, self.kd
        ab = np.zeros((kd + 1, t * n))
        a, b = self._tri
        ab[self._rows, self._cols] = h[:, a, b]
        diag = self._d0 + np.asarray(lam, dtype=float).reshape(-1, 1)
        diag[:, 6:] += self.posture
        ab[kd] += diag.reshape(-1)
        if t > 1:
            ab[kd - n, n:] += self._d1.reshape(-1)
        if t > 2 and kd >= 2 * n:
            ab[kd - 2 * n, 2 * n :] += self._d2.reshape(-1)
        return ab

    def solve_step(
        self, ab: np.ndarray, g: np.ndarray, fixed: np.ndarray, fixed_step: np.ndarray | None = None
    ) -> np.ndarray:
        """Solve the banded system ``ab`` dx = -g for all frames at once; returns dx (T, n).

        Coordinates where ``fixed`` is True take the step ``fixed_step`` (0 when None) and
        the others are solved with those steps substituted (a large diagonal pins them).
        """
        ab = ab.copy()
        ab[self.kd] += (fixed * PIN).reshape(-1)
        target = np.zeros_like(g) if fixed_step is None else fixed_step
        rhs = np.where(fixed, PIN * target, -g).reshape(-1)
        sol = scipy.linalg.solveh_banded(ab, rhs, lower=False, check_finite=False, overwrite_ab=True)
        return sol.reshape(self.t_len, self.n)


def initial_guess(robot: RobotModel, targets: Targets) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Root from the pelvis target (position + pelvis frame), joints at the rest pose."""
    from retarget.targets import human_frames

    k = robot.keypoint_index("pelvis")
    node = robot.nodes[k]
    frame = human_frames(targets.human_world)["pelvis"]
    rot = frame @ robot.rest.rot[0, node] @ robot.rest.rot[0, 0].T
    pos = targets.kp_pos[:, k] - rot @ robot.rest_keypoints[k]
    q = np.tile(robot.rest_q, (len(pos), 1))
    return pos, rot, q


def reference_root(robot: RobotModel, targets: Targets) -> np.ndarray:
    """(T, 3) the root reference of the temporal terms: the initial guess's root position
    (from the human pelvis) smoothed over REF_SMOOTH_SECONDS against joint noise. The terms
    act on the root's deviation from it, so the robot's root may accelerate as the human's
    does (a jump's arc), but not on its own."""
    ref_pos = initial_guess(robot, targets)[0]
    if len(ref_pos) > 2:
        ref_pos = gaussian_filter1d(ref_pos, REF_SMOOTH_SECONDS * targets.fps, axis=0, mode="nearest")
    return ref_pos


def _subsample(targets: Targets, step: int) -> tuple[Targets, np.ndarray]:
    """Every ``step``-th frame of the targets (the last frame always kept)."""
    idx = np.unique(np.r_[np.arange(0, len(targets.kp_pos), step), len(targets.kp_pos) - 1])
    return _take(targets, idx, targets.fps / step), idx


def _take(targets: Targets, idx: np.ndarray, fps: float) -> Targets:
    """The targets of frames ``idx``, labelled with frame rate ``fps``."""
    pick = lambda a: a[idx]  # noqa: E731
    return Targets(
        fps=fps,
        transform=targets.transform,
        human_world=pick(targets.human_world),
        kp_pos=pick(targets.kp_pos),
        kp_weight=pick(targets.kp_weight),
        seg_parent=targets.seg_parent,
        seg_child=targets.seg_child,
        seg_vec=pick(targets.seg_vec),
        seg_weight=targets.seg_weight,
        ori_kp=targets.ori_kp,
        ori_rot=pick(targets.ori_rot),
        ori_weight=pick(targets.ori_weight),
        ori_axis_weight=targets.ori_axis_weight,
        stance={k: pick(v) for k, v in targets.stance.items()},
        lock={k: pick(v) for k, v in targets.lock.items()},
        clearance={k: pick(v) for k, v in targets.clearance.items()},
    )


def _upsample(sol_pos, sol_rot, sol_q, idx, dst):
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
    config: SolverConfig = SolverConfig(),
    init: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None,
) -> Solution:
    """Run the solver on ``targets``; see the module docstring.

    Coarse to fine (``config.levels``, without ``init``): each level solves every k-th frame
    for a few iterations and its interpolation starts the next level; the last level is
    every frame.
    """
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
            body_floor_weight=config.body_floor_weight
            if last
            else min(W_BODY_FLOOR, config.body_floor_weight),
        )
        sol, final = _solve(robot, small, cfg, init)
        total += sol.iterations
        damping = max(config.damping, float(np.median(sol.damping)))
        prev = (sol.root_pos, sol.root_rot, sol.q, idx)
    if config.extra_iterations > 0:
        total += _refine_violations(robot, config, sol, damping, *final)
    sol.iterations = total
    if config.pin_iterations > 0:
        from retarget.feet import pin_stance_feet

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
    spans = [(max(a - 2, 0), min(b + 2, n), a, b) for a, b in zip(edges[::2], edges[1::2])]
    if not spans:
        return np.zeros(0, dtype=int), np.zeros(0, dtype=bool), np.zeros(0, dtype=int)
    idx = np.concatenate([np.arange(lo, hi) for lo, hi, _, _ in spans])
    pinned = np.concatenate([(np.arange(lo, hi) < a) | (np.arange(lo, hi) >= b) for lo, hi, a, b in spans])
    span = np.repeat(np.arange(len(spans)), [hi - lo for lo, hi, _, _ in spans])
    return idx, pinned, span


def _refine_violations(
    robot: RobotModel, config: SolverConfig, sol: Solution, damping: float, prob: _Problem, st: _State
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
    sub = _take(prob.targets, idx, prob.targets.fps)
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
) -> tuple[Solution, tuple[_Problem, _State]]:
    """Levenberg-Marquardt on one problem; ``pinned`` (T,) bool: frames held fixed;
    ``damping`` (T,): each frame's initial damping (default ``config.damping``);
    ``patience``: refused steps in a row after which a span gives up (default: until its
    damping explodes); ``until_resolved``: a span also stops once none of its frames
    violates the stiff terms by more than CONSTRAINT_TOLERANCE (the local refinement's aim).

    ``span`` (T,) int: independent spans side by side (see :class:`_Problem`). Each span
    accepts or refuses its step, stops and gives up on its own, exactly as if it were solved
    alone; the spans still running share the linearisations and banded solves, and the
    problem shrinks to them whenever spans stop. Returns the solution and the final
    (problem, state) of the spans running at the end (all of them when ``span`` is None).
    """
    start = time.perf_counter()
    prob = _Problem(robot, targets, config, ref_pos=ref_pos, span=span)
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
    iterations = 0
    need_linearise = True
    while iterations < config.max_iterations:
        iterations += 1
        sp = prob.span
        if need_linearise:
            h, g = prob.normal_equations(st)
            g += prob.gradient_temporal(st.x)
            g[:, 6:] += prob.posture * (st.q - robot.rest_q)
            frozen = np.zeros_like(g, dtype=bool)
            frozen[:, 6:] = ((st.q <= lower + 1e-12) & (g[:, 6:] > 0)) | (
                (st.q >= upper - 1e-12) & (g[:, 6:] < 0)
            )
            frozen[hold] = True
        try:
            ab = prob.normal_matrix(h, lam)
            step = prob.solve_step(ab, g, frozen)
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
                step = prob.solve_step(ab, g, frozen | cross, fixed_step)
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
            done = accept & ((st.span_cost - trial.span_cost) < config.tolerance * st.span_cost)
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
            prob = _Problem(
                robot,
                _take(prob.targets, rows, prob.targets.fps),
                config,
                ref_pos=prob.ref_x[rows, :3],
                span=new_span,
            )
            st = prob.evaluate(st.root_pos[rows], st.root_rot[rows], st.q[rows])
            frames, lam, hold, refused = frames[rows], lam[rows], hold[rows], refused[~done]
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
