"""A persistent cache of the physics check's executed model text (``physics_model.xml``).

Writing the robot + scene as one self-contained MJCF (12 MB for G1: every mesh inline) takes
MuJoCo about 2.5 s on a 2-core machine, more than a third of a 6 s clip's budget at 0.25x real
time; the text only depends on the model. So it is written once per machine and model, under
the user's cache directory (:func:`controlmm.user_cache.user_cache_dir`) in
``physics/<key>.xml``.

The key hashes a format version, MuJoCo's version, the planning sensors' bodies and the
compiled scene model's binary image (``mj_saveModel``: every array, meshes included), so any
change of the robot, the scene or MuJoCo is another entry. An entry is used only when it
compiles to the same state layout with the cost's sensors (:func:`sim.physics.track`
checks); anything else is rebuilt and rewritten. Files are written atomically; at most
:data:`MAX_ENTRIES` are kept (the least recently used go first). Deleting the directory is
always safe.
"""

from __future__ import annotations

import hashlib
import warnings
from pathlib import Path

import mujoco
import numpy as np

from controlmm.atomic import atomic_path
from controlmm.user_cache import CACHE_ENV, user_cache_dir

FORMAT = 1
"""Version of the saved model's construction (:func:`sim.physics.model.inline_meshes`,
:func:`sim.physics.model.add_plan_sensors`): bump it when they change, so that no entry of the
old construction is read."""

MAX_ENTRIES = 16
"""Entries kept (about 12 MB each for G1 in a scene)."""


def model_key(model: mujoco.MjModel, *extra: str) -> str:
    """A hex digest identifying ``model`` (its binary image) and ``extra`` strings."""
    image = np.empty(mujoco.mj_sizeModel(model), dtype=np.uint8)
    mujoco.mj_saveModel(model, None, image)
    digest = hashlib.sha256("\0".join([str(FORMAT), mujoco.__version__, *extra]).encode("utf-8"))
    digest.update(b"\0")
    digest.update(image.data)
    return digest.hexdigest()[:40]


class ModelTextCache:
    """Saved model texts under ``directory`` (default: the user's cache, ``physics/``).

    ``get`` returns None for a missing or unreadable entry; ``put`` stores one and warns once
    per process (then stops writing) when the directory cannot be written.
    """

    _warned = False

    def __init__(self, directory: Path | None = None) -> None:
        root = user_cache_dir() if directory is None else Path(directory)
        self.directory = None if root is None else root / "physics"

    def path(self, key: str) -> Path | None:
        return None if self.directory is None else self.directory / f"{key}.xml"

    def get(self, key: str) -> str | None:
        path = self.path(key)
        if path is None or not path.is_file():
            return None
        try:
            text = path.read_text(encoding="utf-8")
            path.touch()  # most recently used
        except (OSError, UnicodeDecodeError):
            return None
        return text if text.lstrip().startswith("<mujoco") else None

    def put(self, key: str, text: str) -> None:
        path = self.path(key)
        if path is None or ModelTextCache._warned:
            return
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
            with atomic_path(path) as tmp:
                Path(tmp).write_text(text, encoding="utf-8")
            self._evict(keep=path)
        except Exception as exc:  # noqa: BLE001 - the cache is an optimisation: never fail a run on it
            ModelTextCache._warned = True
            warnings.warn(
                f"cannot write the physics model cache under '{self.directory}' ({exc}); the model "
                f"is saved again in every process (set {CACHE_ENV} to a writable directory)",
                stacklevel=2,
            )

    def _evict(self, keep: Path) -> None:
        """Delete the least recently used entries beyond :data:`MAX_ENTRIES` (never ``keep``)."""
        assert self.directory is not None
        entries = []
        for p in self.directory.glob("*.xml"):
            if p.name.startswith("."):  # another process's entry being written
                continue
            try:
                entries.append((p.stat().st_mtime, p))
            except OSError:  # removed by another process meanwhile
                continue
        entries.sort(reverse=True)
        for _, p in entries[MAX_ENTRIES:]:
            if p != keep:
                p.unlink(missing_ok=True)
