"""Text-motion evaluators: the project's own (trained with ``controlmm train evaluator``, one ships
for the default corpus) and the official HumanML3D evaluator when its files are on disk.

```python
from controlmm.eval.evaluator import load_evaluator

evaluator = load_evaluator()                    # the shipped one (controlmm/checkpoints/evaluator)
evaluator = load_evaluator("EVAL_DIR")          # one trained by `controlmm train evaluator`
evaluator = load_evaluator("momask-codes/")     # the official evaluator (checkpoints/t2m + glove)
evaluator.embed_texts(["a person walks forward"])      # (1, D)
evaluator.embed_motions([features])                    # (1, D); raw (T, 263) features or Motion
```
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import torch

from controlmm.errors import InputFileError
from controlmm.eval.evaluator.base import Evaluator
from controlmm.eval.evaluator.model import (
    TextMotionEvaluator,
    default_evaluator_dir,
    load_evaluator_dir,
)
from controlmm.eval.evaluator.modules import EVALUATOR_PRESETS, EvaluatorConfig, TextMotionEncoder
from controlmm.eval.evaluator.official import OfficialEvaluator, WordVectorizer, load_official_evaluator
from controlmm.eval.evaluator.words import Vocabulary, tokenize

__all__ = [
    "EVALUATOR_PRESETS",
    "Evaluator",
    "EvaluatorConfig",
    "OfficialEvaluator",
    "TextMotionEncoder",
    "TextMotionEvaluator",
    "Vocabulary",
    "WordVectorizer",
    "default_evaluator_dir",
    "load_evaluator",
    "load_evaluator_dir",
    "load_official_evaluator",
    "model_evaluator",
    "tokenize",
]


def model_evaluator(model_dirs: str | Path | Sequence[str | Path] | None) -> Path | None:
    """The evaluator a model directory carries (``MODEL_DIR/evaluator``, written by
    ``controlmm import-official --evaluator``) when exactly one model is given, else None."""
    given = [model_dirs] if model_dirs is None or isinstance(model_dirs, (str, Path)) else list(model_dirs)
    dirs = [d for d in given if d]
    if len(dirs) == 1 and (Path(dirs[0]) / "evaluator").is_dir():
        return Path(dirs[0]) / "evaluator"
    return None


def load_evaluator(path: str | Path | None = None, device: str | torch.device = "cpu") -> Evaluator:
    """An evaluator by location.

    Args:
        path: None -> the shipped evaluator; a directory with ``evaluator.json`` -> the project's
            evaluator; a directory with the official layout (``text_mot_match/model/finest.tar`` under
            it, its ``checkpoints/t2m`` or ``t2m``) -> the official HumanML3D evaluator.
        device: where the encoders run.
    """
    if path is None:
        path = default_evaluator_dir()
        if not (path / "evaluator.json").is_file():
            raise InputFileError(
                f"no shipped evaluator at '{path}'; train one with 'controlmm train evaluator "
                "--data DIR --out EVAL_DIR' and pass --evaluator EVAL_DIR"
            )
        return load_evaluator_dir(path, device)
    path = Path(path)
    if not path.is_dir():
        raise InputFileError(
            f"evaluator '{path}' is not a directory (an evaluator directory with evaluator.json, "
            "or a folder with the official HumanML3D evaluator)"
        )
    if (path / "evaluator.json").is_file():
        return load_evaluator_dir(path, device)
    if any((d / "text_mot_match").is_dir() for d in (path, path / "t2m", path / "checkpoints" / "t2m")):
        return load_official_evaluator(path, device)
    raise InputFileError(
        f"'{path}' is neither an evaluator directory (no evaluator.json) nor the official "
        "HumanML3D evaluator layout (no text_mot_match/ under it, t2m/ or checkpoints/t2m/)"
    )
