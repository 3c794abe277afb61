"""Scene SDF benchmark: accuracy against MuJoCo / exact mesh distances, and speed.

    python benchmarks/scene_sdf.py [--points 10000] [--repeats 50] [--threads N]

Accuracy: per packaged scene, random points (half uniform over the scene's extent: obstacles
and start pose grown by 0.6 m, floor level and up; half within 5 cm of obstacle surfaces'
bounding boxes) at random times on moving obstacles' tracks; reference = MuJoCo's
``mj_geomDistance`` with a 1e-6 m probe sphere (tight GJK/EPA tolerances), except for meshes,
whose reference is trimesh's exact signed distance to the mesh (MuJoCo collides the convex
hull; the 'hull' row compares SceneSDF(convex_hull_meshes=True) with MuJoCo). Far field: the
mesh error by distance band, out to 4 m. Speed: SDF + gradient per call for 196 x 22 (or 100)
points (min and median of repeats), with the load average before and after.
"""

from __future__ import annotations

import argparse
import os
import platform
import time

import mujoco
import numpy as np
import torch
import trimesh

from scenes import SceneSDF, list_scenes, load_scene
from scenes.probe import add_probe, probe_distances
from scenes.render import scene_bounds


def _points(scene, n: int, rng: np.random.Generator) -> np.ndarray:
    lo, hi = scene_bounds(scene)  # obstacles (every track pose) and start pose, grown by 0.6 m
    lo[2] = max(lo[2], -0.1)
    m, d = scene.model, mujoco.MjData(scene.model)
    mujoco.mj_kinematics(m, d)
    boxes = []
    for g in scene.obstacle_geom_ids:
        centre = d.geom_xpos[g] + d.geom_xmat[g].reshape(3, 3) @ m.geom_aabb[g, :3]
        half = np.abs(d.geom_xmat[g].reshape(3, 3)) @ m.geom_aabb[g, 3:] + 0.05
        boxes.append((centre - half, centre + half))
    near = [rng.uniform(*boxes[k]) for k in rng.integers(len(boxes), size=n // 2)]
    return np.concatenate([rng.uniform(lo, hi, (n - n // 2, 3)), np.stack(near)])


def _world_meshes(scene) -> list[trimesh.Trimesh]:
    m, d = scene.model, mujoco.MjData(scene.model)
    mujoco.mj_kinematics(m, d)
    meshes = []
    for g in scene.obstacle_geom_ids:
        mid = m.geom_dataid[g]
        v = m.mesh_vert[m.mesh_vertadr[mid] : m.mesh_vertadr[mid] + m.mesh_vertnum[mid]]
        f = m.mesh_face[m.mesh_faceadr[mid] : m.mesh_faceadr[mid] + m.mesh_facenum[mid]]
        rot = d.geom_xmat[g].reshape(3, 3)
        meshes.append(trimesh.Trimesh(v @ rot.T + d.geom_xpos[g], f, process=True))
    return meshes


def _mesh_reference(scene, points: np.ndarray) -> np.ndarray:
    out = np.full(len(points), np.inf)
    for mesh in _world_meshes(scene):
        out = np.minimum(out, -trimesh.proximity.signed_distance(mesh, points))
    return out


def accuracy(n: int, seed: int = 0) -> list[tuple]:
    rows = []
    for name in list_scenes():
        scene = load_scene(name, robot=None, edit_spec=add_probe)
        if not scene.obstacle_geom_ids:
            continue
        rng = np.random.default_rng(seed)
        has_mesh = any(
            scene.model.geom_type[g] == mujoco.mjtGeom.mjGEOM_MESH for g in scene.obstacle_geom_ids
        )
        pts = _points(scene, n, rng)
        times = rng.uniform(0.0, 6.0, n) if scene.tracks else np.zeros(n)
        t0 = time.perf_counter()
        sdf = scene.sdf()
        build = time.perf_counter() - t0
        out = sdf(torch.as_tensor(pts)[:, None, :], torch.as_tensor(times))[:, 0].numpy()
        data = mujoco.MjData(scene.model)
        if has_mesh:
            ref = _mesh_reference(scene, pts)
            reference = "trimesh exact"
        else:
            ref = np.empty(n)
            for i in range(n):
                scene.set_time(data, times[i])
                ref[i] = probe_distances(scene.model, scene.obstacle_geom_ids, pts[i : i + 1], data).min()
            reference = "mj_geomDistance"
        rows.append(
            (
                name,
                len(scene.obstacle_geom_ids),
                reference,
                n,
                int((ref < 0).sum()),
                np.abs(out - ref).max(),
                int((np.sign(out) != np.sign(ref)).sum()),
                build,
            )
        )
        if has_mesh:
            hull = SceneSDF(scene, convex_hull_meshes=True)(torch.as_tensor(pts)).numpy()
            mj = probe_distances(scene.model, scene.obstacle_geom_ids, pts, data).min(1)
            rows.append(
                (
                    f"{name} (hull)",
                    len(scene.obstacle_geom_ids),
                    "mj_geomDistance",
                    n,
                    int((mj < 0).sum()),
                    np.abs(hull - mj).max(),
                    int((np.sign(hull) != np.sign(mj)).sum()),
                    float("nan"),
                )
            )
    return rows


def far_field(name: str = "mesh_rock", per_band: int = 1000, seed: int = 0) -> list[tuple]:
    """Mesh SDF error by distance from the mesh: points on random rays from the mesh's centre,
    at distances (from the centre) drawn per band, binned by their true distance."""
    scene = load_scene(name, robot=None)
    (mesh,) = _world_meshes(scene)
    rng = np.random.default_rng(seed)
    radius = float(np.linalg.norm(mesh.vertices - mesh.centroid, axis=1).max())
    dirs = rng.normal(size=(6 * per_band, 3))
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    pts = mesh.centroid + dirs * rng.uniform(0.0, radius + 4.2, (len(dirs), 1))
    ref = -trimesh.proximity.signed_distance(mesh, pts)
    rows = []
    for dtype in (torch.float64, torch.float32):
        out = scene.sdf()(torch.as_tensor(pts, dtype=dtype)).double().numpy()
        err = np.abs(out - ref)
        for lo, hi in [(-1.0, 0.0), (0.0, 0.1), (0.1, 0.5), (0.5, 1.0), (1.0, 2.0), (2.0, 3.0), (3.0, 4.0)]:
            k = (ref >= lo) & (ref < hi)
            rows.append(
                (
                    str(dtype).removeprefix("torch."),
                    "inside" if hi <= 0 else f"{lo:g}-{hi:g} m",
                    int(k.sum()),
                    float(err[k].max()),
                    float(np.median(err[k])),
                    int((np.sign(out[k]) != np.sign(ref[k])).sum()),
                )
            )
    return rows


def speed(
    name: str, dtype: torch.dtype, repeats: int, points_per_frame: int = 22, moving_t: bool = False
) -> tuple:
    scene = load_scene(name, robot=None)
    sdf = scene.sdf()
    lo, hi = scene_bounds(scene)
    gen = torch.Generator().manual_seed(0)
    pts = (
        torch.rand(196, points_per_frame, 3, generator=gen, dtype=torch.float64) * torch.as_tensor(hi - lo)
        + torch.as_tensor(lo)
    ).to(dtype)
    times = torch.arange(196, dtype=dtype) / 20 if moving_t else None
    samples = []
    for k in range(repeats + 5):
        x = pts.clone().requires_grad_(True)
        t0 = time.perf_counter()
        value = sdf(x, times)
        value.sum().backward()
        if k >= 5:
            samples.append(time.perf_counter() - t0)
    return (
        name,
        len(scene.obstacle_geom_ids),
        str(dtype).removeprefix("torch."),
        f"196x{points_per_frame}",
        1e3 * min(samples),
        1e3 * float(np.median(samples)),
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--points", type=int, default=10_000)
    parser.add_argument("--repeats", type=int, default=50)
    parser.add_argument("--threads", type=int, default=None, help="torch threads (default: torch's own)")
    args = parser.parse_args()
    if args.threads:
        torch.set_num_threads(args.threads)
    print(
        f"machine: {platform.machine()}, {os.cpu_count()} CPUs, {torch.get_num_threads()} torch threads, "
        f"torch {torch.__version__}, mujoco {mujoco.__version__}, trimesh {trimesh.__version__}"
    )
    print("\naccuracy (metres)")
    print(
        f"{'scene':24s} {'geoms':>5s}  {'reference':16s} {'points':>6s} {'inside':>6s} {'max |err|':>10s} "
        f"{'sign errs':>9s} {'build s':>7s}"
    )
    for row in accuracy(args.points):
        print(
            f"{row[0]:24s} {row[1]:5d}  {row[2]:16s} {row[3]:6d} {row[4]:6d} {row[5]:10.2e} "
            f"{row[6]:9d} {row[7]:7.2f}"
        )
    print("\nmesh far field (mesh_rock, trimesh exact; by true distance from the mesh)")
    print(f"{'dtype':8s} {'band':>10s} {'points':>6s} {'max |err|':>10s} {'median':>10s} {'sign errs':>9s}")
    for row in far_field():
        print(f"{row[0]:8s} {row[1]:>10s} {row[2]:6d} {row[3]:10.2e} {row[4]:10.2e} {row[5]:9d}")
    print(f"\nspeed: SDF + gradient per call (ms); load average before: {_load()}")
    print(f"{'scene':16s} {'geoms':>5s} {'dtype':>8s} {'points':>8s} {'min':>7s} {'median':>7s}")
    for name, dtype, ppf, moving in [
        ("room", torch.float32, 22, False),
        ("room", torch.float64, 22, False),
        ("moving_obstacle", torch.float32, 22, True),
        ("mesh_rock", torch.float32, 22, False),
        ("room", torch.float32, 100, False),
    ]:
        row = speed(name, dtype, args.repeats, ppf, moving)
        print(f"{row[0]:16s} {row[1]:5d} {row[2]:>8s} {row[3]:>8s} {row[4]:7.2f} {row[5]:7.2f}")
    print(f"load average after: {_load()}")


def _load() -> str:
    return " ".join(f"{v:.2f}" for v in os.getloadavg())


if __name__ == "__main__":
    main()
