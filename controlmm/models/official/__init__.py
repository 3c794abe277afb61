"""Loading the official MoMask / MaskControl checkpoints into the ``paper`` preset.

- :mod:`~controlmm.models.official.names`: the documented name mapping (official key -> part file);
- :mod:`~controlmm.models.official.opt`: ``opt.txt`` parsing;
- :mod:`~controlmm.models.official.folders`: the ``checkpoints/t2m`` folder layout;
- :mod:`~controlmm.models.official.convert`: :func:`import_official` (``controlmm import-official``).
"""

from controlmm.models.official.convert import import_official, load_official_checkpoint, official_model
from controlmm.models.official.folders import (
    RELEASED_CONTROL_NAMES,
    RELEASED_NAMES,
    find_control,
    find_momask,
)
from controlmm.models.official.names import map_official_state, split_control_state
from controlmm.models.official.opt import read_opt

__all__ = [
    "RELEASED_CONTROL_NAMES",
    "RELEASED_NAMES",
    "find_control",
    "find_momask",
    "import_official",
    "load_official_checkpoint",
    "map_official_state",
    "official_model",
    "read_opt",
    "split_control_state",
]
