"""The text-encoder interface and the factory that picks an implementation by name."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Protocol, runtime_checkable

import torch

from controlmm.errors import ControlMMError
from controlmm.models.config import TEXT_ENCODER_DIMS, TextEncoderConfig


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


def load_text_encoder(
    config: TextEncoderConfig | str = "minilm", device: str | torch.device = "cpu", weights: str | None = None
) -> TextEncoder:
    """Build the encoder a model was trained with.

    Args:
        config: a :class:`TextEncoderConfig` or just the encoder name.
        device: where the encoder runs; vectors are returned on the CPU.
        weights: CLIP only: overrides ``config.weights`` (a ``save_pretrained`` folder or a model id
            in the local Hugging Face cache).
    """
    if isinstance(config, str):
        config = TextEncoderConfig(name=config)
    if config.name not in TEXT_ENCODER_DIMS:
        raise ControlMMError(f"unknown text encoder '{config.name}'; allowed: {', '.join(TEXT_ENCODER_DIMS)}")
    if config.name == "minilm":
        from controlmm.text.minilm import MiniLMTextEncoder

        return MiniLMTextEncoder(device=device)
    from controlmm.text.clip import CLIPTextEncoder

    return CLIPTextEncoder(weights or config.weights, device=device, precision=config.precision)
