"""Shared fixtures: the real HumanML3D sample in ``../shared/data/humanml3d``.

The sample is beside the repository on development machines and in CI, not in a user's clone:
there the tests that need it are skipped with a one-line reason. CI sets
``CONTROLMM_REQUIRE_SHARED=1`` (``.ci/run``), which turns a missing sample into a failure.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest

REPO_ROOT = Path(__file__).resolve().parents[1]
SHARED = Path(os.environ.get("CONTROLMM_SHARED", REPO_ROOT.parent / "shared"))
HUMANML3D = SHARED / "data" / "humanml3d"
SAMPLE_ID = "012314"


@pytest.fixture(scope="session")
def humanml3d_dir() -> Path:
    if not (HUMANML3D / "new_joint_vecs" / f"{SAMPLE_ID}.npy").is_file():
        reason = f"the real HumanML3D sample is not under {HUMANML3D} (set CONTROLMM_SHARED)"
        if os.environ.get("CONTROLMM_REQUIRE_SHARED") == "1":
            pytest.fail(reason)
        pytest.skip(reason)
    return HUMANML3D


@pytest.fixture(scope="session")
def sample_features(humanml3d_dir: Path) -> np.ndarray:
    """(170, 263) float32 features of HumanML3D motion 012314."""
    return np.load(humanml3d_dir / "new_joint_vecs" / f"{SAMPLE_ID}.npy")


@pytest.fixture(scope="session")
def sample_joints(humanml3d_dir: Path) -> np.ndarray:
    """(170, 22, 3) float32 global joints of HumanML3D motion 012314."""
    return np.load(humanml3d_dir / "new_joints" / f"{SAMPLE_ID}.npy")


@pytest.fixture(scope="session", autouse=True)
def embedding_cache(tmp_path_factory):
    """Prompt embeddings go to a session directory, not the user's cache (``CONTROLMM_CACHE_DIR``)."""
    previous = os.environ.get("CONTROLMM_CACHE_DIR")
    os.environ["CONTROLMM_CACHE_DIR"] = str(tmp_path_factory.mktemp("controlmm-cache"))
    yield Path(os.environ["CONTROLMM_CACHE_DIR"])
    if previous is None:
        os.environ.pop("CONTROLMM_CACHE_DIR", None)
    else:
        os.environ["CONTROLMM_CACHE_DIR"] = previous
