"""The packaged G1's MJCF edited the ways other robot files are written, for the tests."""

from __future__ import annotations

from pathlib import Path

import mujoco

from retarget import robot_mjcf


def g1_spec() -> mujoco.MjSpec:
    """The packaged G1's MjSpec, its meshes found wherever the edited copy is written."""
    src = robot_mjcf("g1")
    spec = mujoco.MjSpec.from_file(str(src))
    spec.meshdir = str(src.parent / "assets")
    return spec


def saved_without_controls(spec: mujoco.MjSpec, path: Path) -> Path:
    """``spec`` written to ``path`` without its actuators, sensors and keyframes (an edited
    tree no longer matches them)."""
    for kind in (spec.actuators, spec.sensors, spec.keys):
        for element in list(kind):
            spec.delete(element)
    path.write_text(spec.to_xml())
    return path
