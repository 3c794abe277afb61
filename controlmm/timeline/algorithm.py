"""Body-part timeline control (ControlMM paper, appendix A.9): whole body first, then track by track.

1. **Base pass**: generate the whole body for the whole timeline from ``timeline.base`` (default: the
   first track's prompt); with extra loss terms (obstacles...), codebook editing meets them.
2. **One pass per track**, in order. The track's prompt is generated alone over its span (at least
   2 s): its part's motion, relative to what the part hangs from (spine3 for arms and head) or, for
   the legs, to the pelvis and facing at the span start, becomes a soft target. Codebook editing,
   started from the current motion's own decoder latent, then moves the track's part toward that
   target while holding everything the track does not own as dense spatial control
   (:mod:`controlmm.timeline.signals`): the other joints over its span and every joint outside it, at
   what earlier passes fixed (the *reference*); the part blends into the held motion at the span
   edges. The track's part over its span then joins the reference.
3. The result is the last pass's motion, decoded as one piece (its features match its joints).

Why editing starts from the held motion: editing a motion generated afresh from the track's prompt
toward thousands of held entries converged slowly with first-order steps (on the dev model, the
controlled generator left held joints up to 10 cm off after 600 AdamW codebook-editing steps, 5 cm
after 2400); from the held motion the editors only have to keep them. Each pass edits in two runs:

* run 1: held (weight 20) + blend + prompt target (``prompt_weight`` 0.3) + the caller's terms, up to
  the preset's ``codebook_steps``;
* run 2, up to ``settle_steps`` (default 2x ``codebook_steps``) per try: held + blend + the caller's
  terms + a *keep* term holding the part near where run 1 took it (the prompt target's margins, then
  10 cm looser, then no keep term), stopping as soon as every held entry is within the tolerance. So
  the held entries get the last word without the part falling back to the held motion's pose.

Without an explicit ``base``, a first track spanning the whole timeline is made by the base pass
itself (its prompt drove the whole body there), so it is not regenerated.

The report says, per pass, how far the held entries moved (cm), whether editing converged and how many
steps it took; per track, the fastest joint at its span edges (m/s), how far the entries it fixed are in
the final motion from what it fixed (cm), and, when the track names a probe, whether its span passes.
"""

from __future__ import annotations

import secrets
import time
from collections.abc import Sequence
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
import torch
from tqdm import tqdm

from controlmm.control.terms import LossTerm
from controlmm.corpus.probes import probe
from controlmm.editing.objective import Objective
from controlmm.editing.presets import EditingConfig, editing_preset
from controlmm.errors import ControlMMError
from controlmm.frames import HumanToWorld
from controlmm.generate.api import generate
from controlmm.generate.controlled import decode_latent, edit_latent
from controlmm.models.model_dir import MotionModel
from controlmm.motion.container import Motion
from controlmm.motion.skeleton import FPS, MIN_FRAMES, NUM_JOINTS
from controlmm.timeline.parts import ATTACHMENT, moves_root
from controlmm.timeline.signals import (
    boundary_speed,
    build_signal,
    held_drift,
    hinge_term,
    prompt_entries,
    reference_targets,
    signal_terms,
)
from controlmm.timeline.spec import Timeline

BASE = -1  # owner id of entries fixed by the base pass
KEEP_SLACK = (0.0, 0.1)  # m: extra margins of the keep term in the second editing run's successive tries


def as_timeline(timeline: Timeline | dict | str | Path) -> Timeline:
    """A :class:`Timeline` from itself, its JSON dict or a JSON file path."""
    if isinstance(timeline, Timeline):
        return timeline
    if isinstance(timeline, dict):
        return Timeline.from_dict(timeline)
    if isinstance(timeline, (str, Path)):
        return Timeline.load(timeline)
    raise ControlMMError(
        f"a timeline must be a Timeline, a dict or a JSON path; got {type(timeline).__name__}"
    )


def generate_timeline(
    model: MotionModel,
    timeline: Timeline | dict | str | Path,
    *,
    seed: int | None = None,
    preset: str | EditingConfig = "accurate",
    terms: Sequence[LossTerm] = (),
    transform: HumanToWorld | None = None,
    blend_frames: int = 10,
    blend_rate: float = 0.05,
    prompt_weight: float = 0.3,
    settle_steps: int | None = None,
    progress: bool = False,
) -> tuple[Motion, dict[str, Any]]:
    """Generate a motion whose body parts follow their tracks' prompts over their spans.

    Args:
        model: a loaded :class:`~controlmm.models.model_dir.MotionModel`.
        timeline: a :class:`Timeline`, its JSON dict, or the path of a JSON spec.
        seed: reproducibility (None: random, recorded); pass ``k`` uses ``seed + k``.
        preset: editing preset (``fast``, ``medium``, ``accurate``) or an EditingConfig; its
            ``codebook_steps`` (at most; editing stops once every held entry is within ``tolerance``)
            and optimiser settings are used in every pass.
        terms: extra loss terms on the joints (B, T, 22, 3), human frame (obstacle SDF losses...),
            minimised in every pass.
        transform: placement of the human in the world (kept in the metadata; terms carry their own).
        blend_frames: frames blended at each interior span edge.
        blend_rate: how fast (m per frame) a regenerated part may leave the held motion at an edge.
        prompt_weight: weight of the soft target a track's part gets from its prompt's own motion.
        settle_steps: step budget of each pass's second editing run (held entries, blend and ``terms``
            only; it stops once they are met). Default: 2x the preset's ``codebook_steps``.

    Returns:
        (motion, report): the motion (T, 22, 3) with ``metadata["timeline"]`` (spec and report) and
        extras ``timeline_owner`` (T, 22) int8 (track that fixed each entry, -1 = base pass) and
        ``timeline_drift`` (T, 22) float32 metres; the report as a JSON-serialisable dict.
    """
    timeline = as_timeline(timeline)
    config = editing_preset(preset)
    if blend_frames < 0 or blend_rate < 0 or prompt_weight < 0:
        raise ControlMMError(
            f"blend_frames, blend_rate and prompt_weight must be >= 0; "
            f"got {blend_frames}, {blend_rate}, {prompt_weight}"
        )
    seed = secrets.randbits(31) if seed is None else int(seed)
    if settle_steps is not None and (
        isinstance(settle_steps, bool) or int(settle_steps) != settle_steps or settle_steps < 0
    ):
        raise ControlMMError(f"settle_steps must be a whole number >= 0; got {settle_steps!r}")
    settle = replace(
        config, codebook_steps=2 * config.codebook_steps if settle_steps is None else int(settle_steps)
    )
    num_frames = timeline.num_frames
    tracks = timeline.tracks
    first = 1 if timeline.base is None and tracks[0].frames(num_frames) == (0, num_frames) else 0
    bar = tqdm(total=1 + len(tracks) - first, desc="timeline", unit="pass", disable=not progress, leave=False)
    started = time.perf_counter()

    clock = time.perf_counter()
    latent = _generate_latent(model, timeline.base_prompt, num_frames, seed)
    latent, record = edit_latent(
        model,
        latent,
        num_frames,
        Objective(terms=tuple(terms), tolerance=config.tolerance, loss_tolerance=config.loss_tolerance),
        config,
    )
    joints, features = decode_latent(model, latent, num_frames)
    passes = [
        _pass_record(
            None,
            timeline.base_prompt,
            "whole_body",
            (0, num_frames),
            record,
            0.0,
            0,
            time.perf_counter() - clock,
        )
    ]
    bar.update(1)
    reference = joints.copy()
    owner = np.full((num_frames, NUM_JOINTS), BASE, dtype=np.int8)
    if first:
        owner[:] = 0
    drift = np.zeros((num_frames, NUM_JOINTS), dtype=np.float64)
    for k in range(first, len(tracks)):
        clock = time.perf_counter()
        track = tracks[k]
        span = track.frames(num_frames)
        root = moves_root(track.part)
        tol = 0.8 * config.tolerance
        signal = build_signal(
            num_frames,
            track.joints,
            span,
            root_moves=root,
            tolerance=tol,
            blend_frames=blend_frames,
            blend_rate=blend_rate,
        )
        clip_frames = max(span[1] - span[0], MIN_FRAMES)
        clip, _ = decode_latent(
            model, _generate_latent(model, track.prompt, clip_frames, seed + k + 1), clip_frames
        )
        prompt = (
            prompt_entries(
                signal,
                track.joints,
                root_moves=root,
                attachment=ATTACHMENT[track.part],
                blend_frames=blend_frames,
                blend_rate=blend_rate,
            )
            if prompt_weight > 0
            else None
        )
        pass_terms = signal_terms(
            signal, reference, clip, prompt, tolerance=tol, prompt_weight=prompt_weight, prompt_shift=span[0]
        )
        objective = Objective(
            targets=torch.as_tensor(reference)[None],
            mask=torch.as_tensor(signal.mask)[None],
            terms=tuple(terms) + tuple(pass_terms),
            tolerance=config.tolerance,
            loss_tolerance=config.loss_tolerance,
        )
        latent, first_record = edit_latent(model, latent, num_frames, objective, config)
        # the held entries, the blend and the caller's terms get the last word (the prompt target is soft);
        # the part may not leave where the first run took it by more than the prompt target's margins
        hard = replace(objective, terms=tuple(t for t in objective.terms if t.name != "timeline:prompt"))
        keeps: list[tuple[LossTerm, ...]] = [()]
        if prompt is not None:
            moved_to, _ = decode_latent(model, latent, num_frames)
            targets = reference_targets(moved_to, prompt)
            keeps = [
                (
                    hinge_term(
                        "timeline:keep",
                        targets,
                        replace(prompt, margins=prompt.margins + extra),
                        prompt_weight,
                    ),
                )
                for extra in KEEP_SLACK
            ] + [()]
        steps = first_record["steps"]
        for keep in keeps:  # looser and looser, until the held entries are met
            latent, record = edit_latent(
                model, latent, num_frames, replace(hard, terms=tuple(hard.terms) + keep), settle
            )
            steps += record["steps"]
            if record["converged"]:
                break
        record["steps"] = steps
        record["losses"]["timeline:prompt"] = first_record["losses"].get("timeline:prompt", 0.0)
        joints, features = decode_latent(model, latent, num_frames)
        drift = held_drift(joints, reference, signal)
        passes.append(
            _pass_record(
                k,
                track.prompt,
                track.part,
                span,
                record,
                float(drift.max()),
                int(signal.held.sum()),
                time.perf_counter() - clock,
            )
        )
        moved = signal.held & ~signal.mask  # held relative to the body: their world position moved with it
        reference[moved] = joints[moved]
        reference[signal.free] = joints[signal.free]
        owner[signal.free] = k
        bar.update(1)
    bar.close()
    report = _report(timeline, joints, owner, drift, passes, seed, config, time.perf_counter() - started)
    text = "; ".join(f"{t.part} {t.start:g}-{t.end:g} s: {t.prompt}" for t in tracks)
    metadata = {
        "seed": seed,
        "model": str(getattr(model, "directory", "") or ""),
        "transform": None if transform is None else repr(transform),
        "timeline": {"spec": timeline.to_dict(), "report": report},
    }
    motion = Motion(
        joints=joints,
        fps=float(FPS),
        features=features,
        text=text,
        metadata=metadata,
        extras={"timeline_owner": owner, "timeline_drift": drift.astype(np.float32)},
    )
    return motion, report


# -- the pieces of a pass ---------------------------------------------------------------------------
def _generate_latent(model: MotionModel, prompt: str, frames: int, seed: int) -> torch.Tensor:
    """Decoder latent (1, N, code_dim) of the prompt generated alone (MoMask: base + residual layers)."""
    latent = generate(model, prompt, frames=frames, seed=seed).latent
    if latent is None:  # generate always fills it
        raise RuntimeError("generate returned no decoder latent")
    return latent.detach()


def _pass_record(
    track: int | None,
    prompt: str,
    part: str,
    span: tuple[int, int],
    record: dict,
    drift: float,
    held: int,
    seconds: float,
) -> dict[str, Any]:
    return {
        "track": track,
        "prompt": prompt,
        "part": part,
        "frames": list(span),
        "held_entries": held,
        "drift_cm": round(100 * drift, 3),
        "converged": record["converged"],
        "editing_steps": record["steps"],
        "losses": record["losses"],
        "seconds": round(seconds, 3),
    }


def _report(
    timeline: Timeline,
    joints: np.ndarray,
    owner: np.ndarray,
    drift: np.ndarray,
    passes: list[dict],
    seed: int,
    config: EditingConfig,
    seconds: float,
) -> dict[str, Any]:
    num_frames = timeline.num_frames
    tracks = []
    for k, track in enumerate(timeline.tracks):
        s, e = track.frames(num_frames)
        edges = {
            name: round(boundary_speed(joints, f), 4)
            for name, f in (("start", s), ("end", e))
            if 0 < f < num_frames
        }
        mine = owner == k
        entry: dict[str, Any] = {
            "track": k,
            "part": track.part,
            "prompt": track.prompt,
            "frames": [s, e],
            "owned_entries": int(mine.sum()),
            "final_drift_cm": round(100 * float(drift[mine].max()), 3) if mine.any() else 0.0,
            "boundary_speed_mps": edges,
        }
        if track.probe is not None:
            result = probe(joints[s:e], track.probe["family"], track.probe.get("claims", {}))
            entry["probe"] = {
                "family": track.probe["family"],
                "passed": result.passed,
                "checks": result.describe(),
            }
        tracks.append(entry)
    speeds = [v for t in tracks for v in t["boundary_speed_mps"].values()]
    probed = [t["probe"]["passed"] for t in tracks if "probe" in t]
    return {
        "frames": num_frames,
        "seconds": timeline.seconds,
        "seed": seed,
        "preset": config.name,
        "passes": passes,
        "tracks": tracks,
        "max_drift_cm": round(100 * float(drift.max()), 3),
        "max_boundary_speed_mps": round(max(speeds), 4) if speeds else 0.0,
        "probes_passed": [int(sum(probed)), len(probed)],
        "wall_seconds": round(seconds, 2),
    }
