"""SceneSDF against MuJoCo's own distances (probe sphere), trimesh's exact mesh distance, tracks,
gradients, dtypes and errors."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest
import torch
import trimesh
from scene_helpers import PRIMITIVES_XML, heightfield_xml

from controlmm.errors import ControlMMError
from scenes import SceneSDF, load_scene
from scenes.probe import add_probe, probe_distances
from scenes.render import scene_bounds
from scenes.sdf import primitives as formulas
from scenes.sdf.mesh import closed_mesh


def _probe_scene(tmp_path, xml: str, name: str = "s.xml"):
    path = tmp_path / name
    path.write_text(xml)
    return load_scene(str(path), robot=None, edit_spec=add_probe)


def _geom_frame(model, data, g):
    return data.geom_xpos[g].copy(), data.geom_xmat[g].reshape(3, 3).copy()


@pytest.fixture(scope="module")
def primitives(tmp_path_factory):
    scene = _probe_scene(tmp_path_factory.mktemp("prim"), PRIMITIVES_XML)
    data = mujoco.MjData(scene.model)
    mujoco.mj_kinematics(scene.model, data)
    return scene, data


@pytest.mark.parametrize("geom", ["sphere", "capsule", "cylinder", "box", "ellipsoid", "wall_plane"])
def test_primitive_sdf_matches_mujoco(primitives, geom):
    scene, data = primitives
    m = scene.model
    g = m.geom(geom).id
    assert g in scene.obstacle_geom_ids
    centre, rot = _geom_frame(m, data, g)
    rng = np.random.default_rng(g)
    reach = m.geom_rbound[g] or 1.0  # bounding radius (0 for planes)
    local = rng.uniform(-1.2, 1.2, (600, 3)) * reach
    points = centre + local @ rot.T
    ref = probe_distances(m, [g], points, data)[:, 0]
    sdf = SceneSDF(scene, geom_ids=[g])
    out = sdf(torch.as_tensor(points)).numpy()
    assert (ref < 0).sum() > 20 and (ref > 0).sum() > 20  # inside and outside both tested
    tol = 1e-6 if geom == "ellipsoid" else 1e-9
    assert np.abs(out - ref).max() < tol
    assert np.array_equal(np.sign(out), np.sign(ref))


def test_union_over_geoms_and_floor_excluded(primitives):
    scene, data = primitives
    m = scene.model
    sdf = scene.sdf()
    assert m.geom("floor").id not in sdf.geom_ids and len(sdf.geom_ids) == 6
    rng = np.random.default_rng(1)
    points = rng.uniform([-1, -1, -0.5], [5.5, 2, 1.5], (400, 3))
    ref = probe_distances(m, sdf.geom_ids, points, data)
    out = sdf.per_geom(torch.as_tensor(points)).numpy()
    assert np.abs(out - ref).max() < 1e-6
    assert np.abs(sdf(torch.as_tensor(points)).numpy() - ref.min(1)).max() < 1e-6


@pytest.fixture(scope="module")
def rock():
    scene = load_scene("mesh_rock", robot=None, edit_spec=add_probe)
    m = scene.model
    g = scene.obstacle_geom_ids[0]
    data = mujoco.MjData(m)
    mujoco.mj_kinematics(m, data)
    mid = m.geom_dataid[g]
    v = m.mesh_vert[m.mesh_vertadr[mid] : m.mesh_vertadr[mid] + m.mesh_vertnum[mid]]
    f = m.mesh_face[m.mesh_faceadr[mid] : m.mesh_faceadr[mid] + m.mesh_facenum[mid]]
    centre, rot = _geom_frame(m, data, g)
    mesh = trimesh.Trimesh(v @ rot.T + centre, f, process=True)  # the rock in world coordinates
    return scene, data, g, mesh


def _rock_points(mesh, n, seed):
    rng = np.random.default_rng(seed)
    lo, hi = mesh.bounds
    near = mesh.sample(n // 2, seed=seed) + rng.normal(scale=0.05, size=(n // 2, 3))
    return np.concatenate([rng.uniform(lo - 0.25, hi + 0.25, (n - n // 2, 3)), near])


def test_mesh_sdf_matches_exact_trimesh_distance(rock):
    scene, data, g, mesh = rock
    points = _rock_points(mesh, 1500, 0)
    ref = -trimesh.proximity.signed_distance(mesh, points)  # trimesh: positive inside
    out = scene.sdf()(torch.as_tensor(points)).numpy()
    assert (ref < 0).sum() > 250 and (ref > 0).sum() > 250
    err = np.abs(out - ref)
    assert err.max() < 1e-3 and np.median(err) < 1e-9
    assert np.array_equal(np.sign(out), np.sign(ref))


def test_mesh_sdf_is_accurate_far_from_the_mesh(rock):
    """Across the whole scene (start pose included) and out to ~4 m from the rock: the nested
    grids keep the error far below 1 cm (the old single grid reached ~6 cm at 1.5 m)."""
    scene, data, g, mesh = rock
    rng = np.random.default_rng(2)
    lo, hi = scene_bounds(scene)  # obstacles + start pose + 0.6 m
    directions = rng.normal(size=(300, 3))
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    shell = mesh.centroid + directions * rng.uniform(2.5, 4.5, (300, 1))
    points = np.concatenate([rng.uniform(lo, hi, (900, 3)), shell])
    ref = -trimesh.proximity.signed_distance(mesh, points)
    for dtype in (torch.float64, torch.float32):
        out = scene.sdf()(torch.as_tensor(points, dtype=dtype)).double().numpy()
        assert np.abs(out - ref).max() < 1e-3
        assert np.array_equal(np.sign(out), np.sign(ref))
    far = ref > 1.5
    assert far.sum() > 400 and ref.max() > 3.0


def test_mesh_convex_hull_mode_matches_mujoco(rock):
    scene, data, g, mesh = rock
    points = _rock_points(mesh, 600, 1)
    ref = probe_distances(scene.model, [g], points, data)[:, 0]  # MuJoCo collides the hull
    hull = SceneSDF(scene, convex_hull_meshes=True)(torch.as_tensor(points)).numpy()
    exact = scene.sdf()(torch.as_tensor(points)).numpy()
    err = np.abs(hull - ref)
    assert err.max() < 1e-3 and np.median(err) < 1e-6
    assert np.all(hull <= exact + 1e-6)  # the hull contains the rock
    assert (exact - hull).max() > 0.03  # the dents are real


def test_heightfield_sdf(tmp_path):
    rng = np.random.default_rng(3)
    scene = _probe_scene(tmp_path, heightfield_xml(rng.uniform(0, 1, (6, 8))), "hf.xml")
    m = scene.model
    data = mujoco.MjData(m)
    mujoco.mj_kinematics(m, data)
    g = m.geom("terrain").id
    centre, rot = _geom_frame(m, data, g)
    sdf = SceneSDF(scene, geom_ids=[g])
    # The top surface (triangulation included) is MuJoCo's: compare heights seen by rays.
    local = np.column_stack([rng.uniform(-0.99, 0.99, 300), rng.uniform(-0.59, 0.59, 300), np.full(300, 2.0)])
    geomid = np.zeros(1, np.int32)
    for p in local[:40]:
        hit = mujoco.mj_ray(m, data, centre + rot @ p, -rot[:, 2].copy(), None, 1, -1, geomid)
        top = centre + rot @ (p - [0, 0, hit])  # the surface point under p
        assert abs(float(sdf(torch.as_tensor(top[None]))[0])) < 1e-9
    # Distances: against trimesh's exact distance to the same closed solid.
    mesh = sdf.mesh(g)
    solid = trimesh.Trimesh(mesh.vertices, mesh.faces)
    pts = rng.uniform([-1.2, -0.8, -0.2], [1.2, 0.8, 0.7], (600, 3))
    ref = -trimesh.proximity.signed_distance(solid, pts)
    out = sdf(torch.as_tensor(centre + pts @ rot.T)).numpy()
    assert (ref < 0).sum() > 40 and np.abs(out - ref).max() < 0.01 and np.median(np.abs(out - ref)) < 1e-6


def test_moving_obstacle_sdf_follows_track():
    scene = load_scene("moving_obstacle", robot=None, edit_spec=add_probe)
    m = scene.model
    data = mujoco.MjData(m)
    sdf = scene.sdf()
    assert sdf.is_moving
    rng = np.random.default_rng(4)
    times = np.array([0.0, 0.7, 2.5, 3.3, 5.0, 7.0])
    points = rng.uniform([1.2, -3.0, 0.0], [3.2, 3.0, 1.2], (len(times), 200, 3))
    out = sdf(torch.as_tensor(points[None]), torch.as_tensor(times)).numpy()[0]  # (1, T, N, 3), t (T,)
    assert out.shape == (len(times), 200)
    for k, t in enumerate(times):
        scene.set_time(data, t)
        ref = probe_distances(m, sdf.geom_ids, points[k], data).min(1)
        assert np.abs(out[k] - ref).max() < 1e-9
    # A point on the path is inside the cart at 2.5 s only.
    p = torch.tensor([[[2.2, 0.0, 0.5]]], dtype=torch.float64).expand(3, 1, 3)
    values = sdf(p, torch.tensor([0.0, 2.5, 5.0]))[:, 0]
    assert values[1] < -0.2 and values[0] > 1.5 and values[2] > 1.5
    assert torch.allclose(sdf(p[:1, 0]), values[:1])  # t=None: the track's first pose


@pytest.mark.parametrize("scene_name", ["room", "mesh_rock", "moving_obstacle"])
def test_gradients_match_finite_differences(scene_name):
    scene = load_scene(scene_name, robot=None)
    sdf = scene.sdf()
    rng = np.random.default_rng(5)
    lo = np.array([-1.0, -2.5, 0.0]) if scene_name == "room" else np.array([1.0, -1.0, 0.0])
    points = torch.as_tensor(rng.uniform(lo, lo + [5.0, 5.0, 1.6], (64, 3)), dtype=torch.float64)
    times = torch.as_tensor(rng.uniform(0, 5, 64))
    points.requires_grad_(True)
    value = sdf(points[:, None, :], times)[:, 0]
    (grad,) = torch.autograd.grad(value.sum(), points)
    eps = 1e-6
    for axis in range(3):
        step = torch.zeros(3, dtype=torch.float64)
        step[axis] = eps
        with torch.no_grad():
            fd = (sdf((points + step)[:, None], times) - sdf((points - step)[:, None], times))[:, 0] / (
                2 * eps
            )
        assert torch.allclose(grad[:, axis], fd, atol=1e-4)
    assert torch.allclose(
        grad.norm(dim=-1), torch.ones(64, dtype=torch.float64), atol=1e-6
    )  # an SDF: |grad| = 1


def test_dtypes_devices_shapes_and_empty_scene():
    scene = load_scene("room", robot=None)
    sdf = scene.sdf()
    p64 = torch.rand(2, 5, 7, 3, dtype=torch.float64) * 4
    out64 = sdf(p64)
    out32 = sdf(p64.float())
    assert out64.shape == (2, 5, 7) and out64.dtype == torch.float64 and out32.dtype == torch.float32
    assert torch.allclose(out32.double(), out64, atol=1e-5)
    if torch.cuda.is_available():
        assert torch.allclose(sdf(p64.cuda()).cpu(), out64, atol=1e-9)
    empty = load_scene("empty", robot=None).sdf()
    assert torch.isinf(empty(p64)).all() and empty.per_geom(p64).shape == (2, 5, 7, 0)


def test_sdf_errors(tmp_path):
    sdf = load_scene("pillars", robot=None).sdf()
    bad = torch.zeros(4, 3)
    bad[1, 2] = float("nan")
    with pytest.raises(ControlMMError, match="NaN"):
        sdf(bad)
    with pytest.raises(ControlMMError, match=r"\(\.\.\., N, 3\)"):
        sdf(torch.zeros(4, 2))
    with pytest.raises(ControlMMError, match="broadcast"):
        sdf(torch.zeros(2, 4, 3), torch.zeros(3))
    torus = tmp_path / "torus.xml"
    torus.write_text(
        '<mujoco><extension><plugin plugin="mujoco.sdf.torus"><instance name="torus">'
        '<config key="radius1" value="0.35"/><config key="radius2" value="0.15"/>'
        "</instance></plugin></extension>"
        '<asset><mesh name="torus"><plugin instance="torus"/></mesh></asset><worldbody><body name="t">'
        '<geom name="donut" type="sdf" mesh="torus"><plugin instance="torus"/></geom>'
        "</body></worldbody></mujoco>"
    )
    with pytest.raises(ControlMMError, match="geom 'donut' has type 'sdf'"):
        load_scene(str(torus), robot=None).sdf()


def test_open_mesh_falls_back_to_its_convex_hull():
    box = trimesh.creation.box(extents=(1, 1, 1))
    opened, is_hull = closed_mesh(box.vertices, box.faces[:-1])  # one triangle missing
    assert is_hull and opened.is_watertight and opened.is_convex
    closed, is_hull = closed_mesh(box.vertices, box.faces[:, ::-1])  # inward winding is fixed
    assert not is_hull and closed.volume > 0


EVERY_PRIMITIVE_XML = """<mujoco>
  <custom>
    <numeric name="controlmm.track.cart"
             data="0  1 -1 0.5  1 0 0 0   2  1 1 0.7  0.7071 0 0 0.7071   4  2 1 0.6  0 0 0 1"/>
    <numeric name="controlmm.track.ball" data="0  3 0 1  1 0 0 0   3  3 0.5 0.4  0.9239 0.3827 0 0"/>
  </custom>
  <worldbody>
    <geom name="floor" type="plane" size="0 0 0.05"/>
    <body name="static" pos="0.2 -0.1 0.4" euler="12 -25 40">
      <geom name="s_sphere" type="sphere" size="0.25" pos="-0.5 0.3 0"/>
      <geom name="s_capsule" type="capsule" size="0.15 0.35" pos="0.4 0 0" euler="30 50 0"/>
      <geom name="s_cylinder" type="cylinder" size="0.2 0.3" pos="0 0.8 0" euler="0 70 20"/>
      <geom name="s_box" type="box" size="0.3 0.15 0.4" pos="0 -0.8 0.2" euler="15 0 60"/>
      <geom name="s_ellipsoid" type="ellipsoid" size="0.4 0.15 0.25" pos="-0.9 -0.6 0.1" euler="-20 35 10"/>
      <geom name="s_wall" type="plane" size="1 1 0.1" pos="-2 0 0" euler="0 -90 0"/>
    </body>
    <body name="cart" mocap="true">
      <geom name="m_box" type="box" size="0.25 0.2 0.1" pos="0.1 0 0.05" euler="0 0 20"/>
      <geom name="m_ellipsoid" type="ellipsoid" size="0.3 0.2 0.1" pos="0 0.3 0.2" euler="10 20 30"/>
      <geom name="m_cylinder" type="cylinder" size="0.1 0.25" pos="-0.3 0 0" euler="90 0 0"/>
    </body>
    <body name="ball" mocap="true">
      <geom name="m_sphere" type="sphere" size="0.2"/>
      <geom name="m_capsule" type="capsule" size="0.05 0.3" pos="0 0 -0.4" euler="0 90 0"/>
      <geom name="m_plane" type="plane" size="0.5 0.5 0.1" pos="0 0 -1.5" euler="180 0 0"/>
    </body>
  </worldbody>
</mujoco>
"""

_REFERENCE = {
    "sphere": formulas.sdf_sphere,
    "capsule": formulas.sdf_capsule,
    "cylinder": formulas.sdf_cylinder,
    "box": formulas.sdf_box,
    "ellipsoid": formulas.sdf_ellipsoid,
    "plane": formulas.sdf_plane,
}


def _geom_poses(scene, times: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """MuJoCo's world pose of every geom at each time: xpos (T, ngeom, 3), xmat (T, ngeom, 3, 3)."""
    data = mujoco.MjData(scene.model)
    pos, mat = [], []
    for t in times:
        scene.set_time(data, float(t))
        mujoco.mj_kinematics(scene.model, data)
        pos.append(data.geom_xpos.copy())
        mat.append(data.geom_xmat.reshape(-1, 3, 3).copy())
    return np.stack(pos), np.stack(mat)


def _per_geom_reference(scene, geom_ids, points: torch.Tensor, poses) -> torch.Tensor:
    """(T, N, G) signed distances, one geom at a time: the geom's MuJoCo pose at each time
    (``_geom_poses``) and the single-geom formulas of scenes.sdf.primitives (differentiable in
    ``points`` (T, N, 3))."""
    m = scene.model
    cols = []
    for g in geom_ids:
        centre = torch.as_tensor(poses[0][:, g], dtype=points.dtype)[:, None, :]  # (T, 1, 3)
        rot = torch.as_tensor(poses[1][:, g], dtype=points.dtype)  # (T, 3, 3)
        local = (points - centre) @ rot
        size = torch.as_tensor(m.geom_size[g], dtype=points.dtype)
        cols.append(
            _REFERENCE[mujoco.mjtGeom(m.geom_type[g]).name.removeprefix("mjGEOM_").lower()](local, size)
        )
    return torch.stack(cols, dim=-1)


@pytest.fixture(scope="module")
def every_primitive(tmp_path_factory):
    path = tmp_path_factory.mktemp("every") / "every.xml"
    path.write_text(EVERY_PRIMITIVE_XML)
    return load_scene(str(path), robot=None)


def test_vectorised_sdf_equals_a_per_geom_reference(every_primitive):
    """Every primitive type, static and on two mocap tracks: the kind-vectorised, culled fast path
    (values and gradients), ``per_geom`` and float32 all agree with one-geom-at-a-time formulas."""
    scene = every_primitive
    sdf = scene.sdf()
    m = scene.model
    kinds = {mujoco.mjtGeom(m.geom_type[g]).name for g in sdf.geom_ids}
    assert len(sdf.geom_ids) == 12 and len(kinds) == 6 and sdf.is_moving
    rng = np.random.default_rng(11)
    times = np.array([0.0, 0.6, 1.3, 2.0, 2.7, 3.5, 5.0])
    poses = _geom_poses(scene, times)
    points = []
    for k in range(len(times)):  # uniform in the scene, and in every geom's box at time k
        near = [
            poses[0][k, g]
            + (rng.uniform(-1.3, 1.3, (25, 3)) * np.minimum(m.geom_aabb[g, 3:], 1.0)) @ poses[1][k, g].T
            for g in sdf.geom_ids
        ]
        points.append(np.concatenate([rng.uniform([-2.5, -2.0, -0.6], [3.5, 2.0, 1.8], (100, 3)), *near]))
    points = torch.as_tensor(np.stack(points))  # (T, 400, 3)
    ref = _per_geom_reference(scene, sdf.geom_ids, points.clone().requires_grad_(True), poses)
    inside = (ref < 0).sum(dim=(0, 1))
    assert (inside > 10).all() and ((ref > 0).sum(dim=(0, 1)) > 10).all()  # every geom from inside and out
    t = torch.as_tensor(times)
    assert torch.allclose(sdf.per_geom(points, t), ref.detach(), atol=1e-9, rtol=0)
    x = points.clone().requires_grad_(True)
    value = sdf(x[None], t)[0]  # (1, T, N, 3) points, (T,) times
    y = points.clone().requires_grad_(True)
    ref_min = _per_geom_reference(scene, sdf.geom_ids, y, poses).amin(dim=-1)
    assert torch.allclose(value.detach(), ref_min.detach(), atol=1e-9, rtol=0)
    (grad,) = torch.autograd.grad(value.sum(), x)
    (ref_grad,) = torch.autograd.grad(ref_min.sum(), y)
    assert torch.allclose(grad, ref_grad, atol=1e-7)
    assert torch.allclose(grad.norm(dim=-1), torch.ones(grad.shape[:-1], dtype=grad.dtype), atol=1e-9)
    assert torch.allclose(sdf(points.float(), t.float()).double(), value.detach(), atol=2e-5)
    # Subsets exercise each kind alone (no cheaper kind to cull against) and mixed pairs.
    names = {m.geom(g).name: g for g in sdf.geom_ids}
    for subset in (
        ["s_ellipsoid", "m_ellipsoid"],
        ["s_wall", "m_plane"],
        ["m_capsule", "s_cylinder", "m_ellipsoid"],
    ):
        ids = [names[n] for n in subset]
        cols = [sdf.geom_ids.index(g) for g in ids]
        part = SceneSDF(scene, geom_ids=ids)
        x = points.clone().requires_grad_(True)
        value = part(x, t)
        assert torch.allclose(value.detach(), ref[..., cols].detach().amin(dim=-1), atol=1e-9, rtol=0)
        (grad,) = torch.autograd.grad(value.sum(), x)
        y = points.clone().requires_grad_(True)
        (ref_grad,) = torch.autograd.grad(_per_geom_reference(scene, ids, y, poses).amin(dim=-1).sum(), y)
        assert torch.allclose(grad, ref_grad, atol=1e-7)
