"""Obstacle footprints from above: exact for primitives, linear in the number of geoms."""

from __future__ import annotations

import numpy as np
from scipy.spatial import ConvexHull

from scenes import load_scene
from scenes.footprint import footprints

SCENE = """<mujoco model="shapes">
  <worldbody>
    <geom name="floor" type="plane" size="0 0 0.05"/>
    <geom name="box" type="box" size="0.5 0.2 0.4" pos="2 0 0.4" euler="0 0 90"/>
    <geom name="post" type="cylinder" size="0.1 0.5" pos="3 1 0.5"/>
    <geom name="beam" type="box" size="0.1 1 0.05" pos="4 0 2.5"/>
    {many}
  </worldbody>
</mujoco>
"""


def _scene(tmp_path, n_extra=0):
    rng = np.random.default_rng(0)
    many = "".join(
        f'<geom name="b{i}" type="box" size="0.05 0.05 0.3" pos="{x:.2f} {y:.2f} 0.3"/>'
        for i, (x, y) in enumerate(rng.uniform([5, -4], [9, 4], size=(n_extra, 2)))
    )
    path = tmp_path / "shapes.xml"
    path.write_text(SCENE.format(many=many))
    return load_scene(path, robot=None)


def test_primitive_footprints_are_exact(tmp_path):
    polygons = footprints(_scene(tmp_path), z_range=(0.0, 1.5))
    assert len(polygons) == 2  # the beam at 2.45-2.55 m is above the body
    box, post = polygons
    assert np.isclose(ConvexHull(box).volume, 1.0 * 0.4)  # area of the rotated 1.0 x 0.4 box
    assert np.allclose(box.min(0), [1.8, -0.5]) and np.allclose(box.max(0), [2.2, 0.5])
    assert np.allclose(np.linalg.norm(post - [3, 1], axis=1), 0.1)
    assert len(footprints(_scene(tmp_path))) == 3  # no height limit: the beam too


def test_many_geoms_stay_cheap(tmp_path):
    polygons = footprints(_scene(tmp_path, n_extra=500), z_range=(0.0, 1.5))
    assert len(polygons) == 502
    areas = [ConvexHull(p).volume for p in polygons[2:]]
    assert np.allclose(areas, 0.01)
