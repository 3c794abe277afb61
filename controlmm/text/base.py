"""The text-encoder interface, text checks and the offline switch every encoder sets."""

from __future__ import annotations

import os
from collections.abc import Sequence
from typing import Protocol, runtime_checkable

import torch

from controlmm.errors import ControlMMError


@runtime_checkable
class TextEncoder(Protocol):
    """Maps sentences to fixed-size vectors.

    Attributes:
        name: ``"minilm"`` or ``"clip"``.
        dim: size of the vectors.
        identity: a string that changes whenever the vectors would (used to key caches).
    """

    name: str
    dim: int
    identity: str

    def encode(self, texts: Sequence[str]) -> torch.Tensor:
        """(B,) sentences -> (B, dim) float32 CPU tensor."""
        ...

    def warn_truncated(self, texts: Sequence[str], max_tokens: int | None = None) -> None:
        """Warn about texts longer than the encoder reads (or than ``max_tokens`` token states)."""
        ...


@runtime_checkable
class TokenTextEncoder(TextEncoder, Protocol):
    """A :class:`TextEncoder` that also gives the token states its sentence vectors pool (MiniLM)."""

    def encode_tokens(self, texts: Sequence[str], max_tokens: int) -> torch.Tensor:
        """(B,) sentences -> (B, L, dim) float32 token states, zero rows padding, L <= ``max_tokens``."""
        ...


def check_texts(texts: Sequence[str]) -> list[str]:
    """The texts as a list of strings; one-line error for an empty or non-string entry."""
    if isinstance(texts, str):
        texts = [texts]
    out = []
    for i, text in enumerate(texts):
        if not isinstance(text, str):
            raise ControlMMError(f"text #{i} must be a string; got {type(text).__name__}")
        if not text.strip():
            raise ControlMMError("text must not be empty")
        out.append(text.strip())
    return out


def offline() -> None:
    """Forbid Hugging Face downloads in this process (environment only: nothing is imported)."""
    os.environ.setdefault("HF_HUB_OFFLINE", "1")
    os.environ.setdefault("TRANSFORMERS_OFFLINE", "1")
    os.environ.setdefault("TOKENIZERS_PARALLELISM", "false")


def quiet_transformers() -> None:
    """Quieten ``transformers``' warnings and progress bars; call after importing it (an encoder
    loading its weights), never before: importing it costs about a second."""
    try:
        from transformers.utils import logging as hf_logging  # already imported by the caller

        hf_logging.set_verbosity_error()
        hf_logging.disable_progress_bar()
    except Exception:  # noqa: BLE001 - cosmetic only
        pass
