"""Analytic signed distance functions of MuJoCo primitive geoms, in the geom's own frame.

Every function maps local points ``p`` (..., 3) (metres, the geom frame of MuJoCo: the geom at
the origin, its axis along local +z) and sizes (..., 3) broadcastable against ``p`` to signed
distances (...,): negative inside, zero on the surface, positive outside. Sizes follow
``mujoco.MjModel.geom_size``:

===========  ==============================================================
plane        half-space z <= 0 (its size only matters for rendering)
sphere       radius r = size[0]
capsule      radius r = size[0], half-length h = size[1] of the axis segment
cylinder     radius r = size[0], half-height h = size[1]
box          half-extents (size[0], size[1], size[2])
ellipsoid    semi-axes (size[0], size[1], size[2]); exact distance (root finding)
===========  ==============================================================

All functions are differentiable with respect to ``p`` (torch autograd) and work for float32
and float64 on any device. The formulas are the ones checked against ``mj_geomDistance`` in
``docs/scenes.md``.
"""

from __future__ import annotations

import torch

Tensor = torch.Tensor


def _norm(v: Tensor) -> Tensor:
    """Euclidean norm over the last axis (gradient 0 at the origin instead of NaN)."""
    return torch.linalg.vector_norm(v, dim=-1)


def sdf_plane(p: Tensor, size: Tensor) -> Tensor:
    """Half-space below the plane z = 0: the signed distance is p_z."""
    return p[..., 2]


def sdf_sphere(p: Tensor, size: Tensor) -> Tensor:
    """Sphere of radius size[0]: ||p|| - r."""
    return _norm(p) - size[..., 0]


def sdf_capsule(p: Tensor, size: Tensor) -> Tensor:
    """Capsule of radius size[0] around the segment z in [-size[1], size[1]]."""
    r, h = size[..., 0], size[..., 1]
    z = p[..., 2] - torch.clamp(p[..., 2], -h, h)
    return _norm(torch.stack((p[..., 0], p[..., 1], z), dim=-1)) - r


def sdf_cylinder(p: Tensor, size: Tensor) -> Tensor:
    """Solid cylinder of radius size[0], z in [-size[1], size[1]]."""
    r, h = size[..., 0], size[..., 1]
    d_r = _norm(p[..., :2]) - r
    d_z = p[..., 2].abs() - h
    outside = _norm(torch.stack((d_r.clamp_min(0), d_z.clamp_min(0)), dim=-1))
    return outside + torch.maximum(d_r, d_z).clamp_max(0)


def sdf_box(p: Tensor, size: Tensor) -> Tensor:
    """Box with half-extents size[0:3]."""
    q = p.abs() - size[..., :3]
    return _norm(q.clamp_min(0)) + q.amax(dim=-1).clamp_max(0)


ELLIPSOID_NEWTON_STEPS = 8
"""Newton steps of :func:`sdf_ellipsoid` (float64 reaches ~1e-12 m on scene-sized ellipsoids)."""


def _ellipsoid_closest(p: Tensor, a: Tensor, steps: int) -> Tensor:
    """Closest surface point of the ellipsoid with semi-axes ``a`` to ``p`` (no gradient).

    The closest point is x_i = a_i^2 p_i / (a_i^2 + t) where t solves
    F(t) = sum_i (a_i p_i / (a_i^2 + t))^2 = 1 on t > -min a_i^2 (t > 0 outside, < 0 inside).
    Newton runs on phi = F^(-1/2) - 1, increasing and concave in t (a power mean of affine
    functions), so iterates started left of the root (where one term equals 1) rise
    monotonically to it; phi is exactly linear when one axis dominates, so few steps suffice.
    The unknown is s = t + min a_i^2 > 0, which keeps a_i^2 + t = (a_i^2 - min a^2) + s free of
    cancellation near the pole (points deep inside a flat ellipsoid).
    """
    dtype = torch.promote_types(p.dtype, torch.float64)
    p64, a64 = p.to(dtype), a.to(dtype).expand_as(p)
    # Points on a symmetry plane: nudge off it (the limit is the correct closest point).
    tiny = 1e-12 * a64.amax(dim=-1, keepdim=True)
    sign = torch.where(p64 >= 0, 1.0, -1.0)
    c = a64 * p64.abs().clamp_min(tiny)  # term i of F is (c_i / (a_i^2 + t))^2
    a2 = a64 * a64
    eps = a2 - a2.amin(dim=-1, keepdim=True)  # a_i^2 + t = eps_i + s
    s = (c - eps).amax(dim=-1)
    for _ in range(steps):
        u = (eps + s[..., None]) / c  # > 0
        f = (u ** -2).sum(dim=-1)
        phi = f.rsqrt() - 1.0
        dphi = f.pow(-1.5) * (u ** -3 / c).sum(dim=-1)  # d/ds F^(-1/2) = -F^(-3/2) F'/2
        s = s - phi / dphi
    u = (eps + s[..., None]) / c
    return (sign * a64 / u).to(p.dtype)


def sdf_ellipsoid(p: Tensor, size: Tensor, steps: int = ELLIPSOID_NEWTON_STEPS) -> Tensor:
    """Exact signed distance to the ellipsoid with semi-axes size[0:3].

    The closest surface point x is found without gradient (:func:`_ellipsoid_closest`); the
    distance ||p - x|| then has the exact gradient (p - x)/||p - x|| because p - x is normal to
    the surface at x, so x's own dependence on p drops out.
    """
    a = size[..., :3]
    with torch.no_grad():
        x = _ellipsoid_closest(p.detach(), a, steps)
        inside = ((p.detach() / a) ** 2).sum(dim=-1) < 1.0
    dist = _norm(p - x)
    return torch.where(inside, -dist, dist)
