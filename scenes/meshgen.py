"""Generate the packaged mesh obstacle(s) with trimesh: ``python -m scenes.meshgen``.

``rock.stl`` is a closed, non-convex boulder: an icosphere scaled to the rock's semi-axes with
smooth radial bumps and dents. It is deterministic (fixed seed), so rerunning the script
rewrites the same file. The dents matter: MuJoCo collides the rock's convex hull while the
SDF follows the dents (see ``docs/scenes.md``).
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import trimesh

from scenes.registry import ASSETS_DIR

ROCK_RADII = (0.45, 0.35, 0.30)
"""Semi-axes of the rock before bumps (m)."""


def make_rock(
    seed: int = 7,
    subdivisions: int = 3,
    radii: tuple[float, float, float] = ROCK_RADII,
    bumps: int = 7,
    amplitude: float = 0.4,
    width: float = 0.15,
) -> trimesh.Trimesh:
    """A closed, outward-wound, non-convex rock mesh centred at the origin (metres)."""
    rng = np.random.default_rng(seed)
    sphere = trimesh.creation.icosphere(subdivisions=subdivisions)
    unit = sphere.vertices / np.linalg.norm(sphere.vertices, axis=1, keepdims=True)
    centres = rng.normal(size=(bumps, 3))
    centres /= np.linalg.norm(centres, axis=1, keepdims=True)
    heights = amplitude * rng.uniform(-1.0, 1.0, size=bumps)
    heights[: bumps // 2] = -np.abs(heights[: bumps // 2])  # at least a few dents
    radial = 1.0 + (heights[None, :] * np.exp(-(1.0 - unit @ centres.T) / width)).sum(axis=1)
    mesh = trimesh.Trimesh(unit * radial[:, None] * np.asarray(radii), sphere.faces, process=True)
    mesh.fix_normals()
    mesh.apply_translation(-mesh.bounds.mean(axis=0))
    return mesh


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=ASSETS_DIR / "rock.stl", help="output STL")
    args = parser.parse_args(argv)
    mesh = make_rock()
    assert mesh.is_watertight and mesh.is_winding_consistent
    mesh.export(args.out)
    print(
        f"wrote {args.out}: {len(mesh.vertices)} vertices, {len(mesh.faces)} faces, "
        f"extent {np.round(mesh.extents, 3).tolist()} m, convex: {mesh.is_convex}"
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
