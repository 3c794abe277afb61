"""The spatial-control evaluation protocol of OmniControl/ControlMM (the official MaskControl evaluation,
https://github.com/exitudio/MaskControl).

Cases come from held-out motions (the test split of a HumanML3D-format directory): per case a clip
and one of its captions, the length rounded down to a multiple of 4 (at most 196 frames) with a
random crop, targets = the clip's own global joints R(features). Keyframes: ``density`` d in
{1, 2, 5, 49, 196}: d frames for d <= 5, else int(m d / 196) frames (25 % / 100 % of the clip),
drawn uniformly without replacement; every coordinate of each controlled joint is controlled.

Joint modes: a single control joint (``pelvis``, ``left_foot``, ``right_foot``, ``head``,
``left_wrist``, ``right_wrist``), ``cross`` (the 63 non-empty subsets of those six joints, Paper
A.11 order; case i takes subset i mod 63, where the official script draws one subset per 256-sample
call), ``all`` (the six at once), ``random`` (one of the six per case) or ``each`` (the six in turn,
case i controls joint i mod 6: the paper's all-joints average with a sixth of the cases per joint).

Metrics (per case, keyframes F = frames with a controlled joint, e_t = mean over the controlled
joints of frame t of the distance to the target, metres):

- **Traj. err**: fraction of cases with any e_t > 0.5 m;
- **Loc. err**: mean over cases of the fraction of keyframes with e_t > 0.5 m;
- **Avg. err**: mean over cases of the mean e_t;
- **foot-skating ratio** (:func:`controlmm.motion.geometry.foot_skating_ratio`) on the generated
  motion's own frames (the official script also counts the padding frames up to 196).

Text-motion metrics (FID, R-precision, diversity) plug in through ``text_metrics``: any callable
``(generated motions, texts, ground-truth motions) -> {column: value}``.
"""

from __future__ import annotations

import itertools
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from tqdm import tqdm

from controlmm.data.humanml3d import HumanML3D
from controlmm.editing import EditingConfig, editing_preset
from controlmm.errors import ControlMMError
from controlmm.generate import generate_controlled
from controlmm.models import MotionModel
from controlmm.motion.container import Motion
from controlmm.motion.geometry import foot_skating_ratio
from controlmm.motion.recover import features_to_joints_np
from controlmm.motion.skeleton import CONTROL_JOINTS, FPS, JOINT_NAMES, MAX_FRAMES, NUM_JOINTS

DENSITIES: tuple[int, ...] = (1, 2, 5, 49, 196)
SINGLE_JOINTS: dict[str, int] = {JOINT_NAMES[j]: j for j in CONTROL_JOINTS}
JOINT_MODES: tuple[str, ...] = tuple(SINGLE_JOINTS) + ("cross", "all", "random", "each")
CROSS_COMBINATIONS: tuple[tuple[int, ...], ...] = tuple(
    c for k in range(1, len(CONTROL_JOINTS) + 1) for c in itertools.combinations(CONTROL_JOINTS, k)
)
"""The 63 non-empty subsets of the six control joints: 6 singles, 15 pairs, 20 triples, 15, 6, 1."""
THRESHOLD = 0.5  # metres, the "50 cm" of Traj./Loc. err

TextMetrics = Callable[[list[Motion], list[str], list[Motion]], dict[str, float]]
"""(generated motions, their texts, ground-truth motions) -> extra columns (FID, R-precision...)."""


@dataclass(frozen=True)
class ControlCase:
    """One evaluation case: a caption, a length, targets and the controlled entries."""

    motion_id: str
    text: str
    frames: int
    targets: np.ndarray  # (frames, 22, 3) metres, human frame
    mask: np.ndarray  # (frames, 22) bool
    density: int
    joints: tuple[int, ...]
    features: np.ndarray  # (frames, 263) the ground-truth clip


def build_cases(
    data_dir: str | Path,
    joints: str = "pelvis",
    densities: Sequence[int] = DENSITIES,
    samples: int = 100,
    seed: int = 0,
    split: str = "test",
) -> list[ControlCase]:
    """``samples`` cases from a split; case i uses ``densities[i % len(densities)]``.

    Clips are drawn without replacement while they last (then again), with a random caption and crop.
    """
    if joints not in JOINT_MODES:
        raise ControlMMError(f"unknown joint mode '{joints}'; allowed: {', '.join(JOINT_MODES)}")
    for d in densities:
        if d not in DENSITIES:
            raise ControlMMError(f"unknown density {d}; allowed: {', '.join(map(str, DENSITIES))}")
    if samples < 1:
        raise ControlMMError(f"samples must be at least 1; got {samples}")
    pool = HumanML3D(data_dir).text_samples(split)
    if not pool:
        raise ControlMMError(f"the {split} split of '{data_dir}' has no usable clips")
    rng = np.random.default_rng(seed)
    order: list[int] = []
    while len(order) < samples:
        order.extend(rng.permutation(len(pool)).tolist())
    cases = []
    for i in range(samples):
        sample = pool[order[i]]
        text = sample.captions[int(rng.integers(len(sample.captions)))]
        m = min(sample.length, MAX_FRAMES) // 4 * 4
        start = int(rng.integers(0, sample.length - m + 1))
        feats = sample.motion[start : start + m].astype(np.float32)
        targets = features_to_joints_np(feats).astype(np.float32)
        density = int(densities[i % len(densities)])
        chosen = _case_joints(joints, i, rng)
        count = density if density <= 5 else int(m * density / MAX_FRAMES)
        frames = rng.choice(m, size=max(1, min(count, m)), replace=False)
        mask = np.zeros((m, NUM_JOINTS), dtype=bool)
        mask[np.ix_(frames, np.array(chosen, dtype=np.intp))] = True
        cases.append(ControlCase(sample.motion_id, text, m, targets, mask, density, chosen, feats))
    return cases


def _case_joints(mode: str, i: int, rng: np.random.Generator) -> tuple[int, ...]:
    if mode in SINGLE_JOINTS:
        return (SINGLE_JOINTS[mode],)
    if mode == "cross":
        return CROSS_COMBINATIONS[i % len(CROSS_COMBINATIONS)]
    if mode == "all":
        return tuple(CONTROL_JOINTS)
    if mode == "each":
        return (CONTROL_JOINTS[i % len(CONTROL_JOINTS)],)
    return (CONTROL_JOINTS[int(rng.integers(len(CONTROL_JOINTS)))],)


# -- metrics ----------------------------------------------------------------------------------------
def keyframe_errors(joints: np.ndarray, targets: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """e_t (|F|,): for each frame with a controlled joint, the mean distance (m) over its controlled
    joints."""
    t = mask.shape[0]
    dist = np.linalg.norm(np.asarray(joints, dtype=np.float64)[:t] - targets, axis=-1)
    frames = np.flatnonzero(mask.any(-1))
    return np.array([dist[f][mask[f]].mean() for f in frames], dtype=np.float64)


def case_metrics(
    joints: np.ndarray, targets: np.ndarray, mask: np.ndarray, threshold: float = THRESHOLD
) -> dict[str, float]:
    """Traj. fail (0/1), Loc. fail fraction, Avg. err (m) and the worst controlled-joint error (m) of one
    case."""
    e = keyframe_errors(joints, targets, mask)
    if len(e) == 0:
        raise ControlMMError("a control case needs at least one controlled entry")
    dist = np.linalg.norm(np.asarray(joints, dtype=np.float64)[: mask.shape[0]] - targets, axis=-1)[mask]
    return {
        "traj": float(np.any(e > threshold)),
        "loc": float(np.mean(e > threshold)),
        "avg": float(e.mean()),
        "max": float(dist.max()),
    }


def summarize(rows: Sequence[dict[str, float]]) -> dict[str, float]:
    """Means of per-case metric dicts: traj -> Traj. err, loc -> Loc. err, avg -> Avg. err, ...;
    max -> max."""
    if not rows:
        return {}
    out = {k: float(np.mean([r[k] for r in rows])) for k in rows[0] if k != "max"}
    if "max" in rows[0]:
        out["max"] = float(np.max([r["max"] for r in rows]))
    out["cases"] = float(len(rows))
    return out


# -- the protocol -----------------------------------------------------------------------------------
@dataclass
class ControlEvaluation:
    """Per-case metrics and the tables of one evaluation run."""

    preset: str
    joints: str
    cases: list[ControlCase]
    rows: list[dict[str, float]]
    generated: list[Motion] = field(default_factory=list)
    extra: dict[str, float] = field(default_factory=dict)  # text-motion metrics, if any
    seconds: float = 0.0

    def by_density(self) -> dict[str, dict[str, float]]:
        """Summary per density and over all cases (``"all"``)."""
        out: dict[str, dict[str, float]] = {}
        for d in sorted({c.density for c in self.cases}):
            out[str(d)] = summarize([r for r, c in zip(self.rows, self.cases, strict=True) if c.density == d])
        out["all"] = summarize(self.rows) | self.extra
        return out

    def table(self) -> str:
        """A text table: one row per density and the average."""
        header = (
            f"{'density':>8} {'cases':>6} {'Traj.err':>9} {'Loc.err':>8} {'Avg.err cm':>11} "
            f"{'max cm':>8} {'skate':>7} {'steps':>7} {'s/motion':>9}"
        )
        lines = [f"spatial control: joints {self.joints}, preset {self.preset}", header]
        for name, s in self.by_density().items():
            lines.append(
                f"{name:>8} {int(s['cases']):>6} {s['traj']:>9.4f} {s['loc']:>8.4f} {100 * s['avg']:>11.3f} "
                f"{100 * s['max']:>8.2f} {s['skate']:>7.4f} {s['steps']:>7.0f} {s['seconds']:>9.2f}"
            )
        if self.extra:
            lines.append("  " + ", ".join(f"{k} {v:.4g}" for k, v in self.extra.items()))
        return "\n".join(lines)

    def to_json(self) -> dict[str, Any]:
        return {
            "preset": self.preset,
            "joints": self.joints,
            "summary": self.by_density(),
            "cases": [
                {
                    "motion_id": c.motion_id,
                    "text": c.text,
                    "frames": c.frames,
                    "density": c.density,
                    "joints": [JOINT_NAMES[j] for j in c.joints],
                }
                | r
                for c, r in zip(self.cases, self.rows, strict=True)
            ],
        }


def evaluate_control(
    model: MotionModel,
    cases: Sequence[ControlCase],
    preset: str | EditingConfig = "accurate",
    seed: int = 0,
    batch_size: int = 1,
    text_metrics: TextMetrics | None = None,
    progress: bool = False,
    joints: str = "",
) -> ControlEvaluation:
    """Generate every case under its control and measure it (see the module docstring).

    Args:
        model: a loaded :class:`~controlmm.models.MotionModel`.
        cases: from :func:`build_cases`.
        preset: ``fast``, ``medium``, ``accurate`` or an :class:`~controlmm.editing.EditingConfig`.
        batch_size: cases generated together (1 gives per-motion timings).
        text_metrics: optional extra columns computed on (generated, texts, ground truth).
    """
    rows: list[dict[str, float]] = []
    generated: list[Motion] = []
    started = time.perf_counter()
    bar = tqdm(total=len(cases), desc="eval control", unit="case", disable=not progress)
    for start in range(0, len(cases), batch_size):
        chunk = list(cases[start : start + batch_size])
        t_max = max(c.frames for c in chunk)
        targets = np.zeros((len(chunk), t_max, NUM_JOINTS, 3), dtype=np.float32)
        mask = np.zeros((len(chunk), t_max, NUM_JOINTS), dtype=bool)
        for k, c in enumerate(chunk):
            targets[k, : c.frames], mask[k, : c.frames] = c.targets, c.mask
        out = generate_controlled(
            model,
            [c.text for c in chunk],
            targets=targets,
            mask=mask,
            frames=[c.frames for c in chunk],
            preset=preset,
            seed=seed + start,
            batch_size=batch_size,
        )
        for c, motion, record in zip(chunk, out.motions, out.records, strict=True):
            row = case_metrics(motion.joints, c.targets, c.mask)
            row |= {
                "skate": foot_skating_ratio(motion.joints, FPS),
                "steps": float(record.total_steps),
                "seconds": record.seconds,
                "cpu_seconds": record.cpu_seconds,
                "converged": float(record.converged),
            }
            rows.append(row)
            generated.append(motion)
        bar.update(len(chunk))
    bar.close()
    result = ControlEvaluation(
        preset=editing_preset(preset).name,
        joints=joints,
        cases=list(cases),
        rows=rows,
        generated=generated,
        seconds=time.perf_counter() - started,
    )
    if text_metrics is not None:
        truth = [Motion.from_features(c.features, text=c.text) for c in cases]
        result.extra = dict(text_metrics(generated, [c.text for c in cases], truth))
    return result
