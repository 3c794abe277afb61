"""The project's evaluator as a directory on disk, and its :class:`~.base.Evaluator` implementation.

Layout (written by ``controlmm train evaluator --out EVAL_DIR``)::

    EVAL_DIR/evaluator.json   format "controlmm-evaluator", format_version 1, config (sizes),
                              vocabulary (the training captions' words), normalization (source),
                              part (file, dtype, parameters, bytes, sha256), training record
                              (data, schedule, seed, wall time, throughput, validation history),
                              retrieval (R-precision of the ground truth on val and test)
    EVAL_DIR/mean.npy         (263,) feature mean (the training data's Mean.npy)
    EVAL_DIR/std.npy          (263,) feature std (the training data's Std.npy)
    EVAL_DIR/evaluator.pt     weights {"format": "controlmm-part", "part": "evaluator", "state_dict"}, float16
    EVAL_DIR/checkpoints/     training checkpoints (not needed to evaluate; not shipped)

The evaluator trained on the default corpus ships in ``controlmm/checkpoints/evaluator``
(:func:`default_evaluator_dir`) and is used when no other is named.
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
import torch

from controlmm.assets import CHECKPOINT_ROOT
from controlmm.atomic import write_text
from controlmm.errors import InputFileError
from controlmm.eval.evaluator.base import MotionLike, TextLike, caption_text, pad_normalized
from controlmm.eval.evaluator.modules import EvaluatorConfig, TextMotionEncoder
from controlmm.eval.evaluator.words import Vocabulary
from controlmm.models.model_dir import load_part_state, load_state_strict, read_statistics
from controlmm.motion.normalization import Normalizer

FORMAT = "controlmm-evaluator"
FORMAT_VERSION = 1
MANIFEST = "evaluator.json"
WEIGHTS = "evaluator"  # part name: evaluator.pt


def default_evaluator_dir() -> Path:
    """The evaluator shipped with the package (trained on the default corpus)."""
    return CHECKPOINT_ROOT / "evaluator"


class TextMotionEvaluator:
    """The project's evaluator: vocabulary, normalisation and the two encoders (eval mode, CPU)."""

    def __init__(
        self,
        module: TextMotionEncoder,
        vocabulary: Vocabulary,
        normalizer: Normalizer,
        manifest: dict[str, Any] | None = None,
        directory: Path | None = None,
        device: str | torch.device = "cpu",
    ) -> None:
        self.module = module.eval().requires_grad_(False).to(device)
        self.vocabulary, self.normalizer = vocabulary, normalizer
        self.manifest = manifest or {}
        self.directory = directory
        self.device = torch.device(device)
        self.dim = module.cfg.embed_dim
        trained_on = Path(str(self.manifest.get("training", {}).get("data", ""))).name or "?"
        self.name = f"controlmm evaluator ({trained_on})"

    @torch.no_grad()
    def embed_texts(self, captions: Sequence[TextLike], batch_size: int = 256) -> np.ndarray:
        """Captions (strings, or objects with ``.text``) -> (N, dim) float64 embeddings."""
        out = []
        for start in range(0, len(captions), batch_size):
            texts = [caption_text(c) for c in captions[start : start + batch_size]]
            ids, lengths = self.vocabulary.encode(texts)
            out.append(self.module.encode_text(ids.to(self.device), lengths).double().cpu().numpy())
        return np.concatenate(out) if out else np.zeros((0, self.dim))

    @torch.no_grad()
    def embed_motions(self, motions: Sequence[MotionLike], batch_size: int = 256) -> np.ndarray:
        """Motions (raw features, up to 196 frames; longer ones are cut) -> (N, dim) float64 embeddings."""
        out = []
        for start in range(0, len(motions), batch_size):
            x, lengths = pad_normalized(motions[start : start + batch_size], self.normalizer)
            out.append(
                self.module.encode_motion(x.to(self.device), lengths.to(self.device)).double().cpu().numpy()
            )
        return np.concatenate(out) if out else np.zeros((0, self.dim))

    def unknown_word_share(self, captions: Sequence[TextLike]) -> float:
        """Share of caption words outside the evaluator's vocabulary (0..1)."""
        return self.vocabulary.unknown_share([caption_text(c) for c in captions])


# -- the directory --------------------------------------------------------------------------------
def new_manifest(
    config: EvaluatorConfig, vocabulary: Vocabulary, normalization: dict[str, Any]
) -> dict[str, Any]:
    return {
        "format": FORMAT,
        "format_version": FORMAT_VERSION,
        "config": config.to_dict(),
        "vocabulary": list(vocabulary.words),
        "normalization": normalization,
        "part": None,
        "training": {},
        "retrieval": {},
    }


def read_evaluator_manifest(directory: str | Path) -> dict[str, Any]:
    """The checked ``evaluator.json`` of an evaluator directory."""
    directory = Path(directory)
    path = directory / MANIFEST
    if not directory.is_dir():
        raise InputFileError(f"evaluator directory '{directory}' does not exist")
    if not path.is_file():
        raise InputFileError(f"'{directory}' is not an evaluator directory: {MANIFEST} is missing")
    try:
        manifest = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, json.JSONDecodeError) as exc:
        raise InputFileError(f"'{path}' is not valid JSON: {exc}") from None
    if not isinstance(manifest, dict) or manifest.get("format") != FORMAT:
        raise InputFileError(f"'{path}' is not a controlmm evaluator description (format '{FORMAT}')")
    if manifest.get("format_version") != FORMAT_VERSION:
        raise InputFileError(
            f"'{path}' has format version {manifest.get('format_version')}; "
            f"this controlmm reads version {FORMAT_VERSION}"
        )
    for key in ("config", "vocabulary", "part"):
        if not manifest.get(key):
            raise InputFileError(
                f"'{path}' has no {key}" + (" (training has not finished)" if key == "part" else "")
            )
    return manifest


def write_evaluator_manifest(directory: Path, manifest: dict[str, Any]) -> None:
    write_text(directory / MANIFEST, json.dumps(manifest, indent=1) + "\n")


def load_evaluator_dir(directory: str | Path, device: str | torch.device = "cpu") -> TextMotionEvaluator:
    """Load an evaluator directory (checked format, checksum, names and shapes)."""
    directory = Path(directory)
    manifest = read_evaluator_manifest(directory)
    try:
        config = EvaluatorConfig.from_dict(manifest["config"])
        vocabulary = Vocabulary(tuple(manifest["vocabulary"]), config.max_words)
    except (TypeError, ValueError) as exc:
        raise InputFileError(f"'{directory / MANIFEST}' is malformed: {exc}") from None
    module = TextMotionEncoder(config)
    state = load_part_state(directory, WEIGHTS, manifest["part"])
    load_state_strict(module, state, str(directory / f"{WEIGHTS}.pt"))
    return TextMotionEvaluator(module, vocabulary, read_statistics(directory), manifest, directory, device)
