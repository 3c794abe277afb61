"""Batched, autograd-free kernels behind :class:`scenes.sdf.SceneSDF`'s fast path.

They evaluate many (point, geom) pairs at once on local coordinates held as separate component
tensors ``x, y, z`` of shape (L, G, N) (L pose sets, G geoms, N points; each component is
contiguous, which keeps every op a plain vectorised loop), working in place where that saves a
pass. The formulas are those of :mod:`scenes.sdf.primitives` (which the autograd path and the
tests use), rearranged for speed:

* :func:`box_distance`: a box grown by a ball (exactly a box, a sphere or a capsule);
* :func:`cylinder_distance`: a solid cylinder;
* :func:`round_gradient`: the unit gradient of :func:`scenes.sdf.primitives.sdf_round`, which
  covers all four, at one point per (pose set, point);
* :func:`stack_frames` / :func:`to_local`: every point into every geom frame in one batched
  matmul; :class:`WithGradient`: a value with a precomputed gradient, for autograd;
* :func:`check_points` / :func:`check_times`: the inputs, checked and converted.
"""

from __future__ import annotations

import numpy as np
import torch
from torch.autograd.function import BackwardCFunction, FunctionCtx, once_differentiable

from controlmm.errors import ShapeError

Tensor = torch.Tensor


def box_distance(x: Tensor, y: Tensor, z: Tensor, box: Tensor, ball: Tensor) -> Tensor:
    """Signed distance (L, G, N) to the box of half-extents ``box`` (G, 3, 1) grown by a ball of
    radius ``ball`` (G, 1): a box (ball 0), a sphere (box 0) or a capsule (box (0, 0, h))."""
    qx = x.abs().sub_(box[:, 0])
    qy = y.abs().sub_(box[:, 1])
    qz = z.abs().sub_(box[:, 2])
    inside = torch.maximum(torch.maximum(qx, qy), qz).clamp_max_(0)
    qx, qy, qz = qx.clamp_min_(0), qy.clamp_min_(0), qz.clamp_min_(0)
    return qx.square_().addcmul_(qy, qy).addcmul_(qz, qz).sqrt_().add_(inside).sub_(ball)


def cylinder_distance(x: Tensor, y: Tensor, z: Tensor, half_height: Tensor, radius: Tensor) -> Tensor:
    """Signed distance (L, G, N) to solid cylinders along local z, ``half_height`` and
    ``radius`` (G, 1)."""
    radial = (x * x).addcmul_(y, y).sqrt_().sub_(radius)
    axial = z.abs().sub_(half_height)
    inside = torch.maximum(radial, axial).clamp_max_(0)
    radial, axial = radial.clamp_min_(0), axial.clamp_min_(0)
    return radial.square_().addcmul_(axial, axial).sqrt_().add_(inside)


def round_gradient(p: Tensor, box: Tensor, disk: Tensor) -> Tensor:
    """Gradient (L, 3, N) of :func:`scenes.sdf.primitives.sdf_round` at local points p (L, 3, N)
    with box (L, 3, N) and disk (L, N) (the ball radius does not change the gradient).

    A unit vector everywhere; on a ridge (equidistant faces inside a box, a capsule's or
    cylinder's axis) that of one of the sides, a valid subgradient.
    """
    tiny = torch.finfo(p.dtype).tiny
    q = p.abs() - box
    qx, qy, qz = q.unbind(1)
    ox, oy = qx.clamp_min(0), qy.clamp_min(0)
    r = (ox * ox).addcmul_(oy, oy).sqrt_()  # outside the xy rectangle: ds/d(qx, qy) = (ox, oy) / r
    out_xy = r > 0
    gx = torch.where(out_xy, ox / r.clamp_min(tiny), (qx >= qy).to(p.dtype))
    gy = torch.where(out_xy, oy / r.clamp_min(tiny), (qx < qy).to(p.dtype))
    s = r.add_(torch.maximum(qx, qy).clamp_max_(0)).sub_(disk)  # the rounded rectangle's 2D SDF
    os, oz = s.clamp_min(0), qz.clamp_min(0)
    h = (os * os).addcmul_(oz, oz).sqrt_()
    out = h > 0
    gs = torch.where(out, os / h.clamp_min(tiny), (s >= qz).to(p.dtype))
    gz = torch.where(out, oz / h.clamp_min(tiny), (s < qz).to(p.dtype))
    return torch.stack((gs * gx, gs.mul_(gy), gz), dim=1).copysign_(p)  # back from |p| to p


def put(target: Tensor, hit: tuple[Tensor, ...] | None, values: Tensor) -> None:
    """target[hit] = values in place; every entry (in order) when hit is None."""
    if hit is None:
        target.copy_(values.view(target.shape))
    else:
        target.index_put_(hit, values)


def stack_frames(rot_t: Tensor, pos: Tensor) -> tuple[Tensor, Tensor]:
    """Geom frames (L, G, 3, 3) geom-from-world, origins (L, G, 3) -> W (L, 3G, 3), bias (L, 3G, 1)
    with rows ordered axis-major (row k * G + g is local axis k of geom g)."""
    num_l, num_g = rot_t.shape[:2]
    weight = rot_t.transpose(1, 2).reshape(num_l, 3 * num_g, 3)
    bias = -(rot_t @ pos[..., None])[..., 0].transpose(1, 2).reshape(num_l, 3 * num_g, 1)
    return weight, bias


def to_local(p: Tensor, frames: tuple[Tensor, Tensor]) -> Tensor:
    """Points (L, N, 3) in every geom frame: (L, 3, G, N), one batched matmul."""
    weight, bias = frames
    local = torch.baddbmm(bias, weight, p.transpose(1, 2))  # (L, 3G, N)
    return local.view(p.shape[0], 3, -1, p.shape[1])


class WithGradient(torch.autograd.Function):
    """``value`` as a function of ``points`` with the given ``gradient`` (..., N, 3) (first order)."""

    @staticmethod
    def forward(ctx: FunctionCtx, points: Tensor, value: Tensor, gradient: Tensor) -> Tensor:
        ctx.save_for_backward(gradient)
        return value.clone()

    @staticmethod
    @once_differentiable
    def backward(ctx: BackwardCFunction, grad_out: Tensor) -> tuple[Tensor, None, None]:
        (gradient,) = ctx.saved_tensors
        return grad_out[..., None] * gradient, None, None


def check_points(points: Tensor | np.ndarray) -> Tensor:
    """World points (..., N, 3) as a float tensor (one-line errors for a wrong shape, NaN, inf)."""
    if not isinstance(points, Tensor):
        points = torch.as_tensor(np.asarray(points, dtype=np.float64))
    if points.ndim < 2 or points.shape[-1] != 3:
        raise ShapeError(f"points must have shape (..., N, 3); got {tuple(points.shape)}")
    if not points.is_floating_point():
        points = points.to(torch.get_default_dtype())
    if not bool(torch.isfinite(points.detach().sum())) and not bool(torch.isfinite(points.detach()).all()):
        raise ShapeError("points hold NaN or inf; the SDF needs finite world coordinates (m)")
    return points


def check_times(t: Tensor | np.ndarray | float, lead: torch.Size, like: Tensor) -> Tensor:
    """Frame times (s) broadcast to the points' leading shape ``lead``, in ``like``'s dtype and device."""
    times = torch.as_tensor(t, dtype=like.dtype, device=like.device)
    if not bool(torch.isfinite(times).all()):
        raise ShapeError("frame times hold NaN or inf")
    try:
        return torch.broadcast_to(times, lead)
    except RuntimeError:
        raise ShapeError(
            f"frame times of shape {tuple(times.shape)} do not broadcast to the points' leading "
            f"shape {tuple(lead)} (points (..., N, 3), times (...))"
        ) from None
