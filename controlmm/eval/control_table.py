"""Spatial control with text-motion quality: the paper's Table 1 and Table 3 analogues, over repeats.

Each row of the table is a joint mode (whose cases give the targets,
:func:`controlmm.eval.control.build_cases`) and an editing preset; every repeat r draws fresh cases
(seed + r: other clips, captions, crops, keyframes) and generates every row on them with seed + r.
Per row and repeat:

- the control columns of :func:`~controlmm.eval.control.evaluate_control` over all its cases:
  foot-skating ratio, Traj. err, Loc. err, Avg. err (m);
- the text-motion columns of :func:`controlmm.eval.scoring.score_motions` on the generated motions,
  with the ground truth of the same cases as the FID reference: R-precision top-1/2/3, FID, MM-Dist,
  Diversity.

The **Real** row scores the ground truth itself (control errors 0 by construction, its own foot
skating; FID against the same clips with other random crops, :func:`recropped`, as the official
"ground truth" row compares two loader passes over the same test clips). The **uncontrolled** row
(:data:`UNCONTROLLED`) generates the same prompts and lengths with neither the control model nor
editing, its errors measured against the targets of its joint mode (Table 3 row 1). Every column is
reported as mean and 95 % CI (1.96 std / sqrt(repeats)).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from controlmm.data.humanml3d import HumanML3D
from controlmm.editing import EditingConfig
from controlmm.errors import ControlMMError
from controlmm.eval.control import ControlCase, ControlEvaluation, build_cases, evaluate_control
from controlmm.eval.evaluator.base import Evaluator
from controlmm.eval.scoring import SCORE_COLUMNS, MotionSet, Scores, score_motions
from controlmm.models import MotionModel
from controlmm.motion.geometry import foot_skating_ratio
from controlmm.motion.skeleton import FPS, MAX_FRAMES

CONTROL_COLUMNS = ("skate", "traj", "loc", "avg")
TABLE_COLUMNS = (
    "r_precision_top1",
    "r_precision_top2",
    "r_precision_top3",
    "fid",
    "diversity",
    "mm_dist",
) + CONTROL_COLUMNS
HEADERS = {
    "r_precision_top1": "R@1",
    "r_precision_top2": "R@2",
    "r_precision_top3": "R@3",
    "fid": "FID",
    "mm_dist": "MM-Dist",
    "diversity": "Diversity",
    "skate": "Skate",
    "traj": "Traj. err",
    "loc": "Loc. err",
    "avg": "Avg. err cm",
}
UNCONTROLLED = EditingConfig(name="uncontrolled", control_model=False, logits_steps=0, codebook_steps=0)
"""Plain generation through the controlled path: no control model, no editing (Table 3 row 1)."""
REAL_SEED_OFFSET = 100_003


@dataclass(frozen=True)
class TableRow:
    """One method row: its name, the joint mode of its cases and the editing preset it generates with."""

    name: str
    joints: str = "pelvis"
    preset: str | EditingConfig = "accurate"


@dataclass
class ControlTable:
    """Per-repeat values of every column for each row (:attr:`rows`) and the per-row evaluations."""

    data: str
    model: str
    evaluator: str
    repeats: int
    samples: int
    densities: tuple[int, ...]
    rows: dict[str, Scores] = field(default_factory=dict)
    evaluations: dict[str, list[ControlEvaluation]] = field(default_factory=dict)  # one per repeat
    settings: dict[str, Any] = field(default_factory=dict)

    def summary(self) -> dict[str, dict[str, tuple[float, float]]]:
        """Row -> column -> (mean, 95 % CI half-width)."""
        return {name: scores.summary() for name, scores in self.rows.items()}

    def table(self) -> str:
        """Text table: one row per method, cells ``mean±ci`` (Avg. err in cm)."""
        summary = self.summary()
        width = max([len("Method")] + [len(r) for r in summary])
        cols = [c for c in TABLE_COLUMNS if any(c in s for s in summary.values())]
        head = f"{'Method':<{width}} " + " ".join(f"{HEADERS[c]:>14}" for c in cols)
        lines = [head, "-" * len(head)]
        for name, values in summary.items():
            cells = []
            for c in cols:
                if c not in values:
                    cells.append("-".rjust(14))
                    continue
                mean, ci = values[c]
                scale, digits = (100.0, 2) if c == "avg" else (1.0, 4 if c in CONTROL_COLUMNS else 3)
                cells.append(f"{scale * mean:.{digits}f}±{scale * ci:.{digits}f}".rjust(14))
            lines.append(f"{name:<{width}} " + " ".join(cells))
        return "\n".join(lines)

    def to_json(self) -> dict[str, Any]:
        return {
            "data": self.data,
            "model": self.model,
            "evaluator": self.evaluator,
            "repeats": self.repeats,
            "samples_per_repeat": self.samples,
            "densities": list(self.densities),
            "settings": self.settings,
            "rows": {name: scores.to_json() for name, scores in self.rows.items()},
        }


def _control_values(result: ControlEvaluation) -> dict[str, float]:
    summary = result.by_density()["all"]
    keep = CONTROL_COLUMNS + ("max", "steps", "seconds", "cpu_seconds")
    return {k: float(summary[k]) for k in keep if k in summary}


def _real_values(cases: Sequence[ControlCase]) -> dict[str, float]:
    return {
        "skate": float(np.mean([foot_skating_ratio(c.targets, FPS) for c in cases])),
        "traj": 0.0,
        "loc": 0.0,
        "avg": 0.0,
    }


def recropped(
    data: str | Path, cases: Sequence[ControlCase], seed: int, split: str = "test"
) -> list[np.ndarray]:
    """The ground truth of the same samples with another random crop: per case, the clip (or captioned
    span) it was cut from, m = its length rounded down to a multiple of 4 (at most 196) with one unit
    less with probability 1/3 (the official loader's coin), a random start. Returns (m, 263) arrays."""
    by_id: dict[str, list] = {}
    for sample in HumanML3D(data).text_samples(split):
        by_id.setdefault(sample.motion_id, []).append(sample)
    rng = np.random.default_rng([seed, REAL_SEED_OFFSET])
    out = []
    for case in cases:
        candidates = by_id.get(case.motion_id)
        if not candidates:
            raise ControlMMError(f"clip '{case.motion_id}' is not in the {split} split of '{data}'")
        source = next((s for s in candidates if case.text in s.captions), candidates[0])
        units = min(source.length, MAX_FRAMES) // 4
        if rng.integers(3) == 2 and units > 1:
            units -= 1
        start = int(rng.integers(0, source.length - 4 * units + 1))
        out.append(source.motion[start : start + 4 * units].astype(np.float32))
    return out


def evaluate_control_table(
    model: MotionModel,
    data: str | Path,
    rows: Sequence[TableRow],
    *,
    evaluator: Evaluator | None = None,
    densities: Sequence[int] = (1, 2, 5, 49, 196),
    samples: int = 64,
    repeats: int = 1,
    seed: int = 0,
    batch_size: int = 1,
    real: bool = True,
    progress: bool = False,
) -> ControlTable:
    """Generate and measure every row on ``repeats`` fresh draws of cases (see the module docstring).

    Args:
        model: a loaded :class:`~controlmm.models.MotionModel` (with ``control.pt`` for presets using the
            control model).
        data: HumanML3D-format directory; its test split gives the cases.
        rows: the method rows, in table order (e.g. ``TableRow("uncontrolled", "pelvis", UNCONTROLLED)``,
            ``TableRow("pelvis")``, ``TableRow("all joints (avg)", "each")``).
        evaluator: scores the text-motion columns; None = control columns only.
        densities, samples, seed, batch_size: as :func:`~controlmm.eval.control.build_cases` and
            :func:`~controlmm.eval.control.evaluate_control`.
        repeats: draws of cases (and generations); the CIs are over these.
        real: include the "Real" row (ground truth, cases of the first row's joint mode; FID against
            :func:`recropped`).
    """
    if repeats < 1:
        raise ControlMMError(f"repeats must be at least 1; got {repeats}")
    if not rows:
        raise ControlMMError("no rows to evaluate")
    names = [r.name for r in rows]
    if len(set(names)) != len(names) or (real and "Real" in names):
        raise ControlMMError(f"row names must be unique (and not 'Real'); got {', '.join(names)}")
    table = ControlTable(
        data=str(data),
        model=str(model.directory or ""),
        evaluator=evaluator.name if evaluator is not None else "",
        repeats=repeats,
        samples=samples,
        densities=tuple(densities),
        settings={
            "seed": seed,
            "batch_size": batch_size,
            "rows": {r.name: {"joints": r.joints, "preset": _preset_record(r.preset)} for r in rows},
        },
    )
    sets: dict[str, list[MotionSet]] = {}
    for r in range(repeats):
        run_seed = seed + r
        cases_by_mode = {}
        for row in rows:
            if row.joints not in cases_by_mode:
                cases_by_mode[row.joints] = build_cases(data, row.joints, densities, samples, seed=run_seed)
        if real:
            cases = cases_by_mode[rows[0].joints]
            table.rows.setdefault("Real", Scores()).add(_real_values(cases), CONTROL_COLUMNS)
            sets.setdefault("Real", []).append(
                MotionSet(
                    [c.features for c in cases], [c.text for c in cases], recropped(data, cases, run_seed)
                )
            )
        for row in rows:
            cases = cases_by_mode[row.joints]
            result = evaluate_control(
                model,
                cases,
                preset=row.preset,
                seed=run_seed,
                batch_size=batch_size,
                progress=progress,
                joints=row.joints,
            )
            table.evaluations.setdefault(row.name, []).append(result)
            table.rows.setdefault(row.name, Scores()).add(
                _control_values(result), CONTROL_COLUMNS + ("max", "steps", "seconds", "cpu_seconds")
            )
            sets.setdefault(row.name, []).append(
                MotionSet(list(result.generated), [c.text for c in cases], [c.features for c in cases])
            )
    if evaluator is not None:
        for name, runs in sets.items():
            table.rows[name].values.update(score_motions(evaluator, runs, seed=seed).values)
    return table


def _preset_record(preset: str | EditingConfig) -> Any:
    if isinstance(preset, str):
        return preset
    return {
        "name": preset.name,
        "control_model": preset.control_model,
        "logits_steps": preset.logits_steps,
        "codebook_steps": preset.codebook_steps,
    }


__all__ = [
    "CONTROL_COLUMNS",
    "ControlTable",
    "SCORE_COLUMNS",
    "TABLE_COLUMNS",
    "TableRow",
    "UNCONTROLLED",
    "evaluate_control_table",
    "recropped",
]
