"""Caption embeddings computed once per (caption set, encoder) and cached in one tensor file."""

from __future__ import annotations

import hashlib
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import torch

from controlmm.atomic import atomic_path
from controlmm.text.base import TextEncoder


@dataclass(frozen=True)
class CaptionEmbeddings:
    """Unique captions and their vectors: ``vectors[index[caption]]`` is (dim,)."""

    captions: tuple[str, ...]
    vectors: torch.Tensor  # (num_captions, dim) float32

    @property
    def index(self) -> dict[str, int]:
        return {c: i for i, c in enumerate(self.captions)}


def cache_key(captions: Sequence[str], encoder_identity: str) -> str:
    h = hashlib.sha256(encoder_identity.encode())
    for caption in captions:
        h.update(b"\0" + caption.encode())
    return h.hexdigest()[:16]


def embed_captions(encoder: TextEncoder, captions: Sequence[str], cache_dir: Path | None = None,
                   batch_size: int = 256, progress: bool = True) -> CaptionEmbeddings:
    """Embed the unique ``captions`` (order kept), reading/writing ``cache_dir/text-<name>-<key>.pt``."""
    unique = tuple(dict.fromkeys(captions))
    path = None
    if cache_dir is not None:
        path = Path(cache_dir) / f"text-{encoder.name}-{cache_key(unique, encoder.identity)}.pt"
        if path.is_file():
            try:
                data = torch.load(path, map_location="cpu", weights_only=True)
                if tuple(data["captions"]) == unique and data["vectors"].shape == (len(unique), encoder.dim):
                    return CaptionEmbeddings(unique, data["vectors"].float())
            except Exception:  # noqa: BLE001 - a bad cache is recomputed
                pass
    from tqdm import tqdm

    chunks = []
    starts = range(0, len(unique), batch_size)
    for start in tqdm(starts, desc=f"text embeddings ({encoder.name})", unit="batch", disable=not progress,
                      leave=False):
        chunks.append(encoder.encode(list(unique[start:start + batch_size])))
    vectors = torch.cat(chunks) if chunks else torch.zeros(0, encoder.dim)
    if path is not None:
        path.parent.mkdir(parents=True, exist_ok=True)
        with atomic_path(path) as tmp:
            torch.save({"captions": list(unique), "vectors": vectors, "encoder": encoder.identity}, tmp)
    return CaptionEmbeddings(unique, vectors)
