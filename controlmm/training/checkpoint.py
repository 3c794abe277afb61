"""Training checkpoints: everything needed to continue a run exactly where it stopped.

``MODEL_DIR/checkpoints/<stage>.pt`` holds the trained module, the optimizer, the LR scheduler, the
step and epoch, the RNG states of every process (Python, NumPy, torch CPU and CUDA), the best weights
so far, the validation history and stage extras (the tokenizer's EMA codebook statistics). It is
written atomically (temporary file + rename), so a run killed at any moment, even with SIGKILL,
leaves either the previous checkpoint or the new one, never a torn file.
"""

from __future__ import annotations

import random
from pathlib import Path
from typing import Any

import numpy as np
import torch

from controlmm.atomic import atomic_path
from controlmm.errors import InputFileError


def rng_state() -> dict[str, Any]:
    state = {"python": random.getstate(), "numpy": np.random.get_state(), "torch": torch.get_rng_state()}
    if torch.cuda.is_available():
        state["cuda"] = torch.cuda.get_rng_state_all()
    return state


def set_rng_state(state: dict[str, Any]) -> None:
    random.setstate(state["python"])
    np.random.set_state(state["numpy"])
    torch.set_rng_state(state["torch"])
    if "cuda" in state and torch.cuda.is_available():
        torch.cuda.set_rng_state_all(state["cuda"])


def seed_everything(seed: int) -> None:
    random.seed(seed)
    np.random.seed(seed % 2**32)
    torch.manual_seed(seed)


def save_checkpoint(path: Path, payload: dict[str, Any]) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic_path(path) as tmp:
        torch.save(payload, tmp)


def load_checkpoint(path: Path) -> dict[str, Any]:
    if not path.is_file():
        raise InputFileError(f"nothing to resume: '{path}' does not exist")
    try:
        data = torch.load(path, map_location="cpu", weights_only=False)
    except Exception as exc:  # noqa: BLE001
        raise InputFileError(
            f"training checkpoint '{path}' is corrupt or unreadable ({type(exc).__name__})"
        ) from exc
    if not isinstance(data, dict) or "step" not in data or "model" not in data:
        raise InputFileError(f"'{path}' is not a controlmm training checkpoint")
    return data
