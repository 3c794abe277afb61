"""MuJoCo with an offscreen OpenGL backend for the commands that render (retarget, plan)."""

from __future__ import annotations

import os
import sys


def import_mujoco(default_backend: str) -> str | None:
    """Import MuJoCo with an offscreen GL backend; return why GL is unavailable, or None.

    MuJoCo reads MUJOCO_GL once, at import; a backend whose libraries are missing (e.g.
    MUJOCO_GL=osmesa without libosmesa6) makes the import itself fail. Then MuJoCo is
    imported again with rendering disabled, and the video falls back to the stick figure.
    """
    if "mujoco" in sys.modules:
        return None
    os.environ.setdefault("MUJOCO_GL", default_backend)
    try:
        import mujoco  # noqa: F401

        return None
    except Exception as exc:  # noqa: BLE001 - AttributeError/ImportError/OSError from the GL layer
        note = (
            f"MUJOCO_GL={os.environ.get('MUJOCO_GL', '')}: {' '.join(str(exc).split()) or type(exc).__name__}"
        )
        for name in list(sys.modules):
            if name == "mujoco" or name.startswith(("mujoco.", "OpenGL")):
                del sys.modules[name]
        os.environ["MUJOCO_GL"] = "disable"
        import mujoco  # noqa: F401

        return note
