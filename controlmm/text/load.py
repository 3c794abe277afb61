"""Pick a text encoder by name: the one a model was trained with."""

from __future__ import annotations

import torch

from controlmm.errors import ControlMMError
from controlmm.text.base import TextEncoder
from controlmm.text.clip import CLIPTextEncoder
from controlmm.text.config import TEXT_ENCODER_DIMS, TextEncoderConfig
from controlmm.text.minilm import MiniLMTextEncoder


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
        return MiniLMTextEncoder(device=device)
    return CLIPTextEncoder(weights or config.weights, device=device, precision=config.precision)
