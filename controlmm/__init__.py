"""controlmm: plan humanoid-robot motion from text and spatial constraints (ControlMM).

Data flows one way: text + constraints + scene -> :mod:`controlmm` (generation with
logits/codebook editing) -> :mod:`retarget` (human joints -> robot qpos) -> :mod:`sim`
(MuJoCo replay and checks; failures become extra editing losses) -> export.
"""

__version__ = "0.1.0"

from controlmm.errors import ControlMMError  # noqa: E402
from controlmm.frames import HumanToWorld  # noqa: E402

__all__ = ["ControlMMError", "HumanToWorld", "__version__"]
