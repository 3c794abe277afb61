"""The user's controlmm cache directory, shared by the persistent caches.

* ``$CONTROLMM_CACHE_DIR`` when set (``CONTROLMM_CACHE_DIR=`` empty: no persistent cache);
* else ``$XDG_CACHE_HOME/controlmm``, else ``~/.cache/controlmm``.

Users: prompt embeddings (``text/``, :mod:`controlmm.text.embedding_cache`) and the physics
check's saved robot + scene models (``physics/``, :mod:`sim.physics.model_cache`). Every entry
is checked before use and recomputed when unusable; deleting the directory is always safe.
"""

from __future__ import annotations

import os
from pathlib import Path

CACHE_ENV = "CONTROLMM_CACHE_DIR"
"""Environment variable overriding the cache directory (empty: no persistent cache)."""


def user_cache_dir() -> Path | None:
    """The user's controlmm cache directory (see the module docstring), or None when disabled."""
    override = os.environ.get(CACHE_ENV)
    if override is not None:
        return Path(override).expanduser() if override.strip() else None
    xdg = os.environ.get("XDG_CACHE_HOME", "").strip()
    base = Path(xdg).expanduser() if xdg else Path.home() / ".cache"
    return base / "controlmm"
