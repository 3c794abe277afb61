"""A static scene's SDF read from a distance grid, evaluated exactly near the obstacles.

The editing losses only need the SDF where it is small: a point farther from every obstacle than
its clearance adds nothing to ``relu(clearance - SDF)`` and has no gradient. :class:`GridSDF`
answers those far points from a lattice of exact SDF samples and sends only the others to the
exact :class:`~scenes.sdf.scene_sdf.SceneSDF`:

1. the lattice (:class:`DistanceGrid`, spacing h, over the scene's extent) is built lazily in
   bricks of 8 x 8 x 8 nodes, each the first time a point falls into it, with the exact SDF; a
   motion visits a few dozen bricks, so a mesh scene pays for the nodes it needs only;
2. trilinear interpolation of the 8 nodes around a point gives v and its gradient in closed form.
   The SDF is 1-Lipschitz, so ``|v - SDF(p)| <= sum_i w_i ||x_i - p||
   <= sqrt(sum_i w_i ||x_i - p||^2) = h sqrt(sum_k t_k (1 - t_k)) <= (sqrt(3) / 2) h``
   (w_i the trilinear weights, t_k the point's fractions in its cell);
3. a point is **exact** (the SceneSDF's value and gradient) when ``v - bound < exact_within`` or
   it lies outside the lattice; every other point is at least ``exact_within`` from every
   obstacle and gets v with its interpolated gradient.

A loss whose clearances are all at most ``exact_within`` therefore has exactly the same value and
gradient as with the exact SDF; it only skips the far points. Moving obstacles (mocap tracks)
have no static lattice and stay exact: :func:`banded_sdf` returns their SceneSDF unchanged.

Shapes as :class:`SceneSDF`: points (..., N, 3) world metres -> (..., N), differentiable (first
order) in the points; any float dtype and device.
"""

from __future__ import annotations

import math
import weakref

import numpy as np
import torch

from controlmm.errors import ControlMMError
from scenes.sdf import kernels
from scenes.sdf.kernels import check_points, check_times
from scenes.sdf.scene_sdf import SceneSDF

Tensor = torch.Tensor

DEFAULT_SPACING = 0.05
"""Lattice spacing h (m): an error bound of 4.3 cm, so exact evaluation within ~4 cm + the
clearance of the obstacles."""

BRICK = 8
"""Nodes per brick side (7 cells; neighbouring bricks share their boundary nodes)."""

NODE_ERROR = 1e-3
"""Slack (m) added to the interpolation bound for node values that are exact to ~4e-4 m only
(mesh SDFs, :mod:`scenes.sdf.mesh`)."""

_CORNERS = [(dx, dy, dz) for dx in (0, 1) for dy in (0, 1) for dz in (0, 1)]


class DistanceGrid:
    """Exact SDF samples of a static :class:`SceneSDF` on a lattice, built brick by brick.

    Args:
        sdf: the exact SDF (static: no moving obstacles).
        spacing: node spacing h (m).
        extent: (2, 3) world box the lattice covers (default: ``sdf.extent``).
    """

    def __init__(self, sdf: SceneSDF, spacing: float = DEFAULT_SPACING, extent: np.ndarray | None = None):
        if sdf.is_moving:
            raise ControlMMError("a distance grid needs static obstacles; moving ones are evaluated exactly")
        if not (math.isfinite(spacing) and spacing > 0):
            raise ControlMMError(f"grid spacing must be a positive length in metres; got {spacing}")
        box = np.asarray(sdf.extent if extent is None else extent, dtype=np.float64)
        self.sdf = sdf
        self.spacing = float(spacing)
        self.origin = box[0]
        self.cells = np.maximum(np.ceil((box[1] - box[0]) / spacing).astype(np.int64), 1)  # per axis
        self.bricks = -(-self.cells // (BRICK - 1))  # bricks per axis (ceil)
        self.bound = math.sqrt(3.0) / 2.0 * self.spacing + NODE_ERROR
        self._slot = torch.full((int(np.prod(self.bricks)),), -1, dtype=torch.long)
        self._values = torch.empty(0, BRICK**3, dtype=torch.float64)
        local = torch.arange(BRICK, dtype=torch.float64)
        self._brick_nodes = torch.stack(torch.meshgrid(local, local, local, indexing="ij"), -1).reshape(-1, 3)
        self._offsets = torch.tensor([dx * BRICK * BRICK + dy * BRICK + dz for dx, dy, dz in _CORNERS])
        self._cast: dict[tuple[torch.dtype, torch.device], Tensor] = {}
        self._consts: dict[tuple[torch.dtype, torch.device], tuple[Tensor, Tensor, Tensor, Tensor]] = {}

    @property
    def built_bricks(self) -> int:
        """How many bricks have been evaluated so far."""
        return int(self._values.shape[0])

    def _build(self, flat_ids: Tensor) -> None:
        """Evaluate the bricks ``flat_ids`` (unique, not yet built) with the exact SDF."""
        nb = self.bricks
        b = torch.stack([flat_ids // (nb[1] * nb[2]), (flat_ids // nb[2]) % nb[1], flat_ids % nb[2]], -1)
        first = (b * (BRICK - 1)).to(torch.float64)  # (M, 3) first node of each brick
        nodes = (first[:, None] + self._brick_nodes) * self.spacing + torch.as_tensor(self.origin)
        values, _ = self.sdf.value_and_gradient(nodes.reshape(1, -1, 3), None, gradient=False)
        start = self._values.shape[0]
        self._values = torch.cat([self._values, values.reshape(-1, BRICK**3)])
        self._slot[flat_ids] = torch.arange(start, start + len(flat_ids))
        self._cast.clear()

    def _values_like(self, like: Tensor) -> Tensor:
        key = (like.dtype, like.device)
        if key not in self._cast:
            self._cast[key] = self._values.to(dtype=like.dtype, device=like.device).reshape(-1)
        return self._cast[key]

    def lookup(self, points: Tensor, gradient: bool) -> tuple[Tensor, Tensor | None, Tensor]:
        """Interpolated SDF of points (P, 3) (no autograd): value (P,), its gradient (P, 3) when
        ``gradient`` (else None), and ``inside`` (P,) bool, False where a point is off the lattice
        (value +inf there, gradient 0)."""
        dtype, device = points.dtype, points.device
        key = (dtype, device)
        if key not in self._consts:
            self._consts[key] = (
                torch.as_tensor(self.origin, dtype=dtype, device=device),
                torch.as_tensor(self.cells, dtype=dtype, device=device),
                torch.as_tensor(
                    [self.bricks[1] * self.bricks[2], self.bricks[2], 1], dtype=torch.long, device=device
                ),
                torch.as_tensor([BRICK * BRICK, BRICK, 1], dtype=torch.long, device=device),
            )
        origin, cells, brick_stride, node_stride = self._consts[key]
        u = (points - origin).div_(self.spacing)  # lattice coordinates
        cell_f = u.floor()
        outside = (cell_f.amin(-1) < 0) | ((cell_f - cells).amax(-1) >= 0)
        any_outside = bool(outside.any())
        if any_outside:
            cell_f = torch.minimum(cell_f.clamp_min_(0), cells - 1)
        t = u.sub_(cell_f)  # fractions in the cell (P, 3), in [0, 1] on the lattice
        cell = cell_f.long()
        brick = torch.div(cell, BRICK - 1, rounding_mode="floor")
        flat = brick @ brick_stride  # (P,) brick index
        slot = self._slot.index_select(0, flat) if device.type == "cpu" else self._slot.to(device)[flat]
        missing = slot < 0
        if any_outside:
            missing &= ~outside
        if bool(missing.any()):
            self._build(torch.unique(flat[missing]).cpu())
            slot = self._slot.to(device).index_select(0, flat)
        if self.built_bricks == 0:  # every point is off the lattice
            far = torch.full_like(t[:, 0], float("inf"))
            return far, torch.zeros_like(points) if gradient else None, ~outside
        base = slot.clamp_min_(0).mul_(BRICK**3).add_((cell - brick * (BRICK - 1)) @ node_stride)
        index = (base[:, None] + self._offsets.to(device)).reshape(-1)
        c = self._values_like(points).index_select(0, index).view(-1, 8).T  # (8, P), _CORNERS order
        tx, ty, tz = t.T
        # along z, then y, then x: c_ij = c_ij0 + tz (c_ij1 - c_ij0), ...
        d00, d01, d10, d11 = c[1] - c[0], c[3] - c[2], c[5] - c[4], c[7] - c[6]
        c00, c01 = torch.addcmul(c[0], tz, d00), torch.addcmul(c[2], tz, d01)
        c10, c11 = torch.addcmul(c[4], tz, d10), torch.addcmul(c[6], tz, d11)
        e0, e1 = c01 - c00, c11 - c10
        c0, c1 = torch.addcmul(c00, ty, e0), torch.addcmul(c10, ty, e1)
        gx = c1 - c0
        value = torch.addcmul(c0, tx, gx)
        grad = None
        if gradient:
            gy = torch.addcmul(e0, tx, e1 - e0)
            dz0, dz1 = torch.addcmul(d00, ty, d01 - d00), torch.addcmul(d10, ty, d11 - d10)
            gz = torch.addcmul(dz0, tx, dz1 - dz0)
            grad = torch.stack([gx, gy, gz], -1).div_(self.spacing)
            if any_outside:
                grad.masked_fill_(outside[:, None], 0.0)
        if any_outside:
            value.masked_fill_(outside, float("inf"))
        return value, grad, ~outside


_GRIDS: weakref.WeakKeyDictionary[SceneSDF, dict[float, DistanceGrid]] = weakref.WeakKeyDictionary()


def distance_grid(sdf: SceneSDF, spacing: float = DEFAULT_SPACING) -> DistanceGrid:
    """The :class:`DistanceGrid` of ``sdf`` at ``spacing`` (one per SDF and spacing, shared by every
    loss on it; its bricks persist across editing runs and plan rounds)."""
    grids = _GRIDS.setdefault(sdf, {})
    if spacing not in grids:
        grids[spacing] = DistanceGrid(sdf, spacing)
    return grids[spacing]


class GridSDF:
    """A static scene's SDF, exact within ``exact_within`` metres of the obstacles and
    interpolated from a :class:`DistanceGrid` beyond (see the module docstring).

    Args:
        sdf: the exact static :class:`SceneSDF`.
        exact_within: distance (m) up to which values are exact; a loss passes its largest
            clearance.
        spacing: the lattice spacing (m).
    """

    is_moving = False

    def __init__(self, sdf: SceneSDF, exact_within: float, spacing: float = DEFAULT_SPACING) -> None:
        if not math.isfinite(exact_within):
            raise ControlMMError(f"exact_within must be a finite distance in metres; got {exact_within}")
        self.exact = sdf
        self.exact_within = float(exact_within)
        self.grid = distance_grid(sdf, spacing)

    def __call__(self, points: Tensor, t: Tensor | np.ndarray | float | None = None) -> Tensor:
        """SDF (..., N) of world points (..., N, 3); ``t`` is accepted and ignored (static scene)."""
        points = check_points(points)
        lead, n = points.shape[:-2], points.shape[-2]
        if t is not None:
            check_times(t, lead, points)
        grad = points.requires_grad and torch.is_grad_enabled()
        with torch.no_grad():
            flat = points.detach().reshape(-1, 3)
            value, gradient, inside = self.grid.lookup(flat, grad)
            near = (~inside | (value - self.grid.bound < self.exact_within)).nonzero()[:, 0]
            if len(near):
                v, g = self.exact.value_and_gradient(flat[near][None], None, grad)
                value[near] = v[0]
                if gradient is not None and g is not None:
                    gradient[near] = g[0]
        value = value.reshape(*lead, n)
        if gradient is None:
            return value
        return kernels.WithGradient.apply(points, value, gradient.reshape(points.shape))


def banded_sdf(sdf: SceneSDF, exact_within: float, spacing: float = DEFAULT_SPACING) -> SceneSDF | GridSDF:
    """``sdf`` as a loss needs it: a :class:`GridSDF` exact within ``exact_within`` m for static
    scenes with costly geoms (meshes, height fields, ellipsoids: ~6 us per point exactly, 3x
    faster through the grid); ``sdf`` itself when the obstacles move, or when they are all closed
    forms (exact evaluation then costs about what a grid lookup does)."""
    if sdf.is_moving or not sdf.has_costly_geoms:
        return sdf
    return GridSDF(sdf, exact_within, spacing)
