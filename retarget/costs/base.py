"""The interface of the solver's cost terms and the configuration they are evaluated at.

The solver minimises a sum of squares over all T frames. Each term of the sum is a
:class:`CostTerm`: it evaluates its residuals at a :class:`Configuration` (a
:class:`TermValue` with the cost it adds to every frame), adds its Gauss-Newton blocks
``J^T J`` and gradient ``J^T r`` to the normal equations, and may say how far each frame
violates a hard constraint it stands for. Per-frame terms fill the (T, n, n) diagonal blocks
(or hand over sparse rows, :class:`SparseRows`, when only a few frames are active); terms
that couple frames (velocity, acceleration) add a constant banded Hessian instead.
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


def add_sparse_rows(h: np.ndarray, g: np.ndarray, rows: list[SparseRows]) -> None:
    """Add ``J^T J`` to h (T, n, n) and ``J^T r`` to g (T, n) for the rows of every frame
    (rows padded per frame into one batched product)."""
    if not rows:
        return
    t, n = g.shape
    fr = np.concatenate([r.frame for r in rows])
    jr = np.concatenate([r.jac for r in rows])
    res = np.concatenate([r.res for r in rows])
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
    def linearise(
        self, cfg: Configuration, value: V, h: np.ndarray, g: np.ndarray, rows: list[SparseRows]
    ) -> None:
        """Add the Gauss-Newton blocks ``J^T J`` to h (T, n, n) and the gradient ``J^T r`` to
        g (T, n) of the cost / 2 at ``cfg``, or append sparse rows to ``rows``."""

    def add_band(self, d0: np.ndarray, d1: np.ndarray, d2: np.ndarray) -> None:
        """Add a constant Hessian that couples frames: its diagonals per velocity coordinate
        at lags 0 (T, n), 1 (T - 1, n) and 2 (T - 2, n). Per-frame terms add nothing."""
        return None

    def violation(self, cfg: Configuration, value: V) -> np.ndarray | None:
        """(T,) how far (m) each frame violates the hard constraint the term stands for
        (None: the term is a preference, not a constraint)."""
        return None
