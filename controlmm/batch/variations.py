"""Scene variations: a copy of a scene with its static obstacles moved by a seeded jitter.

``jitter_scene("table", index=3, seed=0, jitter_m=0.1)`` returns the MJCF text of the copy and
the offsets applied. Every static obstacle at the top of the world (a body child of the world
holding a colliding geom, or a colliding geom of the world itself; never a floor plane or a
mocap body, whose motion is its track) moves by ``(dx, dy)`` drawn uniformly from
``[-jitter_m, jitter_m]`` by ``numpy.random.default_rng((seed, index))``, in document order; the
same arguments always give the same scene. The copy keeps the scene's metadata (prompt, control,
start pose) and refers to the original's mesh folder, so it loads from anywhere with
``scenes.load_scene(path)``.
"""

from __future__ import annotations

from pathlib import Path

import mujoco
import numpy as np

from scenes import load_scene


def _is_obstacle(geom: mujoco.MjsGeom) -> bool:
    colliding = bool(geom.contype or geom.conaffinity)
    return colliding and geom.type != mujoco.mjtGeom.mjGEOM_PLANE


def _has_obstacle(body: mujoco.MjsBody) -> bool:
    return any(_is_obstacle(g) for g in body.geoms) or any(_has_obstacle(b) for b in body.bodies)


def jitter_scene(
    scene: str | Path, *, index: int, seed: int, jitter_m: float
) -> tuple[str, dict[str, list[float]]]:
    """``(MJCF text, {obstacle: [dx, dy]})`` of variation ``index`` of ``scene`` (see the module).

    ``scene`` is a packaged scene name or an MJCF path; unnamed obstacles are keyed
    ``body<i>`` / ``geom<i>`` by their order in the world.
    """
    path = load_scene(scene, robot=None).path  # resolves the name; bad scenes fail here, in one line
    spec = mujoco.MjSpec.from_file(str(path))
    movable: list[tuple[str, mujoco.MjsBody | mujoco.MjsGeom]] = []
    for i, body in enumerate(spec.worldbody.bodies):
        if not body.mocap and _has_obstacle(body):
            movable.append((body.name or f"body{i}", body))
    for i, geom in enumerate(spec.worldbody.geoms):
        if _is_obstacle(geom):
            movable.append((geom.name or f"geom{i}", geom))
    rng = np.random.default_rng((seed, index))
    offsets = rng.uniform(-jitter_m, jitter_m, size=(len(movable), 2))
    moved: dict[str, list[float]] = {}
    for (name, element), (dx, dy) in zip(movable, offsets, strict=True):
        element.pos = np.asarray(element.pos, dtype=np.float64) + np.array([dx, dy, 0.0])
        moved[name] = [round(float(dx), 6), round(float(dy), 6)]
    for attr in ("meshdir", "texturedir"):  # asset files stay where the original's are
        folder = Path(getattr(spec, attr))
        setattr(spec, attr, str(folder if folder.is_absolute() else (path.parent / folder).resolve()))
    return spec.to_xml(), moved
