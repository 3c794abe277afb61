"""The packaged scene library: MJCF files in ``scenes/assets`` looked up by name."""

from __future__ import annotations

from pathlib import Path

ASSETS_DIR = Path(__file__).resolve().parent / "assets"

SCENE_NAMES: tuple[str, ...] = (
    "empty",
    "corridor",
    "pillars",
    "table",
    "low_beam",
    "doorway",
    "moving_obstacle",
    "mesh_rock",
    "room",
)
"""Packaged scenes, in the order ``controlmm scene list`` shows them."""


def list_scenes() -> list[str]:
    """Names of the packaged scenes."""
    return [name for name in SCENE_NAMES if (ASSETS_DIR / f"{name}.xml").is_file()]


def scene_path(name: str) -> Path | None:
    """MJCF path of a packaged scene, or None when ``name`` is not one."""
    key = name.strip().lower()
    return ASSETS_DIR / f"{key}.xml" if key in SCENE_NAMES else None
