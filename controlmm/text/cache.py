"""Caption embeddings computed once per (caption set, encoder) and cached in one tensor file."""

from __future__ import annotations

import hashlib
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import torch
from tqdm import tqdm

from controlmm.atomic import atomic_path
from controlmm.errors import ControlMMError
from controlmm.text.base import TextEncoder, TokenTextEncoder


@dataclass(frozen=True)
class CaptionEmbeddings:
    """Unique captions and their vectors: ``vectors[index[caption]]`` is (dim,), or (L, dim) token states."""

    captions: tuple[str, ...]
    vectors: torch.Tensor  # (num_captions, dim) or (num_captions, L, dim) float32

    @property
    def index(self) -> dict[str, int]:
        return {c: i for i, c in enumerate(self.captions)}


def cache_key(captions: Sequence[str], encoder_identity: str) -> str:
    h = hashlib.sha256(encoder_identity.encode())
    for caption in captions:
        h.update(b"\0" + caption.encode())
    return h.hexdigest()[:16]


def embed_captions(
    encoder: TextEncoder,
    captions: Sequence[str],
    cache_dir: Path | None = None,
    batch_size: int = 256,
    progress: bool = True,
    tokens: int = 0,
) -> CaptionEmbeddings:
    """Embed the unique ``captions`` (order kept), reading/writing ``cache_dir/text-<name>-<key>.pt``.

    ``tokens`` > 0: token states (num_captions, L, dim), at most ``tokens`` per caption, zero-padded to
    the longest (``encoder.encode_tokens``); stored as float16 on disk (they are large), float32 here.
    """
    unique = tuple(dict.fromkeys(captions))
    token_encoder = None
    if tokens:
        if not isinstance(encoder, TokenTextEncoder):
            raise ControlMMError(f"text encoder '{encoder.name}' gives no token states (tokens={tokens})")
        token_encoder = encoder
    path = None
    if cache_dir is not None:
        kind = f"{encoder.name}-tok{tokens}" if tokens else encoder.name
        path = Path(cache_dir) / f"text-{kind}-{cache_key(unique, encoder.identity)}.pt"
        if path.is_file():
            try:
                data = torch.load(path, map_location="cpu", weights_only=True)
                vectors = data["vectors"]
                if (
                    tuple(data["captions"]) == unique
                    and vectors.shape[0] == len(unique)
                    and vectors.shape[-1] == encoder.dim
                    and vectors.ndim == (3 if tokens else 2)
                ):
                    return CaptionEmbeddings(unique, vectors.float())
            except Exception:  # noqa: BLE001 - a bad cache is recomputed
                pass
    chunks = []
    starts = range(0, len(unique), batch_size)
    for start in tqdm(
        starts, desc=f"text embeddings ({encoder.name})", unit="batch", disable=not progress, leave=False
    ):
        texts = list(unique[start : start + batch_size])
        chunks.append(
            token_encoder.encode_tokens(texts, tokens) if token_encoder is not None else encoder.encode(texts)
        )
    if tokens:
        length = max((c.shape[1] for c in chunks), default=1)
        vectors = torch.zeros(len(unique), length, encoder.dim)
        for start, chunk in zip(starts, chunks, strict=True):
            vectors[start : start + len(chunk), : chunk.shape[1]] = chunk
        stored = vectors.half()
        vectors = stored.float()  # what a later run reads back from the cache
    else:
        vectors = torch.cat(chunks) if chunks else torch.zeros(0, encoder.dim)
        stored = vectors
    if path is not None:
        path.parent.mkdir(parents=True, exist_ok=True)
        with atomic_path(path) as tmp:
            torch.save({"captions": list(unique), "vectors": stored, "encoder": encoder.identity}, tmp)
    return CaptionEmbeddings(unique, vectors)
