"""Text-to-motion generation: masked decoding of the base layer, residual layers, decoding.

```python
from controlmm.generate import load_model, generate
model = load_model()                      # the embedded default (or load_model("MODEL_DIR"))
result = generate(model, "a person walks forward", seconds=6, seed=0)
result.motion.joints                      # (120, 22, 3), metres, Y up
out = generate_controlled(model, "a person walks", control=spec, preset="accurate", terms=[...], seed=0)
```
"""

from controlmm.generate.api import (
    GenerationResult,
    frames_for,
    generate,
    latent_to_features,
    latent_to_joints,
)
from controlmm.generate.controlled import (
    ControlledGeneration,
    EditingRecord,
    generate_controlled,
    latent_to_positions,
)
from controlmm.generate.masked_decoding import (
    BaseDecoding,
    DecodeOptions,
    DecodeState,
    mask_counts,
    masked_decode,
)
from controlmm.generate.residual_decoding import residual_decode
from controlmm.generate.token_view import token_view_logits_fn
from controlmm.models.model_dir import MotionModel, load_model

__all__ = [
    "BaseDecoding",
    "ControlledGeneration",
    "DecodeOptions",
    "DecodeState",
    "EditingRecord",
    "GenerationResult",
    "MotionModel",
    "frames_for",
    "generate",
    "generate_controlled",
    "latent_to_features",
    "latent_to_joints",
    "latent_to_positions",
    "load_model",
    "mask_counts",
    "masked_decode",
    "residual_decode",
    "token_view_logits_fn",
]
