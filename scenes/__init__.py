"""Scene library (MJCF worlds, Z up) and signed distance functions from MuJoCo geometry.

>>> from scenes import load_scene, obstacle_loss
>>> scene = load_scene("low_beam", robot="g1")          # packaged scene + Unitree G1
>>> sdf = scene.sdf()                                    # torch: (..., N, 3) world -> (..., N)
>>> term = obstacle_loss(sdf, scene.human_to_world(scale=0.78), safe_distance=0.05)
"""

from scenes.losses import (
    BODY_BONES,
    Bone,
    body_obstacle_loss,
    body_points,
    floor_loss,
    obstacle_loss,
    scene_loss_terms,
)
from scenes.registry import list_scenes
from scenes.scene import Scene, StartPose, load_scene
from scenes.sdf import SceneSDF
from scenes.tracks import MocapTrack

__all__ = [
    "BODY_BONES",
    "Bone",
    "MocapTrack",
    "Scene",
    "SceneSDF",
    "StartPose",
    "body_obstacle_loss",
    "body_points",
    "floor_loss",
    "list_scenes",
    "load_scene",
    "obstacle_loss",
    "scene_loss_terms",
]
