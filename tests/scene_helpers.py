"""Shared builders for the scene tests: real MuJoCo models written as MJCF text."""

from __future__ import annotations

import numpy as np

WALL_PLANE_XML = """      <geom name="wall_plane" type="plane" size="1 1 0.1" pos="5 0 0" euler="0 90 0"/>
"""
"""The one plane among the obstacles of :data:`PRIMITIVES_XML` (a vertical wall)."""

PRIMITIVES_XML = """<mujoco>
  <worldbody>
    <geom name="floor" type="plane" size="0 0 0.05"/>
    <body name="obstacles" pos="0.1 0.2 0.3" euler="10 20 30">
      <geom name="sphere" type="sphere" size="0.3"/>
      <geom name="capsule" type="capsule" size="0.2 0.4" pos="1 0 0" euler="0 40 0"/>
      <geom name="cylinder" type="cylinder" size="0.25 0.5" pos="2 0 0" euler="30 0 10"/>
      <geom name="box" type="box" size="0.3 0.2 0.5" pos="3 0 0" euler="0 0 25"/>
      <geom name="ellipsoid" type="ellipsoid" size="0.5 0.2 0.3" pos="4 0 0" euler="15 -20 5"/>
      <geom name="wall_plane" type="plane" size="1 1 0.1" pos="5 0 0" euler="0 90 0"/>
    </body>
  </worldbody>
</mujoco>
"""


def heightfield_xml(heights: np.ndarray, size=(1.0, 0.6, 0.4, 0.1)) -> str:
    nrow, ncol = heights.shape
    elevation = " ".join(f"{v:.4f}" for v in heights.ravel())
    return f"""<mujoco>
  <asset>
    <hfield name="hf" nrow="{nrow}" ncol="{ncol}" size="{" ".join(map(str, size))}" elevation="{elevation}"/>
  </asset>
  <worldbody>
    <geom name="floor" type="plane" size="0 0 0.05"/>
    <body name="terrain" pos="1 0.5 0.2" euler="0 0 30">
      <geom name="terrain" type="hfield" hfield="hf"/>
    </body>
  </worldbody>
</mujoco>
"""


def user_scene_xml(mesh_file: str) -> str:
    """A user's own scene: a mesh, a primitive and a tracked mocap sphere, with metadata."""
    control = (
        '{"coords": "world", "constraints": [{"joint": "pelvis", "frame": 10, "position": [1, 0, 0.7]}]}'
    )
    return f"""<mujoco model="my_scene">
  <custom>
    <text name="controlmm.description" data="my test scene"/>
    <text name="controlmm.prompt" data="a person walks"/>
    <text name="controlmm.control" data='{control}'/>
    <numeric name="controlmm.start" data="0.5 -0.5 1.5707963"/>
    <numeric name="controlmm.track.ball" data="0 1 0 1  1 0 0 0   2 1 2 1  1 0 0 0"/>
  </custom>
  <asset><mesh name="block" file="{mesh_file}"/></asset>
  <worldbody>
    <light pos="0 0 3"/>
    <geom name="ground" type="plane" size="5 5 0.1"/>
    <body name="block" pos="2 1 0.3"><geom name="block" type="mesh" mesh="block"/></body>
    <body name="post" pos="-1 0 0.5"><geom name="post" type="capsule" size="0.05 0.5"/></body>
    <body name="ball" mocap="true" pos="1 0 1"><geom name="ball" type="sphere" size="0.2"/></body>
    <body name="decor">
      <geom name="decor" type="box" size="0.1 0.1 0.1" pos="0 3 0.1" contype="0" conaffinity="0"/>
    </body>
  </worldbody>
</mujoco>
"""
