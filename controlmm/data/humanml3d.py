"""Reading a HumanML3D-format directory, with the real dataset's quirks.

Layout (the real HumanML3D or the project's corpus)::

    DIR/new_joint_vecs/<id>.npy   (T, 263) float features, 20 fps
    DIR/texts/<id>.txt            one caption per line: caption#word/POS word/POS ...#start_s#end_s
    DIR/train.txt, val.txt, test.txt   one id per line
    DIR/Mean.npy, DIR/Std.npy     (263,) statistics (Std already group-averaged)

Quirks reproduced from the official text-to-motion loaders (MoMask/MaskControl ``Text2MotionDataset``):

- a motion is used only if 40 <= T < 200 frames (checked on the whole file first);
- a caption with start = end = 0 (or NaN) describes the whole motion; any other caption describes
  frames [int(start*20), int(end*20)) and becomes **its own sample** with that caption only, if the
  span also has 40 <= length < 200;
- the whole motion is a sample only if at least one caption describes all of it.

Anything malformed (missing folder or file, wrong array shape, NaN, an unparsable caption line, an
id listed in a split without its files) raises a one-line :class:`~controlmm.errors.InputFileError`
naming the file.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from tqdm import tqdm

from controlmm.errors import InputFileError
from controlmm.motion.normalization import Normalizer
from controlmm.motion.skeleton import FEATURE_DIM, FPS

SPLITS = ("train", "val", "test")
MIN_FRAMES = 40
MAX_FRAMES_EXCLUSIVE = 200


@dataclass(frozen=True)
class Caption:
    text: str
    tokens: tuple[str, ...]
    start: float  # seconds; 0 with end 0 = the whole motion
    end: float


@dataclass
class MotionSample:
    """One training sample: a motion (or a captioned span of one) and its captions."""

    name: str  # "<id>" or "<id>#<line>" for a span
    motion_id: str
    motion: np.ndarray  # (T, 263) float32, not normalised
    captions: list[str] = field(default_factory=list)

    @property
    def length(self) -> int:
        return int(self.motion.shape[0])


class HumanML3D:
    """A HumanML3D-format directory; checks its layout on construction."""

    def __init__(self, root: str | Path) -> None:
        self.root = Path(root)
        if not self.root.is_dir():
            raise InputFileError(f"data directory '{self.root}' does not exist")
        for sub in ("new_joint_vecs", "texts"):
            if not (self.root / sub).is_dir():
                raise InputFileError(
                    f"data directory '{self.root}' has no '{sub}/' folder "
                    "(expected the HumanML3D layout: new_joint_vecs/, texts/, train.txt, "
                    "val.txt, test.txt, Mean.npy, Std.npy)"
                )
        self.normalizer = self._statistics()

    # -- files ------------------------------------------------------------------------------------
    def _statistics(self) -> Normalizer:
        arrays = []
        for name in ("Mean.npy", "Std.npy"):
            path = self.root / name
            if not path.is_file():
                raise InputFileError(f"data directory '{self.root}' has no {name}")
            try:
                arr = np.load(path)
            except Exception as exc:  # noqa: BLE001
                raise InputFileError(f"cannot read '{path}': {type(exc).__name__}") from exc
            if arr.shape != (FEATURE_DIM,) or not np.all(np.isfinite(arr)):
                raise InputFileError(
                    f"'{path}' must hold a finite ({FEATURE_DIM},) array; got shape {arr.shape}"
                )
            arrays.append(arr.astype(np.float32))
        if np.any(arrays[1] <= 0):
            raise InputFileError(f"'{self.root / 'Std.npy'}' has non-positive entries")
        return Normalizer(*arrays)

    def split_ids(self, split: str) -> list[str]:
        """Ids listed in ``<split>.txt`` (blank lines ignored)."""
        if split not in SPLITS:
            raise InputFileError(f"unknown split '{split}'; allowed: {', '.join(SPLITS)}")
        path = self.root / f"{split}.txt"
        if not path.is_file():
            raise InputFileError(f"data directory '{self.root}' has no {split}.txt")
        ids = [line.strip() for line in path.read_text(encoding="utf-8").splitlines() if line.strip()]
        if not ids:
            raise InputFileError(f"'{path}' lists no motion ids")
        return ids

    def load_motion(self, motion_id: str) -> np.ndarray:
        """(T, 263) float32 features of one motion."""
        path = self.root / "new_joint_vecs" / f"{motion_id}.npy"
        if not path.is_file():
            raise InputFileError(f"motion '{motion_id}' is listed but '{path}' does not exist")
        try:
            arr = np.load(path)
        except Exception as exc:  # noqa: BLE001
            raise InputFileError(f"cannot read '{path}': {type(exc).__name__}: {exc}") from exc
        if arr.ndim != 2 or arr.shape[1] != FEATURE_DIM:
            raise InputFileError(f"'{path}' must hold (T, {FEATURE_DIM}) features; got shape {arr.shape}")
        if not np.issubdtype(arr.dtype, np.floating) or not np.all(np.isfinite(arr)):
            raise InputFileError(f"'{path}' holds non-finite or non-float values")
        return arr.astype(np.float32, copy=False)

    def read_captions(self, motion_id: str) -> list[Caption]:
        """Captions of one motion from ``texts/<id>.txt``."""
        path = self.root / "texts" / f"{motion_id}.txt"
        if not path.is_file():
            raise InputFileError(f"motion '{motion_id}' is listed but '{path}' does not exist")
        captions = []
        for number, line in enumerate(path.read_text(encoding="utf-8").splitlines(), start=1):
            if not line.strip():
                continue
            parts = line.strip().split("#")
            if len(parts) < 4 or not parts[0].strip():
                raise InputFileError(f"'{path}' line {number}: expected 'caption#tokens#start#end'")
            try:
                start, end = float(parts[2]), float(parts[3])
            except ValueError as exc:
                raise InputFileError(
                    f"'{path}' line {number}: start/end '{parts[2]}'/'{parts[3]}' are not numbers"
                ) from exc
            start = 0.0 if math.isnan(start) else start
            end = 0.0 if math.isnan(end) else end
            captions.append(Caption(parts[0].strip(), tuple(parts[1].split()), start, end))
        if not captions:
            raise InputFileError(f"'{path}' holds no captions")
        return captions

    # -- samples ----------------------------------------------------------------------------------
    def text_samples(self, split: str, progress: bool = False) -> list[MotionSample]:
        """Captioned samples of a split with the official span and length rules (see module doc)."""
        samples: list[MotionSample] = []
        for motion_id in tqdm(
            self.split_ids(split), desc=f"loading {split}", unit="motion", disable=not progress, leave=False
        ):
            motion = self.load_motion(motion_id)
            captions = self.read_captions(motion_id)
            if not MIN_FRAMES <= len(motion) < MAX_FRAMES_EXCLUSIVE:
                continue
            whole = []
            for k, cap in enumerate(captions):
                if cap.start == 0.0 and cap.end == 0.0:
                    whole.append(cap.text)
                    continue
                span = motion[int(cap.start * FPS) : int(cap.end * FPS)]
                if MIN_FRAMES <= len(span) < MAX_FRAMES_EXCLUSIVE:
                    samples.append(MotionSample(f"{motion_id}#{k}", motion_id, span, [cap.text]))
            if whole:
                samples.append(MotionSample(motion_id, motion_id, motion, whole))
        if not samples:
            raise InputFileError(
                f"split '{split}' of '{self.root}' has no usable captioned motion "
                f"({MIN_FRAMES} <= frames < {MAX_FRAMES_EXCLUSIVE})"
            )
        return samples

    def motions(self, split: str, min_frames: int, progress: bool = False) -> list[np.ndarray]:
        """Whole motions of a split with at least ``min_frames`` frames (tokenizer training)."""
        out = []
        for motion_id in tqdm(
            self.split_ids(split), desc=f"loading {split}", unit="motion", disable=not progress, leave=False
        ):
            motion = self.load_motion(motion_id)
            if len(motion) >= min_frames:
                out.append(motion)
        if not out:
            raise InputFileError(
                f"split '{split}' of '{self.root}' has no motion of at least {min_frames} frames"
            )
        return out
