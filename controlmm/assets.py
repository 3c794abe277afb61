"""Where shipped model checkpoints live inside the installed package (nothing downloads)."""

from __future__ import annotations

from pathlib import Path

CHECKPOINT_ROOT = Path(__file__).resolve().parent / "checkpoints"
"""Folder of the embedded model directories shipped with the package."""

DEFAULT_MODEL_NAME = "default"


def default_model_dir() -> Path:
    """The embedded default model directory (trained on the project's corpus)."""
    return CHECKPOINT_ROOT / DEFAULT_MODEL_NAME


def available_models() -> list[str]:
    """Names of the embedded model directories that are present (folders with a model.json)."""
    if not CHECKPOINT_ROOT.is_dir():
        return []
    return sorted(p.name for p in CHECKPOINT_ROOT.iterdir() if (p / "model.json").is_file())
