"""A persistent cache of prompt embeddings, one small file per (text encoder, text).

A prompt is embedded once per machine: the next run (a new process) reads its vectors from disk and
never loads the text model. The files go under the user's cache directory
(:func:`controlmm.user_cache.user_cache_dir`: ``$CONTROLMM_CACHE_DIR``, else
``$XDG_CACHE_HOME/controlmm``, else ``~/.cache/controlmm``), in ``text/<encoder key>/<text key>.npz``.
The encoder key hashes the encoder's ``identity`` (its name, package version and a fingerprint of its
files: other weights, other keys), the text key hashes the text. Every entry also stores the
identity, the text and a format version, and is used only when all three match and its arrays have
the expected shapes and finite values; anything else (a corrupt or truncated file, another model
version, a hash collision) is recomputed and rewritten, never trusted. Files are written atomically
(:mod:`controlmm.atomic`), so concurrent processes at worst write the same entry twice.
Deleting the directory is always safe.
"""

from __future__ import annotations

import hashlib
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from controlmm.atomic import atomic_path
from controlmm.user_cache import CACHE_ENV, user_cache_dir

__all__ = ["CACHE_ENV", "Embedding", "EmbeddingCache", "user_cache_dir"]

FORMAT = 1
"""Version of the entry layout; entries of another version are recomputed."""


def _digest(text: str, size: int = 32) -> str:
    return hashlib.sha256(text.encode("utf-8")).hexdigest()[:size]


@dataclass(frozen=True)
class Embedding:
    """One text's encoder outputs.

    Attributes:
        vector: (dim,) float32 sentence vector.
        states: (n, dim) float32 token states (the first n the encoder reads).
        tokens: how many tokens the full text has (special tokens included; may exceed n).
    """

    vector: np.ndarray
    states: np.ndarray
    tokens: int


class EmbeddingCache:
    """Entries of one encoder (``identity``) under ``directory`` (default: :func:`user_cache_dir`).

    ``get`` returns None for a missing or unusable entry; ``put`` stores one, and warns once per
    process (then stops writing) when the directory cannot be written.
    """

    def __init__(self, identity: str, dim: int, directory: Path | None = None) -> None:
        root = user_cache_dir() if directory is None else Path(directory)
        self.identity = identity
        self.dim = int(dim)
        self.directory = None if root is None else root / "text" / _digest(f"{FORMAT}\0{identity}", 16)
        self._writable = self.directory is not None

    @property
    def enabled(self) -> bool:
        return self.directory is not None

    def path(self, text: str) -> Path | None:
        return None if self.directory is None else self.directory / f"{_digest(text)}.npz"

    def get(self, text: str) -> Embedding | None:
        path = self.path(text)
        if path is None or not path.is_file():
            return None
        try:
            with np.load(path, allow_pickle=False) as data:
                meta = [str(x) for x in data["meta"]]
                vector, states, tokens = data["vector"], data["states"], int(data["tokens"])
        except Exception:  # noqa: BLE001 - any unreadable entry is recomputed, never trusted
            return None
        ok = (
            meta == [str(FORMAT), self.identity, text]
            and vector.dtype == np.float32
            and vector.shape == (self.dim,)
            and states.dtype == np.float32
            and states.ndim == 2
            and states.shape[1] == self.dim
            and 1 <= states.shape[0] <= max(tokens, 1)
            and bool(np.isfinite(vector).all() and np.isfinite(states).all())
        )
        return Embedding(vector, states, tokens) if ok else None

    def put(self, text: str, entry: Embedding) -> None:
        path = self.path(text)
        if path is None or not self._writable:
            return
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
            with atomic_path(path) as tmp:
                np.savez(
                    tmp,
                    meta=np.array([str(FORMAT), self.identity, text]),
                    vector=np.asarray(entry.vector, np.float32),
                    states=np.asarray(entry.states, np.float32),
                    tokens=np.int64(entry.tokens),
                )
        except Exception as exc:  # noqa: BLE001 - the cache is an optimisation: never fail a run on it
            self._writable = False
            warnings.warn(
                f"cannot write the text-embedding cache under '{self.directory}' ({exc}); prompts "
                f"are encoded again in every process (set {CACHE_ENV} to a writable directory)",
                stacklevel=2,
            )
