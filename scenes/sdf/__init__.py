"""Signed distance functions from MuJoCo geometry (torch, differentiable)."""

from scenes.sdf.mesh import MeshSDF, closed_mesh
from scenes.sdf.primitives import sdf_box, sdf_capsule, sdf_cylinder, sdf_ellipsoid, sdf_plane, sdf_sphere
from scenes.sdf.scene_sdf import SceneSDF
from scenes.sdf.topology import heightfield_mesh

__all__ = [
    "MeshSDF",
    "SceneSDF",
    "closed_mesh",
    "heightfield_mesh",
    "sdf_box",
    "sdf_capsule",
    "sdf_cylinder",
    "sdf_ellipsoid",
    "sdf_plane",
    "sdf_sphere",
]
