"""GridSDF (the lattice-backed SDF of static scenes) against the exact SceneSDF: exact values and
gradients within the band, the interpolation bound beyond it, bricks built lazily, and losses that
do not change when they use it."""

from __future__ import annotations

import math

import mujoco
import numpy as np
import pytest
import torch

from controlmm.errors import ControlMMError
from controlmm.frames import HumanToWorld
from scenes import body_obstacle_loss, load_scene, obstacle_loss
from scenes.sdf.grid import DistanceGrid, GridSDF, banded_sdf, distance_grid
from tests.scene_helpers import PRIMITIVES_XML, WALL_PLANE_XML

PRIMITIVES = PRIMITIVES_XML.replace(WALL_PLANE_XML, "")  # the five solids, without the wall plane


@pytest.fixture(scope="module")
def primitives(tmp_path_factory):
    """A row of primitives of every bounded kind (the ellipsoid is a costly one), static."""
    path = tmp_path_factory.mktemp("grid") / "primitives.xml"
    path.write_text(PRIMITIVES)
    return load_scene(str(path), robot=None)


def _points(scene, n: int, seed: int, dtype=torch.float64) -> torch.Tensor:
    """n / 4 points over the SDF's extent and 0.5 m beyond (some off the lattice), n around the
    obstacles."""
    rng = np.random.default_rng(seed)
    lo, hi = scene.sdf().extent
    spread = rng.uniform(lo - 0.5, hi + 0.5, (n // 4, 3))
    data = mujoco.MjData(scene.model)
    mujoco.mj_kinematics(scene.model, data)
    centres = data.geom_xpos[list(scene.obstacle_geom_ids)]
    near = centres[rng.integers(0, len(centres), n)] + rng.normal(scale=0.4, size=(n, 3))
    return torch.as_tensor(np.concatenate([spread, near]), dtype=dtype)


def test_grid_sdf_is_exact_near_obstacles_and_bounded_far(primitives):
    sdf = primitives.sdf()
    band = 0.2
    grid = GridSDF(sdf, exact_within=band, spacing=0.1)
    points = _points(primitives, 800, 0).requires_grad_(True)
    value = grid(points)
    (grad,) = torch.autograd.grad(value.sum(), points)
    exact = sdf(points)
    (exact_grad,) = torch.autograd.grad(exact.sum(), points)
    value, exact = value.detach(), exact.detach()
    near = exact < band
    assert int(near.sum()) > 200 and int((~near).sum()) > 300
    # within the band: the exact SDF, value and gradient (to rounding: the subset is batched differently)
    torch.testing.assert_close(value[near], exact[near], atol=1e-12, rtol=0)
    torch.testing.assert_close(grad[near], exact_grad[near], atol=1e-9, rtol=0)
    # beyond: within the interpolation bound of the exact value, never inside the band
    bound = math.sqrt(3) / 2 * grid.grid.spacing + 1e-3
    assert float((value - exact).abs()[~near].max()) <= bound
    assert float(value[~near].min()) >= band - 1e-12
    # the interpolated gradient points the same way as the exact one far out
    far = exact > 0.5
    cos = torch.nn.functional.cosine_similarity(grad[far], exact_grad[far], dim=-1)
    assert float(cos.median()) > 0.99


def test_grid_bricks_are_built_lazily_and_shared(primitives):
    sdf = primitives.sdf()
    grid = distance_grid(sdf, spacing=0.13)
    assert grid is distance_grid(sdf, spacing=0.13)  # one lattice per SDF and spacing
    before = grid.built_bricks
    GridSDF(sdf, 0.1, spacing=0.13)(torch.tensor([[2.0, 0.2, 0.3]], dtype=torch.float64))
    built = grid.built_bricks
    assert built == before + 1
    GridSDF(sdf, 0.1, spacing=0.13)(torch.tensor([[2.01, 0.21, 0.31]], dtype=torch.float64))
    assert grid.built_bricks == built  # the same brick: nothing new to evaluate
    total = int(np.prod(grid.bricks))
    assert built < total


def test_grid_sdf_dtype_shapes_and_off_lattice(primitives):
    sdf = primitives.sdf()
    grid = GridSDF(sdf, exact_within=0.05, spacing=0.1)
    pts = _points(primitives, 240, 1, dtype=torch.float32).reshape(3, -1, 3)  # (..., N, 3) leading dims
    out = grid(pts, torch.zeros(3))
    assert out.shape == pts.shape[:2] and out.dtype == torch.float32
    lo, _ = sdf.extent
    outside = torch.as_tensor(lo - 3.0, dtype=torch.float64)[None]  # off the lattice: exact
    torch.testing.assert_close(grid(outside), sdf(outside), atol=1e-12, rtol=0)


def test_banded_sdf_picks_the_grid_for_costly_static_scenes(primitives):
    assert isinstance(banded_sdf(primitives.sdf(), 0.1), GridSDF)  # it has an ellipsoid
    table = load_scene("table", robot=None).sdf()
    assert banded_sdf(table, 0.1) is table  # boxes only: exact evaluation is as cheap
    moving = load_scene("moving_obstacle", robot=None).sdf()
    assert banded_sdf(moving, 0.1) is moving  # moving obstacles stay exact
    with pytest.raises(ControlMMError, match="static obstacles"):
        DistanceGrid(moving)
    with pytest.raises(ControlMMError, match="positive length"):
        DistanceGrid(table, spacing=0.0)


def test_obstacle_losses_are_unchanged_by_the_grid(primitives, sample_joints):
    """The losses build their GridSDF themselves; their values and gradients equal the exact ones."""
    sdf = primitives.sdf()
    transform = HumanToWorld(scale=1.0, translation=(1.5, 0.2, 0.0))  # the clip walks through the row
    joints = torch.as_tensor(sample_joints, dtype=torch.float64)[None]

    class Exact:  # the same SDF without the grid (not a SceneSDF, so the losses use it as it is)
        is_moving = False

        def __call__(self, points, t=None):
            return sdf(points, t)

    for make in (body_obstacle_loss, obstacle_loss):
        values, grads = [], []
        for field in (sdf, Exact()):
            x = joints.clone().requires_grad_(True)
            value = make(field, transform, safe_distance=0.05)(x)
            (g,) = torch.autograd.grad(value.sum(), x)
            values.append(value.detach())
            grads.append(g)
        assert float(values[0]) > 0  # the clip does touch the obstacles
        torch.testing.assert_close(values[0], values[1], atol=1e-12, rtol=1e-9)
        torch.testing.assert_close(grads[0], grads[1], atol=1e-12, rtol=1e-9)
