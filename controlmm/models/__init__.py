"""The MoMask base models (RVQ-VAE tokenizer, masked and residual transformers) and ControlMM's
motion control model.

Configs and presets live in :mod:`controlmm.models.config`; the model directory format and
``load_model`` in :mod:`controlmm.models.model_dir`.
"""

from controlmm.models.config import (
    PRESETS,
    ControlConfig,
    ModelConfig,
    ResidualConfig,
    StageSchedule,
    TokenizerConfig,
    TokenViewConfig,
    TransformerConfig,
    preset_config,
)
from controlmm.models.mask_transformer import MaskTransformer
from controlmm.models.model_dir import MotionModel, load_model, register_part
from controlmm.models.motion_control_model import MotionControlModel, control_input
from controlmm.models.residual_transformer import ResidualTransformer
from controlmm.models.rvqvae import RVQVAE

__all__ = [
    "PRESETS",
    "RVQVAE",
    "ControlConfig",
    "MaskTransformer",
    "ModelConfig",
    "MotionControlModel",
    "MotionModel",
    "ResidualConfig",
    "ResidualTransformer",
    "StageSchedule",
    "TokenizerConfig",
    "TokenViewConfig",
    "TransformerConfig",
    "control_input",
    "load_model",
    "preset_config",
    "register_part",
]
