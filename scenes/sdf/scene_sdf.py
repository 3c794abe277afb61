"""SceneSDF: the signed distance from world points to a scene's obstacles, in torch.

``SceneSDF(scene)(points, t)`` is the minimum over the scene's obstacle geoms (every colliding
geom that is neither part of the robot nor an upward floor plane; the floor has its own loss)
of the geom's signed distance, evaluated in the geom's frame:

* primitives (plane, sphere, capsule, cylinder, box, ellipsoid): analytic, exact
  (:mod:`scenes.sdf.primitives`);
* meshes and height fields: exact point-triangle distances (:mod:`scenes.sdf.mesh`). A mesh's
  SDF is the distance to the mesh itself (concavities included) while MuJoCo collides its
  convex hull; pass ``convex_hull_meshes=True`` to get the simulator's view instead.

Shapes: points (..., N, 3) world metres; ``t`` None (obstacles at their first track pose) or
frame times in seconds broadcastable to ``points.shape[:-2]``, e.g. (T,) for (B, T, N, 3); mocap
obstacles then take their track pose at each frame's time. Output (..., N) metres, negative
inside an obstacle, +inf when the scene has no obstacles. Differentiable in ``points`` (first
order); any float dtype and device.

How a call runs (vectorised by geom kind; no Python loop over primitive geoms):

1. every point goes into every geom frame with one batched matmul (``baddbmm``; the geoms'
   poses are stacked once, or per frame for mocap obstacles);
2. without autograd, one pass per kind over all geoms of that kind (:mod:`scenes.sdf.kernels`):
   boxes, spheres and capsules (a box grown by a ball), cylinders, planes; ellipsoids and
   meshes, the costly kinds, only where a bounding-sphere lower bound of their distance is not
   above the minimum found so far (elsewhere they cannot be the minimum, so it stays exact);
3. the minimum over geoms; when ``points`` needs a gradient, the winning geom's gradient is
   computed in closed form (the SDF's exact gradient: the analytic one of
   :func:`scenes.sdf.primitives.sdf_round`, or side * (p - q) / ||p - q|| with the closest
   point q of a plane, ellipsoid or mesh) and attached by a small autograd function.

:meth:`SceneSDF.per_geom` evaluates every geom with plain autograd (the reference path).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import mujoco
import numpy as np
import torch

from controlmm.errors import ControlMMError
from scenes.sdf import kernels, primitives
from scenes.sdf.kernels import check_points, check_times
from scenes.sdf.mesh import DEFAULT_PAD, DEFAULT_PITCH, MeshSDF
from scenes.sdf.obstacles import (
    BOX,
    CYLINDER,
    ELLIPSOID,
    MESH,
    PLANE,
    ObstacleScene,
    geom_constants,
    make_geom,
    model_obstacles,
    scene_extent,
)
from scenes.tracks import MocapTrack, quat_to_mat

Tensor = torch.Tensor


_TABLE = 16
"""Columns of the per-geom table: geom-from-world rotation (9), world origin (3), sdf_round's box
half-extents (3) and disk radius (1)."""


class SceneSDF:
    """Signed distance to a scene's obstacles (see the module docstring).

    Args:
        scene: a :class:`scenes.Scene`, or a compiled ``mujoco.MjModel`` (then the obstacles are
            the colliding geoms of joint-free bodies other than upward floor planes).
        geom_ids: override the obstacle geoms.
        tracks: mocap tracks by body name (taken from the scene when it is a Scene).
        convex_hull_meshes: use meshes' convex hulls (what MuJoCo collides) instead of the meshes.
        mesh_pad, mesh_pitch: extent and node spacing of the finest level of the meshes' candidate
            grids (m); the coarser levels reach the scene's extent (see :mod:`scenes.sdf.mesh`).
    """

    def __init__(
        self,
        scene: ObstacleScene | mujoco.MjModel,
        geom_ids: Sequence[int] | None = None,
        tracks: Mapping[str, MocapTrack] | None = None,
        convex_hull_meshes: bool = False,
        mesh_pad: float = DEFAULT_PAD,
        mesh_pitch: float = DEFAULT_PITCH,
    ) -> None:
        if isinstance(scene, mujoco.MjModel):
            model = scene
            ids = model_obstacles(model) if geom_ids is None else geom_ids
            tracks = dict(tracks or {})
        else:
            model = scene.model
            ids = scene.obstacle_geom_ids if geom_ids is None else geom_ids
            tracks = dict(scene.tracks if tracks is None else tracks)
        self.model = model
        self.geom_ids = tuple(int(g) for g in ids)
        self.tracks = tracks
        self.convex_hull_meshes = convex_hull_meshes
        data = mujoco.MjData(model)
        for body, track in tracks.items():
            mocap = model.body(body).mocapid[0]
            data.mocap_pos[mocap], data.mocap_quat[mocap] = track.pose_numpy(float(track.times[0]))
        mujoco.mj_kinematics(model, data)
        start = None if isinstance(scene, mujoco.MjModel) else (scene.start.x, scene.start.y)
        self._extent = scene_extent(model, data, self.geom_ids, tracks, start)
        track_of_body = {model.body(name).id: name for name in tracks}
        moving = sorted(
            {
                track_of_body[int(model.geom_bodyid[g])]
                for g in self.geom_ids
                if int(model.geom_bodyid[g]) in track_of_body
            }
        )
        self._tracks = [tracks[name] for name in moving]  # the tracks that move obstacle geoms
        body_track = {model.body(name).id: k for k, name in enumerate(moving)}
        geoms = [
            make_geom(
                model,
                col,
                g,
                data,
                body_track,
                self._tracks,
                self._extent,
                mesh_pad,
                mesh_pitch,
                convex_hull_meshes,
            )
            for col, g in enumerate(self.geom_ids)
        ]
        self._geoms = sorted(geoms, key=lambda geom: geom.kind)  # stable: geom_ids order within a kind
        kinds = np.array([geom.kind for geom in self._geoms], dtype=np.int64)
        self._slices = {
            k: slice(int(np.searchsorted(kinds, k, "left")), int(np.searchsorted(kinds, k, "right")))
            for k in (BOX, CYLINDER, PLANE, ELLIPSOID, MESH)
        }
        self._num_round = self._slices[CYLINDER].stop  # BOX and CYLINDER columns come first
        self._consts: dict[tuple[torch.dtype, torch.device], dict[str, Tensor]] = {}

    # -- construction ---------------------------------------------------------------------------

    def _tensors(self, like: Tensor) -> dict[str, Tensor]:
        """Stacked geom constants for a dtype and device (built once per pair)."""
        key = (like.dtype, like.device)
        if key not in self._consts:
            self._consts[key] = geom_constants(self._geoms, self._slices, like)
        return self._consts[key]

    # -- public surface ---------------------------------------------------------------------------

    @property
    def is_moving(self) -> bool:
        return bool(self._tracks)

    def mesh(self, geom_id: int) -> MeshSDF:
        """The :class:`MeshSDF` of a mesh or height-field obstacle geom (in its local frame)."""
        for geom in self._geoms:
            if geom.geom_id == geom_id and geom.mesh is not None:
                return geom.mesh
        raise ControlMMError(f"geom {geom_id} is not a mesh or height-field obstacle of this SDF")

    @property
    def has_costly_geoms(self) -> bool:
        """Whether some obstacle is a mesh, height field or ellipsoid (the kinds evaluated
        iteratively, at several microseconds per point; the others are closed forms)."""
        return any(self._slices[k].stop > self._slices[k].start for k in (ELLIPSOID, MESH))

    @property
    def extent(self) -> np.ndarray:
        """(2, 3) world box (min, max corners, m) holding the obstacles (every key pose of moving
        ones), the start pose and a 1 m margin: where the scene's motions happen."""
        return self._extent.copy()

    def __call__(self, points: Tensor, t: Tensor | np.ndarray | float | None = None) -> Tensor:
        """Scene SDF (..., N) of world points (..., N, 3) at frame times ``t`` (see module doc)."""
        points = check_points(points)
        lead, n = points.shape[:-2], points.shape[-2]
        times = None if t is None else check_times(t, lead, points)
        if not self._geoms:
            return torch.full((*lead, n), float("inf"), dtype=points.dtype, device=points.device)
        grad = points.requires_grad and torch.is_grad_enabled()
        value, gradient = self.value_and_gradient(points.detach(), times, grad)
        if gradient is None:
            return value
        return kernels.WithGradient.apply(points, value, gradient)

    def value_and_gradient(
        self, points: Tensor, times: Tensor | None, gradient: bool
    ) -> tuple[Tensor, Tensor | None]:
        """The SDF (..., N) of checked world points (..., N, 3) at checked frame times (None or
        broadcast to ``points.shape[:-2]``) and, when ``gradient``, its exact gradient (..., N, 3);
        no autograd (what :meth:`__call__` attaches)."""
        lead, n = points.shape[:-2], points.shape[-2]
        if not self._geoms:
            value = torch.full((*lead, n), float("inf"), dtype=points.dtype, device=points.device)
            return value, torch.zeros_like(points) if gradient else None
        c = self._tensors(points)
        with torch.no_grad():
            p, poses, frames = self._posed(points, times, c)  # p (L, N', 3)
            local = kernels.to_local(p, frames)  # (L, 3, G, N')
            value, winner, closest = self._nearest(local, c, need_winner=gradient)
            if winner is None:  # no gradient wanted (need_winner False)
                return value.reshape(*lead, n), None
            if poses is None:
                table = c["table"]
            else:
                rot_t, pos = poses
                table = torch.cat(  # (16, L * G), see _TABLE
                    [
                        rot_t.reshape(-1, 9),
                        pos.reshape(-1, 3),
                        c["box"].repeat(rot_t.shape[0], 1),
                        c["disk"].repeat(rot_t.shape[0])[:, None],
                    ],
                    dim=1,
                ).T.contiguous()
            grad = self._winner_gradient(local, value, winner, table, closest, c)  # (L, N', 3)
        return value.reshape(*lead, n), grad.reshape(points.shape)

    def per_geom(self, points: Tensor, t: Tensor | np.ndarray | float | None = None) -> Tensor:
        """Signed distance to each obstacle geom, (..., N, G), columns in ``geom_ids`` order, every
        geom evaluated (no culling) with plain autograd."""
        points = check_points(points)
        lead, n = points.shape[:-2], points.shape[-2]
        times = None if t is None else check_times(t, lead, points)
        if not self._geoms:
            return points.new_zeros((*lead, n, 0))
        c = self._tensors(points)
        p, _, frames = self._posed(points, times, c)
        local = kernels.to_local(p, frames)  # (L, 3, G, N')
        r = self._num_round
        cols = [
            primitives.sdf_round(
                local[:, :, :r].permute(0, 2, 3, 1),
                c["box"][:r, None],
                c["disk"][:r, None],
                c["ball"][:r, None],
            ),
            local[:, 2, self._slices[PLANE]],
        ]
        s = self._slices[ELLIPSOID]
        if s.stop > s.start:
            cols.append(primitives.sdf_ellipsoid(local[:, :, s].permute(0, 2, 3, 1), c["axes"][:, None]))
        for j in range(self._slices[MESH].start, self._slices[MESH].stop):
            cols.append(self._geoms[j].mesh_sdf()(local[:, :, j].transpose(1, 2))[:, None])
        out = torch.cat(cols, dim=1)[:, c["order"]]  # (L, G, N') in geom_ids order
        return out.transpose(1, 2).reshape(*lead, n, len(self._geoms))

    # -- the steps ------------------------------------------------------------------------------

    def _posed(
        self, points: Tensor, times: Tensor | None, c: dict[str, Tensor]
    ) -> tuple[Tensor, tuple[Tensor, Tensor] | None, tuple[Tensor, Tensor]]:
        """Points as (L, N', 3) and the geom poses they meet: L = 1 (all points share the poses)
        or one per leading index (per-frame mocap poses). Returns the points, the geom-from-world
        rotations (L, G, 3, 3) and world origins (L, G, 3) of the geoms (None when static: the
        precomputed table is used), and frames = (W (L, 3G, 3), bias (L, 3G, 1)) for
        ``kernels.to_local``."""
        if not self._tracks:
            return points.reshape(1, -1, 3), None, (c["frames_weight"], c["frames_bias"])
        if times is None:
            times_k = points.new_tensor([float(tr.times[0]) for tr in self._tracks])[:, None]  # (K, 1)
            p = points.reshape(1, -1, 3)
        else:
            times_k = times.reshape(1, -1).expand(len(self._tracks), -1)  # (K, L)
            p = points.reshape(-1, points.shape[-2], 3)
        track_rot, track_pos = [], []
        for k, track in enumerate(self._tracks):
            pos_k, quat_k = track.pose(times_k[k])
            track_rot.append(quat_to_mat(quat_k))
            track_pos.append(pos_k)
        mv = c["moving"]
        body_rot = torch.stack(track_rot, dim=1)[:, c["moving_track"]]  # (L, Gm, 3, 3)
        body_pos = torch.stack(track_pos, dim=1)[:, c["moving_track"]]  # (L, Gm, 3)
        rot_m = (body_rot @ c["rot"][mv]).transpose(-1, -2)  # geom-from-world
        pos_m = body_pos + (body_rot @ c["pos"][mv][..., None])[..., 0]
        if len(mv) == len(self._geoms):
            rot_t, pos = rot_m, pos_m
        else:
            num_l = body_rot.shape[0]
            rot_t = c["rot"].transpose(-1, -2).expand(num_l, -1, -1, -1).clone()
            pos = c["pos"].expand(num_l, -1, -1).clone()
            rot_t[:, mv], pos[:, mv] = rot_m, pos_m
        return p, (rot_t, pos), kernels.stack_frames(rot_t, pos)

    def _nearest(
        self, local: Tensor, c: dict[str, Tensor], need_winner: bool
    ) -> tuple[Tensor, Tensor | None, Tensor | None]:
        """The minimum (L, N') over geoms of points in every geom frame ``local`` (L, 3, G, N');
        when ``need_winner``, also its geom (kind-sorted index, (L, N')) and the closest points
        (L, 3, G - G_round, N') of the plane, ellipsoid and mesh columns (written where
        evaluated). No autograd."""
        num_l, _, num_g, num_n = local.shape
        x, y, z = local.unbind(1)  # (L, G, N') each
        first_cp = self._num_round
        closest: Tensor | None = None
        closest_v: Tensor | None = None
        if need_winner and num_g > first_cp:
            closest = local.new_zeros((num_l, 3, num_g - first_cp, num_n))
            closest_v = closest.permute(0, 2, 3, 1)  # (L, G - G_round, N', 3) view, for writing
        best: Tensor | None = None
        winner: Tensor | None = None

        def merge(d: Tensor, offset: int) -> None:  # fold distances d (L, Gk, N') into best / winner
            nonlocal best, winner
            if need_winner:
                v, i = d.min(dim=1)
                i = i + offset
                winner = i if best is None or winner is None else torch.where(v < best, i, winner)
            else:
                v = d.amin(dim=1)
            best = v if best is None else torch.minimum(best, v)

        s = self._slices[BOX]
        if s.stop > s.start:
            merge(kernels.box_distance(x[:, s], y[:, s], z[:, s], c["box_half"], c["box_ball"]), s.start)
        s = self._slices[CYLINDER]
        if s.stop > s.start:
            merge(
                kernels.cylinder_distance(x[:, s], y[:, s], z[:, s], c["cyl_half"], c["cyl_radius"]), s.start
            )
        s = self._slices[PLANE]
        if s.stop > s.start:
            if closest is not None:  # need_winner (planes follow the round geoms)
                cp = slice(s.start - first_cp, s.stop - first_cp)
                closest[:, 0:2, cp] = local[:, 0:2, s]
            merge(z[:, s], s.start)
        s = self._slices[ELLIPSOID]
        if s.stop > s.start:
            xe, ye, ze = x[:, s], y[:, s], z[:, s]
            d = (
                (xe * xe).addcmul_(ye, ye).addcmul_(ze, ze).sqrt_().sub_(c["axes_max"][:, None])
            )  # lower bound
            pts = local[:, :, s].permute(0, 2, 3, 1)  # (L, Ge, N', 3)
            cp = slice(s.start - first_cp, s.stop - first_cp)
            if best is None:  # nothing to cull against: every pair
                hit, pts, axes = (
                    None,
                    pts.reshape(-1, 3),
                    c["axes"][None, :, None].expand_as(pts).reshape(-1, 3),
                )
            else:
                hit = (d <= best[:, None]).nonzero(as_tuple=True)
                pts, axes = pts[hit], c["axes"].index_select(0, hit[1])
            if len(pts):
                q = primitives._ellipsoid_closest(pts, axes, primitives.ELLIPSOID_NEWTON_STEPS)
                inside = (pts / axes).square_().sum(dim=-1).sub_(1.0)  # < 0 inside
                exact = torch.linalg.vector_norm(pts - q, dim=-1).copysign_(inside)
                kernels.put(d, hit, exact)
                if closest_v is not None:  # need_winner
                    kernels.put(closest_v[:, cp], hit, q)
            merge(d, s.start)
        for j in range(self._slices[MESH].start, self._slices[MESH].stop):
            pts = local[:, :, j].transpose(1, 2)  # (L, N', 3)
            k = j - self._slices[MESH].start
            d = (
                torch.linalg.vector_norm(pts - c["mesh_centre"][k], dim=-1) - c["mesh_radius"][k]
            )  # lower bound
            hit = None if best is None else (d <= best).nonzero(as_tuple=True)
            pts = pts.reshape(-1, 3) if hit is None else pts[hit]
            if len(pts):
                q, sgn = self._geoms[j].mesh_sdf().closest(pts.contiguous())
                kernels.put(d, hit, sgn * torch.linalg.vector_norm(pts - q, dim=-1))
                if closest_v is not None:  # need_winner
                    kernels.put(closest_v[:, j - first_cp], hit, q)
            merge(d[:, None], j)
        if best is None:
            raise RuntimeError("SceneSDF._nearest needs at least one obstacle geom")
        return best, winner, closest

    def _winner_gradient(
        self,
        local: Tensor,
        value: Tensor,
        winner: Tensor,
        table: Tensor,
        closest: Tensor | None,
        c: dict[str, Tensor],
    ) -> Tensor:
        """World gradient (L, N', 3) of the SDF ``value`` (L, N') from the points in every geom frame
        ``local`` (L, 3, G, N') and the winning geom (L, N'). No autograd."""
        num_l, _, num_g, num_n = local.shape
        lw = local.gather(2, winner[:, None, None, :].expand(-1, 3, 1, -1))[:, :, 0]  # (L, 3, N')
        flat = winner if num_l == 1 else winner + (torch.arange(num_l, device=winner.device) * num_g)[:, None]
        row = (
            table.index_select(1, flat.reshape(-1)).view(_TABLE, num_l, num_n).transpose(0, 1)
        )  # (L, 16, N')
        first_cp = self._num_round
        g = kernels.round_gradient(lw, row[:, 12:15], row[:, 15]) if first_cp > 0 else None
        if (
            closest is not None
        ):  # planes, ellipsoids, meshes: side (p - q) / ||p - q|| = (p - q) value / ||p - q||^2
            k = c["closest_column"][winner]
            diff = lw - closest.gather(2, k[:, None, None, :].expand(-1, 3, 1, -1))[:, :, 0]
            x, y, z = diff.unbind(1)
            norm2 = (x * x).addcmul_(y, y).addcmul_(z, z).clamp_min_(torch.finfo(diff.dtype).tiny)
            g_cp = diff.mul_((value / norm2)[:, None])
            g = g_cp if g is None else torch.where((winner >= first_cp)[:, None], g_cp, g)
        if g is None:
            raise RuntimeError("SceneSDF._winner_gradient needs at least one obstacle geom")
        world = row[:, 0:3] * g[:, 0:1]  # R g = sum_k g_k (row k of R^T)
        world.addcmul_(row[:, 3:6], g[:, 1:2]).addcmul_(row[:, 6:9], g[:, 2:3])
        return world.transpose(1, 2)
