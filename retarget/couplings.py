"""Joints coupled by the MJCF's joint equalities (``<equality><joint joint1 joint2 polycoef>``).

MuJoCo holds ``q1 - q1_0 = c0 + c1 x + c2 x^2 + c3 x^3 + c4 x^4`` with ``x = q2 - q2_0``
(``q_0``: the model's ``qpos0``; without ``joint2``, ``q1 - q1_0 = c0``): NAO's two hip
yaw-pitch joints share one motor, written as ``joint1 = joint2``. The solver keeps every
active coupling (:class:`retarget.costs.coupling.CouplingCost`) and the output holds it
exactly (:meth:`JointCouplings.project`).
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np


@dataclass(frozen=True)
class JointCouplings:
    """E couplings between the solver's joint coordinates ``q`` (nj,).

    Attributes:
        first: (E,) index into ``q`` of each coupling's driven joint (MuJoCo's ``joint1``).
        second: (E,) index of its driving joint (``joint2``), -1 where there is none.
        poly: (E, 5) the polynomial's coefficients c0..c4.
        first_ref, second_ref: (E,) the two joints' reference angles (``qpos0``; 0 without).
    """

    first: np.ndarray
    second: np.ndarray
    poly: np.ndarray
    first_ref: np.ndarray
    second_ref: np.ndarray

    @property
    def joints(self) -> np.ndarray:
        """Indices into ``q`` of every coupled joint, driven or driving (sorted, unique)."""
        return np.unique(np.concatenate([self.first, self.second[self.second >= 0]]))

    def _x(self, q: np.ndarray) -> np.ndarray:
        """(T, E) the driving joints' offsets from their reference (0 without one)."""
        x = q[:, np.maximum(self.second, 0)] - self.second_ref
        return np.where(self.second >= 0, x, 0.0)

    def driven(self, q: np.ndarray) -> np.ndarray:
        """(T, E) the angle each driven joint must have given ``q`` (T, nj)."""
        x = self._x(q)
        return self.first_ref + np.sum(self.poly * x[..., None] ** np.arange(5), axis=-1)

    def residual(self, q: np.ndarray) -> np.ndarray:
        """(T, E) how far (rad or m) each driven joint of ``q`` (T, nj) is from its coupling."""
        return q[:, self.first] - self.driven(q)

    def slope(self, q: np.ndarray) -> np.ndarray:
        """(T, E) d(driven angle) / d(driving joint) at ``q`` (T, nj)."""
        x = self._x(q)
        c = self.poly
        return c[:, 1] + 2 * c[:, 2] * x + 3 * c[:, 3] * x**2 + 4 * c[:, 4] * x**3

    def project(self, q: np.ndarray, lower: np.ndarray, upper: np.ndarray) -> np.ndarray:
        """``q`` (T, nj) with every driven joint set to its coupling, clipped to [lower, upper]
        (exact where the driven joint's range allows it). A chain of couplings (a joint driving
        one that drives another) resolves in as many passes as it has links, in any order."""
        out = np.array(q, dtype=np.float64)
        for _ in range(len(self.first)):
            out[:, self.first] = np.clip(self.driven(out), lower[self.first], upper[self.first])
        return out


def joint_couplings(model: mujoco.MjModel, joint_ids: np.ndarray) -> JointCouplings | None:
    """The active joint equalities of ``model`` between the joints ``joint_ids`` (the solver's
    coordinates, MuJoCo joint ids in ``q`` order); None without any. A coupling naming a joint
    the solver does not move (a ball, another free body's) is left out."""
    index = {int(j): i for i, j in enumerate(joint_ids)}
    rows = []
    for e in range(model.neq):
        if model.eq_type[e] != mujoco.mjtEq.mjEQ_JOINT or not model.eq_active0[e]:
            continue
        j1, j2 = int(model.eq_obj1id[e]), int(model.eq_obj2id[e])
        if j1 not in index or (j2 >= 0 and j2 not in index):
            continue
        ref1 = float(model.qpos0[model.jnt_qposadr[j1]])
        ref2 = float(model.qpos0[model.jnt_qposadr[j2]]) if j2 >= 0 else 0.0
        rows.append((index[j1], index[j2] if j2 >= 0 else -1, model.eq_data[e, :5].copy(), ref1, ref2))
    if not rows:
        return None
    first, second, poly, ref1s, ref2s = zip(*rows, strict=True)
    return JointCouplings(np.array(first), np.array(second), np.array(poly), np.array(ref1s), np.array(ref2s))
