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
from controlmm.errors import ControlMMError, InputFileError
from controlmm.files import load_torch


def rng_state() -> dict[str, Any]:
    """Every RNG's state as tensors and plain containers (loadable with ``weights_only=True``)."""
    legacy = np.random.get_state(legacy=True)
    if not isinstance(legacy, tuple):  # a dict only when the global generator is not MT19937
        raise ControlMMError("numpy's global random generator is not MT19937; its state cannot be saved")
    kind, keys, pos, has_gauss, gauss = legacy
    numpy_state = (kind, torch.from_numpy(keys.astype(np.int64)), int(pos), int(has_gauss), float(gauss))
    state = {"python": random.getstate(), "numpy": numpy_state, "torch": torch.get_rng_state()}
    if torch.cuda.is_available():
        state["cuda"] = torch.cuda.get_rng_state_all()
    return state


def set_rng_state(state: dict[str, Any]) -> None:
    random.setstate(tuple(state["python"]))
    kind, keys, pos, has_gauss, gauss = state["numpy"]
    keys = keys.numpy() if isinstance(keys, torch.Tensor) else np.asarray(keys)
    np.random.set_state((kind, keys.astype(np.uint32), pos, has_gauss, gauss))
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


START_OVER = "start this stage over with --force (instead of --resume)"
"""How to recover from a training checkpoint that cannot be resumed."""


def load_checkpoint(path: Path) -> dict[str, Any]:
    """A training checkpoint (tensors and plain containers only: never arbitrary pickles)."""
    if not path.is_file():
        raise InputFileError(f"nothing to resume: '{path}' does not exist")
    data = load_torch(path, "training checkpoint", hint=START_OVER)
    if not isinstance(data, dict) or "step" not in data or "model" not in data:
        raise InputFileError(f"'{path}' is not a controlmm training checkpoint; {START_OVER}")
    return data
