"""Text-to-motion generation: masked decoding of the base layer, residual layers, decoding.

```python
from controlmm.generate import load_model, generate
model = load_model()                      # the embedded default (or load_model("MODEL_DIR"))
result = generate(model, "a person walks forward", seconds=6, seed=0)
result.motion.joints                      # (120, 22, 3), metres, Y up
```
"""

from controlmm.generate.api import GenerationResult, frames_for, generate, latent_to_features, latent_to_joints
from controlmm.generate.masked_decoding import BaseDecoding, DecodeOptions, DecodeState, mask_counts, masked_decode
from controlmm.generate.residual_decoding import residual_decode
from controlmm.models.model_dir import MotionModel, load_model

__all__ = [
    "BaseDecoding",
    "DecodeOptions",
    "DecodeState",
    "GenerationResult",
    "MotionModel",
    "frames_for",
    "generate",
    "latent_to_features",
    "latent_to_joints",
    "load_model",
    "mask_counts",
    "masked_decode",
    "residual_decode",
]
