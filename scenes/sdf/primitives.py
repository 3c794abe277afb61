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

:func:`sdf_round` covers sphere, capsule, cylinder and box with one formula (a box grown by a
horizontal disk and a ball, see :func:`round_params`), so a scene evaluates all geoms of those
types in one vectorised pass.

All functions are differentiable with respect to ``p`` (torch autograd) and work for float32
and float64 on any device. The formulas are the ones checked against ``mj_geomDistance`` in
``docs/scenes.md``.
"""

from __future__ import annotations

from collections.abc import Iterable

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


def sdf_round(p: Tensor, box: Tensor, disk: Tensor, ball: Tensor) -> Tensor:
    """The solid box(half-extents ``box`` (..., 3)) + disk(radius ``disk`` (...,), in the xy plane)
    + ball(radius ``ball`` (...,)) (a Minkowski sum), exact inside and out.

    The disk-grown box is the extrusion along z of a rounded rectangle, whose 2D SDF ``s`` is the
    rectangle's minus ``disk``; the extrusion's SDF is the 2D box formula on (s, |z| - box_z);
    growing a convex solid by a ball subtracts ``ball`` everywhere. With :func:`round_params`
    this is exactly :func:`sdf_sphere`, :func:`sdf_capsule`, :func:`sdf_cylinder` or :func:`sdf_box`.
    """
    q = p.abs() - box
    s = _norm(q[..., :2].clamp_min(0)) + torch.maximum(q[..., 0], q[..., 1]).clamp_max(0) - disk
    w = torch.stack((s, q[..., 2]), dim=-1)
    return _norm(w.clamp_min(0)) + w.amax(dim=-1).clamp_max(0) - ball


def round_params(geom_type: str, size: Iterable[float]) -> tuple[tuple[float, float, float], float, float]:
    """(box half-extents, disk radius, ball radius) of :func:`sdf_round` for a MuJoCo sphere,
    capsule, cylinder or box of ``geom_size`` ``size``."""
    s = [float(v) for v in size]
    if geom_type == "sphere":
        return (0.0, 0.0, 0.0), 0.0, s[0]
    if geom_type == "capsule":
        return (0.0, 0.0, s[1]), 0.0, s[0]
    if geom_type == "cylinder":
        return (0.0, 0.0, s[1]), s[0], 0.0
    if geom_type == "box":
        return (s[0], s[1], s[2]), 0.0, 0.0
    raise ValueError(f"round_params: '{geom_type}' is not a sphere, capsule, cylinder or box")


ELLIPSOID_NEWTON_STEPS = 16
"""Most Newton steps of :func:`sdf_ellipsoid` (it stops once converged: 5-7 steps for round
ellipsoids, ~10 for flat or needle-like ones; float64 then reaches ~1e-12 m)."""


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
    c = a64 * p64.abs().clamp_min(tiny)  # term i of F is (c_i / (a_i^2 + t))^2
    a2 = a64 * a64
    eps = a2 - a2.amin(dim=-1, keepdim=True)  # a_i^2 + t = eps_i + s
    s = (c - eps).amax(dim=-1, keepdim=True)
    for step in range(steps):
        # With e = eps + s and r = c / e: F = sum r^2, F' = -2 sum r^2 / e, and the Newton step
        # on phi = F^(-1/2) - 1 is -phi / phi' = F (sqrt F - 1) / sum(r^2 / e).
        e = eps + s
        r2 = (c / e).square_()
        f = r2.sum(dim=-1, keepdim=True)
        delta = (f * (f.sqrt() - 1.0)).div_((r2 / e).sum(dim=-1, keepdim=True))
        s = s.add_(delta)
        # Quadratic convergence: once every step is below 1e-9 of s, the next would be ~1e-18.
        if step >= 4 and bool((delta.abs() <= 1e-9 * s).all()):
            break
    x = (a64 * c / (eps + s)).copysign_(p64)  # a_i^2 p_i / (a_i^2 + t), the sign of p_i
    return x.to(p.dtype)


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
