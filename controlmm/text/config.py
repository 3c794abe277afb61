"""The text-encoder configuration a model directory records, and the encoders it can name."""

from __future__ import annotations

from dataclasses import dataclass

TEXT_ENCODER_DIMS: dict[str, int] = {"minilm": 384, "clip": 512}
"""Embedding size of each supported text encoder."""

CLIP_MODEL_ID = "openai/clip-vit-base-patch32"


@dataclass(frozen=True)
class TextEncoderConfig:
    """Which sentence encoder conditions the transformers.

    ``name``: ``"minilm"`` (the packaged all-MiniLM-L6-v2, 384-d, L2-normalised mean pooling) or
    ``"clip"`` (CLIP ViT-B/32 ``encode_text``: projected end-of-text token, 512-d, not normalised).
    ``weights``: for CLIP, a folder saved by ``transformers`` (``CLIPModel.save_pretrained``) or a
    Hugging Face model id looked up in the local cache only; ignored by MiniLM.
    ``tokens`` (MiniLM only, not in MoMask): 0 = one sentence vector per text (B, dim); N > 0 = the
    text's token states, at most N, zero-padded (B, L, dim): the masked transformer attends to every
    word instead of one pooled vector; the residual transformer pools them back into the sentence vector.
    """

    name: str = "minilm"
    weights: str | None = None
    precision: str = "float32"  # "float16" reproduces the official GPU CLIP features
    size: int | None = None  # vector size when it differs from the encoder's usual one (other CLIP weights)
    tokens: int = 0

    @property
    def dim(self) -> int:
        """Size of the sentence vectors (384 MiniLM, 512 CLIP ViT-B/32, or ``size``)."""
        return self.size if self.size is not None else TEXT_ENCODER_DIMS[self.name]
