"""Body-part timeline control (ControlMM paper, appendix A.9): whole body first, then track by track.

1. **Base pass**: generate the whole body for the whole timeline from ``timeline.base`` (default: the
   first track's prompt), with any extra loss terms (obstacles...).
2. **One pass per track**, in order: regenerate the motion from the track's prompt with everything
   the track does not own held as dense spatial control (:mod:`controlmm.timeline.signals`): the other
   joints over its span and every joint outside it, at what earlier passes fixed (the *reference*).
   Logits and codebook editing (the preset) meet the control; the span edges are blended. The track's
   part over its span then joins the reference.
3. The result is the last pass's motion (decoded as one piece, so its features match its joints).

Without an explicit ``base``, a first track that spans the whole timeline is made by the base pass
itself (its prompt drove the whole body there), so it is not regenerated.

The report says, per pass, how far the held entries moved (cm), whether the editors converged and
how many steps they took; per track, the fastest joint at its span edges (m/s), how far the entries it
fixed are in the final motion from what it fixed (cm), and, when the track names a probe, whether its
span passes it.
"""

from __future__ import annotations

import secrets
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from controlmm.editing.presets import EditingConfig, editing_preset
from controlmm.editing.terms import LossTerm
from controlmm.errors import ControlMMError
from controlmm.frames import HumanToWorld
from controlmm.motion.container import Motion
from controlmm.motion.skeleton import FPS, NUM_JOINTS
from controlmm.timeline.parts import moves_root
from controlmm.timeline.signals import boundary_speed, build_signal, held_drift, signal_terms
from controlmm.timeline.spec import Timeline

BASE = -1  # owner id of entries fixed by the base pass


def as_timeline(timeline: Timeline | dict | str | Path) -> Timeline:
    """A :class:`Timeline` from itself, its JSON dict or a JSON file path."""
    if isinstance(timeline, Timeline):
        return timeline
    if isinstance(timeline, dict):
        return Timeline.from_dict(timeline)
    if isinstance(timeline, (str, Path)):
        return Timeline.load(timeline)
    raise ControlMMError(f"a timeline must be a Timeline, a dict or a JSON path; got {type(timeline).__name__}")


def generate_timeline(model, timeline: Timeline | dict | str | Path, *, seed: int | None = None,
                      preset: str | EditingConfig = "accurate", terms: Sequence[LossTerm] = (),
                      transform: HumanToWorld | None = None, blend_frames: int = 10, blend_rate: float = 0.05,
                      progress: bool = False) -> tuple[Motion, dict[str, Any]]:
    """Generate a motion whose body parts follow their tracks' prompts over their spans.

    Args:
        model: a loaded :class:`~controlmm.models.model_dir.MotionModel`.
        timeline: a :class:`Timeline`, its JSON dict, or the path of a JSON spec.
        seed: reproducibility (None: random, recorded); pass ``k`` uses ``seed + k``.
        preset: editing preset of every pass (``fast``, ``medium``, ``accurate``) or an EditingConfig.
        terms: extra loss terms on the joints (B, T, 22, 3), human frame (obstacle SDF losses...),
            minimised in every pass.
        transform: placement of the human in the world (passed to the generator).
        blend_frames: frames blended at each interior span edge.
        blend_rate: how fast (m per frame) a regenerated part may leave the held motion at an edge.

    Returns:
        (motion, report): the motion (T, 22, 3) with ``metadata["timeline"]`` (spec and report) and
        extras ``timeline_owner`` (T, 22) int8 (track that fixed each entry, -1 = base pass) and
        ``timeline_drift`` (T, 22) float32 metres; the report as a JSON-serialisable dict.
    """
    from tqdm import tqdm

    from controlmm.generate.controlled import generate_controlled

    timeline = as_timeline(timeline)
    config = editing_preset(preset)
    if blend_frames < 0 or blend_rate < 0:
        raise ControlMMError(f"blend_frames and blend_rate must be >= 0; got {blend_frames}, {blend_rate}")
    if seed is None:
        seed = secrets.randbits(31)
    seed = int(seed)
    num_frames = timeline.num_frames
    tracks = timeline.tracks
    first = 1 if timeline.base is None and tracks[0].frames(num_frames) == (0, num_frames) else 0
    bar = tqdm(total=1 + len(tracks) - first, desc="timeline", unit="pass", disable=not progress, leave=False)
    started = time.perf_counter()

    out = generate_controlled(model, timeline.base_prompt, frames=num_frames, terms=terms, preset=config,
                              seed=seed, transform=transform)
    bar.update(1)
    motion = out.motion
    passes = [_pass_record(None, timeline.base_prompt, "whole_body", (0, num_frames), out.records[0], 0.0, 0)]
    reference = motion.joints.copy()
    owner = np.full((num_frames, NUM_JOINTS), BASE, dtype=np.int8)
    if first:
        owner[:] = 0
    drift = np.zeros((num_frames, NUM_JOINTS), dtype=np.float64)
    for k in range(first, len(tracks)):
        track = tracks[k]
        span = track.frames(num_frames)
        signal = build_signal(num_frames, track.joints, span, root_moves=moves_root(track.part),
                              tolerance=0.8 * config.tolerance, blend_frames=blend_frames, blend_rate=blend_rate)
        out = generate_controlled(model, track.prompt, targets=reference, mask=signal.mask, frames=num_frames,
                                  terms=list(terms) + signal_terms(signal, reference), preset=config,
                                  seed=seed + k + 1, transform=transform)
        motion = out.motion
        joints = motion.joints
        drift = held_drift(joints, reference, signal)
        passes.append(_pass_record(k, track.prompt, track.part, span, out.records[0], float(drift.max()),
                                   int(signal.held.sum())))
        moved = signal.held & ~signal.mask  # held relative to the body: their world position moved with it
        reference[moved] = joints[moved]
        reference[signal.free] = joints[signal.free]
        owner[signal.free] = k
        bar.update(1)
    bar.close()
    report = _report(timeline, motion.joints, owner, drift, passes, seed, config, time.perf_counter() - started)
    text = "; ".join(f"{t.part} {t.start:g}-{t.end:g} s: {t.prompt}" for t in tracks)
    metadata = dict(motion.metadata)
    metadata.pop("control", None)
    metadata.update({"seed": seed, "timeline": {"spec": timeline.to_dict(), "report": report}})
    result = Motion(joints=motion.joints, fps=float(FPS), features=motion.features, text=text, metadata=metadata,
                    extras={"timeline_owner": owner, "timeline_drift": drift.astype(np.float32)})
    return result, report


def _pass_record(track: int | None, prompt: str, part: str, span: tuple[int, int], record, drift: float,
                 held: int) -> dict[str, Any]:
    return {"track": track, "prompt": prompt, "part": part, "frames": list(span), "held_entries": held,
            "drift_cm": round(100 * drift, 3), "converged": bool(record.converged),
            "editing_steps": int(record.total_steps), "losses": {k: float(v) for k, v in record.losses.items()},
            "seconds": round(float(record.seconds), 3)}


def _report(timeline: Timeline, joints: np.ndarray, owner: np.ndarray, drift: np.ndarray, passes: list[dict],
            seed: int, config: EditingConfig, seconds: float) -> dict[str, Any]:
    from controlmm.eval.probes import probe

    num_frames = timeline.num_frames
    tracks = []
    for k, track in enumerate(timeline.tracks):
        s, e = track.frames(num_frames)
        edges = {name: round(boundary_speed(joints, f), 4) for name, f in (("start", s), ("end", e))
                 if 0 < f < num_frames}
        mine = owner == k
        entry: dict[str, Any] = {"track": k, "part": track.part, "prompt": track.prompt, "frames": [s, e],
                                 "owned_entries": int(mine.sum()),
                                 "final_drift_cm": round(100 * float(drift[mine].max()), 3) if mine.any() else 0.0,
                                 "boundary_speed_mps": edges}
        if track.probe is not None:
            result = probe(joints[s:e], track.probe["family"], track.probe.get("claims", {}))
            entry["probe"] = {"family": track.probe["family"], "passed": result.passed, "checks": result.describe()}
        tracks.append(entry)
    speeds = [v for t in tracks for v in t["boundary_speed_mps"].values()]
    probed = [t["probe"]["passed"] for t in tracks if "probe" in t]
    return {"frames": num_frames, "seconds": timeline.seconds, "seed": seed, "preset": config.name,
            "passes": passes, "tracks": tracks,
            "max_drift_cm": round(100 * float(drift.max()), 3),
            "max_boundary_speed_mps": round(max(speeds), 4) if speeds else 0.0,
            "probes_passed": [int(sum(probed)), len(probed)],
            "wall_seconds": round(seconds, 2)}
