"""Where the benchmarks find their data: the default corpus and the real HumanML3D sample clip.

The default corpus is ``data/corpus-default`` under the repository root, built once by
``controlmm corpus --out data/corpus-default --clips 9800 --seed 0`` (docs/corpus.md; about 17 min
on 2 shared cores, 1.5 GB). The real clip 012314 is looked up in ``$CONTROLMM_SHARED/data/humanml3d`` (default
``../shared`` beside the repository root), the folder the tests use. A missing input ends the
benchmark with one line that says how to get it.
"""

from __future__ import annotations

import os
import sys
from collections.abc import Mapping
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:  # only for the annotation: importing the model code pulls in torch
    from controlmm.models.model_dir import MotionModel

ROOT = Path(__file__).resolve().parents[1]
DEFAULT_CORPUS = ROOT / "data" / "corpus-default"
BUILD_CORPUS = "controlmm corpus --out data/corpus-default --clips 9800 --seed 0"
REAL_CLIP = "012314"


def shared_dir() -> Path:
    """The shared data folder: ``$CONTROLMM_SHARED``, else ``../shared`` beside the repository root."""
    return Path(os.environ.get("CONTROLMM_SHARED", ROOT.parent / "shared"))


def humanml3d_dir() -> Path:
    """The HumanML3D sample folder (``new_joint_vecs/``, ``new_joints/``, ``Mean.npy``, ``Std.npy``)."""
    return shared_dir() / "data" / "humanml3d"


def real_clip(kind: str = "new_joint_vecs") -> Path:
    """Path of the real clip 012314 (``kind``: ``new_joint_vecs`` features (T, 263) or ``new_joints``
    joints (T, 22, 3)); exits with one line when it is not there."""
    path = humanml3d_dir() / kind / f"{REAL_CLIP}.npy"
    if not path.is_file():
        sys.exit(
            f"the real HumanML3D clip {REAL_CLIP} is missing ({path}): set CONTROLMM_SHARED to the folder "
            "that holds data/humanml3d"
        )
    return path


def corpus_dir(path: str | Path | None = None, flag: str = "--data") -> Path:
    """The corpus directory ``path`` (default ``data/corpus-default``); exits with one line saying how
    to build it when it is not a HumanML3D-format directory with a test split."""
    corpus = Path(path) if path is not None else DEFAULT_CORPUS
    if not (corpus / "test.txt").is_file():
        sys.exit(
            f"corpus {corpus} not found: build it with `{BUILD_CORPUS}` (docs/corpus.md) or pass {flag} DIR"
        )
    return corpus


def training_data(manifest: Mapping) -> Path | None:
    """The data directory recorded in a model's training record (control stage first, then the
    transformer's, then the tokenizer's) when it exists on this machine, else None."""
    training = manifest.get("training", {})
    for stage in ("control", "transformer", "tokenizer"):
        data = training.get(stage, {}).get("data")
        if data and Path(data).is_dir():
            return Path(data)
    return None


def model_data(model: MotionModel, path: str | Path | None = None) -> Path:
    """The evaluation data of a loaded model: ``path`` when given, else the model's recorded training
    data when it is on this machine, else the default corpus."""
    if path is None:
        path = training_data(model.manifest)
    return corpus_dir(path)
