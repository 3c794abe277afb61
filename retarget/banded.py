"""The banded normal equations of all frames: assembly and the constrained solve.

Unknowns are ordered frame by frame (T blocks of n velocity coordinates). The per-frame
Gauss-Newton blocks H_t (n, n) sit on the diagonal; terms that couple frames add constant
diagonals at lags 1 and 2 (:meth:`retarget.costs.base.CostTerm.add_band`). The matrix is
kept in LAPACK's upper banded storage and factorised by banded Cholesky
(``scipy.linalg.solveh_banded``).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import scipy.linalg

from retarget.costs.base import CostTerm

PIN = 1e9
"""Diagonal weight that pins a coordinate to a prescribed step (active joint limits)."""


class BandedSystem:
    """The banded structure of T frames of n coordinates and the constant couplings of ``terms``.

    Attributes:
        kd: superdiagonals of the band (n times the largest lag a term keeps, at least n).
    """

    def __init__(self, t_len: int, n: int, terms: Sequence[CostTerm]) -> None:
        self.t_len, self.n = t_len, n
        lag = max([1] + [term.lag for term in terms if t_len > term.lag])
        self.kd = lag * n
        a, b = np.triu_indices(n)
        self._tri = (a, b)
        self._rows = np.broadcast_to(self.kd + a - b, (t_len, len(a)))
        self._cols = np.arange(t_len)[:, None] * n + b[None, :]
        # Constant diagonals (same coordinate, lags 0, 1, 2), per frame and coordinate.
        self.d0 = np.zeros((t_len, n))
        self.d1 = np.zeros((max(t_len - 1, 0), n))
        self.d2 = np.zeros((max(t_len - 2, 0), n))
        for term in terms:
            term.add_band(self.d0, self.d1, self.d2)

    def matrix(self, h: np.ndarray, lam: np.ndarray) -> np.ndarray:
        """Upper banded storage (kd + 1, T * n) of H + constant couplings + diag(lam_t)
        (H: (T, n, n) per-frame blocks, lam: (T,) damping per frame)."""
        t, n, kd = self.t_len, self.n, self.kd
        ab = np.zeros((kd + 1, t * n))
        a, b = self._tri
        ab[self._rows, self._cols] = h[:, a, b]
        diag = self.d0 + np.asarray(lam, dtype=float).reshape(-1, 1)
        ab[kd] += diag.reshape(-1)
        if t > 1:
            ab[kd - n, n:] += self.d1.reshape(-1)
        if t > 2 and kd >= 2 * n:
            ab[kd - 2 * n, 2 * n :] += self.d2.reshape(-1)
        return ab

    def solve(
        self, ab: np.ndarray, g: np.ndarray, fixed: np.ndarray, fixed_step: np.ndarray | None = None
    ) -> np.ndarray:
        """Solve the banded system ``ab`` dx = -g for all frames at once; returns dx (T, n).

        Coordinates where ``fixed`` (T, n) is True take the step ``fixed_step`` (0 when None)
        and the others are solved with those steps substituted (a large diagonal pins them).
        """
        ab = ab.copy()
        ab[self.kd] += (fixed * PIN).reshape(-1)
        target = np.zeros_like(g) if fixed_step is None else fixed_step
        rhs = np.where(fixed, PIN * target, -g).reshape(-1)
        sol = scipy.linalg.solveh_banded(ab, rhs, lower=False, check_finite=False, overwrite_ab=True)
        return sol.reshape(self.t_len, self.n)
