"""The MoMask base models: RVQ-VAE tokenizer, masked transformer, residual transformer.

Configs and presets live in :mod:`controlmm.models.config`; the model directory format and
``load_model`` in :mod:`controlmm.models.model_dir`.
"""

from controlmm.models.config import (
    PRESETS,
    ModelConfig,
    ResidualConfig,
    StageSchedule,
    TextEncoderConfig,
    TokenizerConfig,
    TransformerConfig,
    preset_config,
)
from controlmm.models.mask_transformer import MaskTransformer
from controlmm.models.model_dir import MotionModel, load_model, register_part
from controlmm.models.residual_transformer import ResidualTransformer
from controlmm.models.rvqvae import RVQVAE

__all__ = [
    "PRESETS",
    "RVQVAE",
    "MaskTransformer",
    "ModelConfig",
    "MotionModel",
    "ResidualConfig",
    "ResidualTransformer",
    "StageSchedule",
    "TextEncoderConfig",
    "TokenizerConfig",
    "TransformerConfig",
    "load_model",
    "preset_config",
    "register_part",
]
