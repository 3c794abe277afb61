"""The interface of the solver's cost terms and the configuration they are evaluated at.

The solver minimises a sum of squares over all T frames. Each term of the sum is a
:class:`CostTerm`: it evaluates its residuals at a :class:`Configuration` (a
:class:`TermValue` with the cost it adds to every frame), adds its Gauss-Newton blocks
``J^T J`` and gradient ``J^T r`` to the normal equations, and may say how far each frame
violates a hard constraint it stands for. Per-frame terms fill the (T, n, n) diagonal blocks
of the :class:`NormalEquations` (or hand over sparse rows, :class:`SparseRows`, when only a few
frames are active); terms that couple frames (velocity, acceleration) add a constant banded
Hessian instead.
n = 6 + nj velocity coordinates per frame: root translation (m), root rotation (rad, world
frame, applied as ``so3_exp(d) @ R``), joint angles (rad).
"""

from __future__ import annotations

import functools
from abc import ABC, abstractmethod
from dataclasses import dataclass, fields, replace
from typing import Generic, TypeVar

import numpy as np

from retarget.kinematics import Poses, so3_log
from retarget.robot_model import RobotModel


def pick(use: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Frames ``use`` (T,) bool from ``a``, the others from ``b`` (both with the frames on axis 0)."""
    return np.where(use.reshape(-1, *([1] * (a.ndim - 1))), a, b)


def unwrap_rotations(root_rot: np.ndarray) -> np.ndarray:
    """(T, 3) root rotations (T, 3, 3) unwrapped as a world-frame rotation vector (cumulative steps)."""
    steps = so3_log(root_rot[1:] @ np.swapaxes(root_rot[:-1], -1, -2))
    return np.concatenate([np.zeros((1, 3)), np.cumsum(steps, axis=0)])


@dataclass
class Configuration:
    """The robot in all T frames: floating base, joints and the kinematics every term reads.

    Attributes:
        robot: the :class:`RobotModel`.
        root_pos: (T, 3) m; root_rot: (T, 3, 3); q: (T, nj) rad.
        poses: forward kinematics of every node.
        keypoints: (T, K, 3) world positions (m) of the mapped keypoints.
        root_unwrapped: (T, 3) the root rotation as a continuous rotation vector (rad).
    """

    robot: RobotModel
    root_pos: np.ndarray
    root_rot: np.ndarray
    q: np.ndarray
    poses: Poses
    keypoints: np.ndarray
    root_unwrapped: np.ndarray

    @classmethod
    def at(
        cls, robot: RobotModel, root_pos: np.ndarray, root_rot: np.ndarray, q: np.ndarray
    ) -> Configuration:
        """Forward kinematics of ``robot`` at root_pos (T, 3), root_rot (T, 3, 3), q (T, nj)."""
        poses = robot.tree.forward(root_pos, root_rot, q)
        keypoints = robot.tree.points(poses, robot.nodes, robot.offsets)
        return cls(robot, root_pos, root_rot, q, poses, keypoints, unwrap_rotations(root_rot))

    @functools.cached_property
    def keypoint_jacobian(self) -> np.ndarray:
        """(T, K, 3, n) d(keypoint positions)/d(velocity coordinates)."""
        return self.robot.tree.point_jacobian(self.poses, self.robot.nodes, self.keypoints)

    def select(self, use: np.ndarray, other: Configuration) -> Configuration:
        """Frames ``use`` (T,) bool from this configuration, the others from ``other`` (no
        forward kinematics: every quantity is per frame; ``root_unwrapped`` may then be off
        by a constant per run of frames, which differences within a run never see)."""
        poses = Poses(
            *(pick(use, getattr(self.poses, f.name), getattr(other.poses, f.name)) for f in fields(Poses))
        )
        return Configuration(
            self.robot,
            pick(use, self.root_pos, other.root_pos),
            pick(use, self.root_rot, other.root_rot),
            pick(use, self.q, other.q),
            poses,
            pick(use, self.keypoints, other.keypoints),
            pick(use, self.root_unwrapped, other.root_unwrapped),
        )


@dataclass
class TermValue:
    """A term's residuals at one configuration: ``cost`` (T,) is what it adds to each frame
    (a term coupling frames t and t + k books it on frame t). Subclasses add the arrays their
    linearisation needs; every array field has the frames on its leading axis."""

    cost: np.ndarray

    def select(self, use: np.ndarray, other: TermValue) -> TermValue:
        """Frames ``use`` (T,) bool from this value, the others from ``other``."""
        return replace(
            self, **{f.name: pick(use, getattr(self, f.name), getattr(other, f.name)) for f in fields(self)}
        )


@dataclass
class SparseRows:
    """Residual rows of a term active in few (frame, element) entries (E of them).

    Attributes:
        frame: (E,) frame of each row; jac: (E, n) its Jacobian row; res: (E,) its residual
        (both scaled by the square root of the term's weight).
    """

    frame: np.ndarray
    jac: np.ndarray
    res: np.ndarray


class NormalEquations:
    """The Gauss-Newton normal equations of all T frames, as the terms add to them.

    Dense terms add ``J^T J`` to :attr:`h` (T, n, n) and ``J^T r`` to :attr:`g` (T, n) (r the
    weighted residuals: g is half the cost's gradient); sparse terms append :class:`SparseRows`
    to :attr:`rows`; terms on keypoint positions, whose Jacobian is the keypoints' Jacobian J_p
    times a weight pattern, add their weights in keypoint space (:meth:`add_keypoints`), so
    that ``J_p^T (W (x) I3) J_p`` is formed once for all of them. :meth:`finish` adds the last two.
    """

    def __init__(self, t_len: int, n: int) -> None:
        self.h = np.zeros((t_len, n, n))
        self.g = np.zeros((t_len, n))
        self.rows: list[SparseRows] = []
        self.keypoint_weight: np.ndarray | None = None  # (T, K, K) or (K, K)
        self.keypoint_gradient: np.ndarray | None = None  # (T, K, 3)

    def add_keypoints(self, weight: np.ndarray, gradient: np.ndarray) -> None:
        """Add a term on keypoint positions: ``weight`` (T, K, K) or (K, K), the matrix W of its
        cost's second derivative in the keypoint positions (per axis), and ``gradient`` (T, K, 3),
        W times the residual mapped back to the keypoints."""
        if self.keypoint_weight is None or self.keypoint_gradient is None:
            self.keypoint_weight, self.keypoint_gradient = weight, gradient
        else:
            self.keypoint_weight = self.keypoint_weight + weight
            self.keypoint_gradient = self.keypoint_gradient + gradient

    def finish(self, cfg: Configuration) -> tuple[np.ndarray, np.ndarray]:
        """(h (T, n, n), g (T, n)) with the keypoint terms and the sparse rows added."""
        h, g = self.h, self.g
        if self.keypoint_weight is not None and self.keypoint_gradient is not None:
            jk = cfg.keypoint_jacobian  # (T, K, 3, n)
            t, k, _, n = jk.shape
            jt = np.swapaxes(jk.reshape(t, 3 * k, n), 1, 2)
            h += jt @ (self.keypoint_weight @ jk.reshape(t, k, 3 * n)).reshape(t, 3 * k, n)
            g += (jt @ self.keypoint_gradient.reshape(t, 3 * k, 1))[..., 0]
        if self.rows:  # rows padded per frame into one batched product
            fr = np.concatenate([r.frame for r in self.rows])
            jr = np.concatenate([r.jac for r in self.rows])
            res = np.concatenate([r.res for r in self.rows])
            order = np.argsort(fr, kind="stable")
            fr, jr, res = fr[order], jr[order], res[order]
            first = np.searchsorted(fr, fr, side="left")
            slot = np.arange(len(fr)) - first  # rank of each row within its frame
            pad = np.zeros((len(g), int(slot.max()) + 1, g.shape[1]))
            pad[fr, slot] = jr
            rpad = np.zeros((len(g), pad.shape[1]))
            rpad[fr, slot] = res
            padt = np.swapaxes(pad, 1, 2)
            h += padt @ pad
            g += (padt @ rpad[..., None])[..., 0]
        return h, g


V = TypeVar("V", bound=TermValue)
"""The value type a term evaluates to."""


class CostTerm(ABC, Generic[V]):
    """One term of the solver's sum of squares (see the module docstring).

    Class attributes:
        name: short name in reports and tests.
        couples_frames: True for terms on differences between frames: they count per span
            of frames, not per frame, in the solver's step acceptance.
        lag: the farthest frame coupling the term keeps in the banded matrix (0: none).
    """

    name: str = ""
    couples_frames: bool = False
    lag: int = 0

    @abstractmethod
    def evaluate(self, cfg: Configuration) -> V:
        """The term's residuals and per-frame cost (T,) at ``cfg``."""

    @abstractmethod
    def linearise(self, cfg: Configuration, value: V, eq: NormalEquations) -> None:
        """Add the term's Gauss-Newton blocks ``J^T J`` and gradient ``J^T r`` (half its
        cost's gradient) at ``cfg`` to ``eq``."""

    def add_band(self, d0: np.ndarray, d1: np.ndarray, d2: np.ndarray) -> None:
        """Add a constant Hessian that couples frames: its diagonals per velocity coordinate
        at lags 0 (T, n), 1 (T - 1, n) and 2 (T - 2, n). Per-frame terms add nothing."""
        return None

    def violation(self, cfg: Configuration, value: V) -> np.ndarray | None:
        """(T,) how far (m) each frame violates the hard constraint the term stands for
        (None: the term is a preference, not a constraint)."""
        return None
