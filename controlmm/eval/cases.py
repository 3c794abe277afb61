"""Probe cases (a caption with its claims, :class:`~controlmm.corpus.probes.ProbeCase`) from a corpus,
probe runs and their report."""

from __future__ import annotations

import json
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from tqdm import tqdm

from controlmm.corpus.probes import PROBES, ProbeCase, ProbeResult, check
from controlmm.errors import ControlMMError, InputFileError
from controlmm.motion import Motion


def list_cases(data_dir: str | Path, split: str = "test") -> list[ProbeCase]:
    """Every (caption, metadata) pair of a corpus split, in clip-id order.

    Raises a one-line error when the directory is not a corpus with per-clip metadata.
    """
    root = Path(data_dir)
    if not root.is_dir():
        raise InputFileError(f"--data '{root}' is not a directory")
    split_file = root / f"{split}.txt"
    if split not in ("train", "val", "test", "all"):
        raise ControlMMError(f"unknown split '{split}'; allowed: train, val, test, all")
    if not split_file.is_file():
        raise InputFileError(f"'{root}' has no {split}.txt; not a HumanML3D-format corpus")
    if not (root / "meta").is_dir():
        raise InputFileError(f"'{root}' has no meta/ directory; probes need the corpus' per-clip metadata")
    cases = []
    for clip_id in split_file.read_text(encoding="utf-8").split():
        path = root / "meta" / f"{clip_id}.json"
        try:
            meta = json.loads(path.read_text(encoding="utf-8"))
            for cap in meta["captions"]:
                cases.append(
                    ProbeCase(
                        clip_id=clip_id,
                        caption=cap["text"],
                        family=meta["family"],
                        claims=dict(cap["claims"]),
                        frames=int(meta["frames"]),
                        split=meta["split"],
                        template=cap.get("template", ""),
                        held_out=bool(cap.get("held_out")),
                        params=meta.get("params", {}),
                    )
                )
        except FileNotFoundError:
            raise InputFileError(f"clip '{clip_id}' has no metadata file {path}") from None
        except (ValueError, KeyError, TypeError) as exc:
            raise InputFileError(f"malformed metadata {path}: {type(exc).__name__}: {exc}") from None
    return cases


@dataclass
class ProbeReport:
    """Pass counts per family and the failed cases of a probe run."""

    split: str
    counts: dict[str, list[int]] = field(default_factory=dict)  # family -> [passed, total]
    failures: list[tuple[ProbeCase, ProbeResult]] = field(default_factory=list)

    def add(self, case: ProbeCase, result: ProbeResult) -> None:
        entry = self.counts.setdefault(case.family, [0, 0])
        entry[0] += int(result.passed)
        entry[1] += 1
        if not result.passed:
            self.failures.append((case, result))

    @property
    def passed(self) -> int:
        return sum(p for p, _ in self.counts.values())

    @property
    def total(self) -> int:
        return sum(t for _, t in self.counts.values())

    @property
    def rate(self) -> float:
        return self.passed / self.total if self.total else float("nan")

    def table(self) -> str:
        """A plain-text table: family, captions, passed, pass rate."""
        lines = [f"{'family':<18} {'captions':>8} {'passed':>7} {'rate':>7}"]
        for family in sorted(self.counts, key=lambda f: list(PROBES).index(f) if f in PROBES else 99):
            p, t = self.counts[family]
            lines.append(f"{family:<18} {t:>8d} {p:>7d} {100.0 * p / t:>6.1f}%")
        lines.append(f"{'all':<18} {self.total:>8d} {self.passed:>7d} {100.0 * self.rate:>6.1f}%")
        return "\n".join(lines)

    def to_json(self) -> dict[str, Any]:
        return {
            "split": self.split,
            "passed": self.passed,
            "total": self.total,
            "rate": self.rate,
            "families": {f: {"passed": p, "total": t} for f, (p, t) in self.counts.items()},
            "failures": [
                {
                    "clip": c.clip_id,
                    "caption": c.caption,
                    "family": c.family,
                    "claims": c.claims,
                    "checks": [vars(k) for k in r.failures()],
                }
                for c, r in self.failures
            ],
        }


def clip_features(data_dir: str | Path, clip_id: str) -> np.ndarray:
    """The features (T, 263) of corpus clip ``clip_id`` (``new_joint_vecs``); one-line errors."""
    path = Path(data_dir) / "new_joint_vecs" / f"{clip_id}.npy"
    if not path.is_file():
        raise InputFileError(f"clip '{clip_id}' has no features file {path}")
    try:
        return np.load(path, allow_pickle=False)
    except Exception as exc:  # noqa: BLE001 - a corrupt file is a user error
        raise InputFileError(f"cannot read {path}: {type(exc).__name__}") from None


def ground_truth(data_dir: str | Path) -> Callable[[ProbeCase], Motion]:
    """Motion source for :func:`evaluate`: the corpus' own features (``new_joint_vecs``)."""

    def load(case: ProbeCase) -> Motion:
        return Motion.from_features(clip_features(data_dir, case.clip_id))

    return load


def evaluate(
    cases: list[ProbeCase],
    motion_for: Callable[[ProbeCase], Motion | np.ndarray],
    split: str = "test",
    per_clip: bool = False,
    progress: bool = False,
) -> ProbeReport:
    """Probe every case with the motion ``motion_for(case)`` returns.

    Args:
        cases: from :func:`list_cases`.
        motion_for: case -> Motion or joints: the ground truth (:func:`ground_truth`), or a
            model's generation from ``case.caption`` with ``case.frames`` frames.
        split: recorded in the report.
        per_clip: call ``motion_for`` once per clip (ground truth) instead of per caption.
        progress: tqdm progress bar.
    """
    report = ProbeReport(split=split)
    last_id: str | None = None
    motion: Motion | np.ndarray | None = None
    for case in tqdm(cases, desc="probes", unit="caption", disable=not progress):
        if motion is None or not per_clip or case.clip_id != last_id:
            motion, last_id = motion_for(case), case.clip_id
        report.add(case, check(case, motion))
    return report
