"""The plan loop: text + constraints + scene -> motion -> robot -> check -> feedback -> ... -> result.

```python
from controlmm.pipeline import PlanConfig, plan, write_plan

result = plan(PlanConfig(scene="table", rounds=3, seed=0))
result.passed, result.report.summary()
write_plan(result, "out/plan")            # motion.npz, robot.csv/npz/json, report.json, render.mp4, plots/
```

Round 0 generates the tokens (masked decoding with the motion control model and logits editing)
and codebook-edits their latent against the control spec and the scene's obstacle and floor losses.
Every later round adds the feedback terms of the failures found so far
(:mod:`controlmm.pipeline.feedback`) and codebook-edits the previous round's latent again
(:mod:`controlmm.pipeline.refine`), so the motion changes only where the losses ask it to. The loop
stops at the first round that passes with every constraint within 2 cm (one more editing round when a
passing round misses a constraint) or after ``rounds`` feedback rounds; the result is the best round:
passing first, then meeting the constraints, then the fewest failing frames.

With ``PlanConfig(motion=FILE)`` round 0 edits a recorded clip instead of generating: its tokens
are codebook-edited against the same losses plus a closeness term (:mod:`controlmm.pipeline.clip`),
and every round reports how far the joints moved from the clip.
"""

from __future__ import annotations

import functools
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from typing import Any, TextIO

import torch

from controlmm.control.spec import ControlSpec
from controlmm.control.terms import LossTerm
from controlmm.editing.presets import EditingConfig, editing_preset
from controlmm.errors import ControlMMError
from controlmm.frames import HumanToWorld
from controlmm.generate import MotionModel, generate_controlled, load_model
from controlmm.motion.container import Motion
from controlmm.pipeline.clip import ClipEditor, Displacement, closeness_term, displacement, load_clip
from controlmm.pipeline.config import PlanConfig
from controlmm.pipeline.feedback import feedback_terms
from controlmm.pipeline.inputs import constraint_warnings, plan_seconds, start_pose_error
from controlmm.pipeline.refine import edit_motion
from controlmm.pipeline.retarget_checked import with_fallbacks
from controlmm.pipeline.timing import StageTimes
from controlmm.timeline import as_timeline, generate_timeline
from retarget import RobotTrajectory, load_robot, retarget_motion, robot_scale
from scenes import Scene, load_scene, scene_loss_terms
from sim import CheckWorld, Report, check_trajectory, make_world
from sim.physics import check_start

CONSTRAINT_TOLERANCE_M = 0.02
"""A round meets its constraints when every one is within this (2 cm)."""
_DEFAULT_CONFIG = PlanConfig()
"""What :func:`plan` plans when given no config: the defaults of :class:`PlanConfig` (frozen)."""


@dataclass
class PlanRound:
    """One generate -> retarget -> check pass."""

    index: int
    motion: Motion
    trajectory: RobotTrajectory
    report: Report
    terms: list[str]  # names of the loss terms this round was generated with
    constraint_errors_m: list[float]
    editing: dict[str, Any]
    seconds: dict[str, float]  # generate, retarget, check, and generate's stages (text, decoding, ...)
    fallback: str | None = None  # the retargeting fallback kept (controlmm.pipeline.retarget_checked)

    @property
    def passed(self) -> bool:
        return bool(self.report.passed)

    @property
    def constraints_met(self) -> bool:
        return all(e <= CONSTRAINT_TOLERANCE_M for e in self.constraint_errors_m)

    def failing_frames(self) -> int:
        return sum(f.num_frames for f in self.report.errors)

    def to_dict(self) -> dict[str, Any]:
        r = self.report
        kinds: dict[str, int] = {}
        for f in r.errors:
            kinds[f.kind] = kinds.get(f.kind, 0) + 1
        return {
            "round": self.index,
            "passed": self.passed,
            "constraints_met": self.constraints_met,
            "failures": len(r.failures),
            "failure_kinds": kinds,
            "max_penetration_m": round(float(r.max_penetration_m), 6),
            "floor_penetration_m": round(float(r.floor_penetration_m), 6),
            "self_collision_frames": int(r.self_collision_frames),
            "foot_sliding_m": round(float(r.foot_sliding_m), 6),
            "constraint_errors_m": [round(e, 5) for e in self.constraint_errors_m],
            "retarget_fallback": self.fallback,
            "physics": _physics_figures(r.stats.get("physics")),
            "loss_terms": list(self.terms),
            "editing": self.editing,
            "seconds": {k: round(v, 3) for k, v in self.seconds.items()},
        }


@dataclass
class PlanResult:
    """Every round and the chosen one (``best``)."""

    config: PlanConfig
    scene: Scene
    text: str
    spec: ControlSpec | None
    transform: HumanToWorld
    rounds: list[PlanRound]
    best: int
    warnings: list[str] = field(default_factory=list)
    seconds: float = 0.0
    clip: Motion | None = None  # the recorded clip a --motion plan edited
    reconstructed: Displacement | None = None  # the clip's tokens alone against the clip
    timing: StageTimes = field(default_factory=StageTimes)

    @property
    def final(self) -> PlanRound:
        return self.rounds[self.best]

    @property
    def passed(self) -> bool:
        return self.final.passed

    @property
    def motion(self) -> Motion:
        return self.final.motion

    @property
    def trajectory(self) -> RobotTrajectory:
        return self.final.trajectory

    @property
    def report(self) -> Report:
        return self.final.report

    def displacements(self) -> list[tuple[int, Displacement]]:
        """(round, joint displacement from the clip) of every round; empty without a clip."""
        if self.clip is None:
            return []
        return [(r.index, displacement(r.motion.joints, self.clip.joints)) for r in self.rounds]

    def to_dict(self) -> dict[str, Any]:
        """``report.json``: the chosen round's simulation report plus the plan and every round."""
        out = self.final.report.to_dict()
        out["plan"] = {
            "scene": self.scene.name,
            "robot": self.config.robot,
            "text": self.text,
            "control": self.spec.to_dict() if self.spec is not None else None,
            "seed": self.config.seed,
            "preset": self.config.preset,
            "rounds_allowed": self.config.rounds,
            "rounds_run": len(self.rounds),
            "chosen_round": self.best,
            "passed_before_feedback": self.rounds[0].passed,
            "warnings": list(self.warnings),
            "transform": {
                "scale": self.transform.scale,
                "yaw": self.transform.yaw,
                "translation": list(self.transform.translation),
            },
            "seconds": round(self.seconds, 3),
        }
        out["rounds"] = [r.to_dict() for r in self.rounds]
        out["timing"] = self.timing.to_dict()
        if self.clip is not None:
            moved = dict(self.displacements())
            out["clip"] = {
                "source": self.config.motion,
                "import": self.clip.metadata.get("import"),
                "frames": self.clip.num_frames,
                "closeness_weight": self.config.closeness_weight,
                "tokens_only": self.reconstructed.to_dict(per_frame=False) if self.reconstructed else None,
                "displacement": moved[self.best].to_dict(),
            }
            for r in out["rounds"]:
                r["clip_displacement"] = moved[r["round"]].to_dict(per_frame=False)
        return out


def resolve_inputs(config: PlanConfig) -> tuple[Scene, str, ControlSpec | None, HumanToWorld]:
    """Scene, prompt, control spec and the human -> world placement of a config (or one-line errors)."""
    load_robot(config.robot)  # an unknown robot fails here, with the list of packaged ones
    scene = load_scene(config.scene, robot=config.robot)
    transform = scene.human_to_world(robot_scale(config.robot))
    spec: ControlSpec | None = None
    if isinstance(config.control, dict):
        spec = ControlSpec.from_dict(config.control)
    elif config.control is not None:
        spec = ControlSpec.load(config.control)
    elif (
        config.text is None and config.timeline is None and config.motion is None and scene.suggested_control
    ):
        spec = ControlSpec.from_dict(scene.suggested_control)
    text = config.text if config.text is not None else scene.suggested_prompt
    if config.motion is not None and config.text is None:
        text = f"recorded clip {config.motion}"
    if config.timeline is not None:
        timeline = as_timeline(config.timeline)  # a bad spec fails here, before any model is loaded
        text = "; ".join(f"{t.part} {t.start:g}-{t.end:g} s: {t.prompt}" for t in timeline.tracks)
    if not text:
        raise ControlMMError(f"scene '{scene.name}' suggests no prompt; give one with --text")
    return scene, text, spec, transform


def plan(
    config: PlanConfig = _DEFAULT_CONFIG,
    *,
    model: MotionModel | None = None,
    progress: bool = True,
    log: TextIO | None = None,
) -> PlanResult:
    """Plan a robot motion in a scene (see the module docstring).

    Args:
        config: what to plan (default ``PlanConfig()``: the bundled example).
        model: a loaded :class:`controlmm.models.MotionModel` (default: load ``config.model``).
        progress: progress bars and one line per stage on stderr.
        log: where stage lines go (default stderr); None with ``progress=False`` silences them.

    ``result.timing`` holds the wall seconds of every stage (:mod:`controlmm.pipeline.timing`).
    """
    start = time.perf_counter()
    timing = StageTimes(origin=start)
    say = _logger(progress, log)
    scene, text, spec, transform = resolve_inputs(config)
    clip = (
        load_clip(config.motion, config.motion_import, config.motion_start, config.seconds)
        if config.motion is not None
        else None
    )
    error = start_pose_error(scene)
    if error:
        raise ControlMMError(error)
    sdf = scene.sdf() if scene.obstacle_geom_ids else None
    warnings = constraint_warnings(spec, transform, sdf) if spec else []
    if clip is not None and clip.metadata.get("window_note"):
        warnings.insert(0, str(clip.metadata["window_note"]))
    for w in warnings:
        print(f"controlmm: warning: {w}", file=sys.stderr)
    if model is None:
        say("loading the model")
        model = load_model(config.model)
    body_joints: dict[str, Sequence[str]] = dict(load_robot(config.robot).body_joints)
    base_terms = scene_loss_terms(scene, transform, safe_distance=config.safe_distance_m)
    editor = ClipEditor(model, clip) if clip is not None else None
    if clip is not None:
        base_terms.append(closeness_term(clip.joints, weight=config.closeness_weight))
    world = make_world(scene)
    editing = editing_preset(config.preset)
    extra: list[LossTerm] = []
    history: dict = {}  # feedback margins per robot body, across rounds
    rounds: list[PlanRound] = []
    latent: torch.Tensor | None = None  # the edited decoder latent of the last round (not with a timeline)
    timing.add("startup", time.perf_counter() - start)
    for index in range(config.rounds + 1):
        terms = base_terms + extra
        timer: dict[str, float] = {}
        t0 = time.perf_counter()
        if config.timeline is not None:  # a timeline is regenerated whole, its passes minimising every term
            say(f"round {index}: generating the timeline ({len(terms)} loss terms, preset {editing.name})")
            motion, errors, record = _timeline(model, config.timeline, config.seed, terms, transform, editing)
            phases = {"timeline": time.perf_counter() - t0}
        elif editor is not None:
            what = "the clip's tokens" if index == 0 else f"the clip with {len(extra)} feedback terms"
            say(f"round {index}: codebook editing {what} ({len(terms)} loss terms, preset {editing.name})")
            start_latent = editor.latent if index == 0 else latent
            assert start_latent is not None  # round 0 set it
            edited = editor.edit(
                start_latent, spec, transform, terms, editing, text, metadata=editor.clip.metadata
            )
            motion, errors, record, latent = edited.motion, edited.errors, edited.record, edited.latent
            phases = edited.seconds or {"codebook_editing": time.perf_counter() - t0}
        elif index == 0:
            say(f"round 0: generating ({len(terms)} loss terms, preset {editing.name})")
            motion, errors, record, latent, phases = _generate(
                model, config, text, spec, terms, transform, editing
            )
        else:
            say(f"round {index}: codebook editing with {len(extra)} feedback terms")
            assert latent is not None  # round 0 set it (rounds without a timeline)
            edited = edit_motion(
                model,
                latent,
                motion.num_frames,
                spec,
                transform,
                terms,
                editing,
                text,
                metadata=motion.metadata,
            )
            motion, errors, record, latent = edited.motion, edited.errors, edited.record, edited.latent
            phases = edited.seconds
        timer["generate"] = time.perf_counter() - t0
        timer.update(phases)
        t0 = time.perf_counter()
        # check_scale off: a wrongly sized motion is the generator's failure, which the checks report
        traj = retarget_motion(
            motion, robot=config.robot, fps=config.fps, transform=transform, check_scale=False
        )
        timer["retarget"] = time.perf_counter() - t0
        t0 = time.perf_counter()
        report = _check(world, traj, config, index, say, progress)
        # a torque or sliding failure: the retargeter's fallback settings first (the same motion)
        checked = with_fallbacks(
            motion,
            config.robot,
            traj,
            report,
            functools.partial(_check, world, config=config, index=index, say=_quiet, progress=progress),
            transform,
            check_scale=False,
        )
        traj, report = checked.trajectory, checked.report
        timer["check"] = time.perf_counter() - t0  # the fallbacks' retargeting and checks included
        rounds.append(
            PlanRound(
                index, motion, traj, report, [t.name for t in terms], errors, record, timer, checked.fallback
            )
        )
        if index == 0:
            timing.add_all(phases)
            timing.add("retarget", timer["retarget"])
            timing.add("checks", timer["check"])
        else:
            timing.add("feedback_rounds", timer["generate"] + timer["retarget"] + timer["check"])
        blocking = report.errors  # warnings (brief dynamic spikes) do not fail a round
        worst = f", worst constraint {max(errors) * 100:.1f} cm" if errors else ""
        if clip is not None:
            moved = displacement(motion.joints, clip.joints)
            worst += f", joints {moved.mean_m * 100:.1f} cm from the clip (max {moved.max_m * 100:.1f})"
        verdict = "PASSED" if report.passed else f"FAILED ({len(blocking)} failures)"
        if checked.fallback is not None:
            verdict += f" with the retargeting fallback '{checked.fallback}'"
        took = timer["generate"] + timer["retarget"] + timer["check"]
        say(f"round {index}: {verdict}{worst} in {took:.1f} s")
        # Stop when it passes with every constraint met; a pass that misses a constraint gets one more
        # editing round (more codebook steps toward the targets), not more.
        settled = rounds[-1].constraints_met or (index > 0 and rounds[-2].passed)
        if (report.passed and settled) or index == config.rounds:
            break
        mark = time.perf_counter()
        extra = extra + feedback_terms(
            blocking,
            motion.joints,
            body_joints=body_joints,
            transform=transform,
            robot_fps=traj.fps,
            round_index=index,
            sdf=sdf,
            config=config.feedback,
            history=history,
        )
        timing.add("feedback_rounds", time.perf_counter() - mark)
    best = min(
        rounds,
        key=lambda r: (
            not r.passed,
            not r.constraints_met,
            r.failing_frames(),
            max(r.constraint_errors_m, default=0.0),
        ),
    ).index
    timing.stop()
    return PlanResult(
        config=config,
        scene=scene,
        text=text,
        spec=spec,
        transform=transform,
        rounds=rounds,
        best=best,
        warnings=warnings,
        seconds=time.perf_counter() - start,
        clip=clip,
        reconstructed=editor.tokens_only() if editor is not None else None,
        timing=timing,
    )


def _generate(
    model: MotionModel,
    config: PlanConfig,
    text: str,
    spec: ControlSpec | None,
    terms: list[LossTerm],
    transform: HumanToWorld,
    editing: EditingConfig,
) -> tuple[Motion, list[float], dict[str, Any], torch.Tensor, dict[str, float]]:
    """Round 0: tokens by masked decoding (control model + logits editing), then codebook editing.

    Returns (motion, constraint errors (m), editing record, edited latent (1, N, code_dim), wall seconds
    per stage: text, decoding, logits_editing, codebook_editing, foot_contact).
    """
    out = generate_controlled(
        model,
        text,
        control=spec,
        terms=terms,
        preset=replace(editing, codebook_steps=0),
        seconds=plan_seconds(config.seconds, spec),
        seed=config.seed,
        transform=transform,
        progress=False,
    )
    phases = dict(out.records[0].phases)
    mark = time.perf_counter()
    ids = out.ids[0].to(model.device)
    with torch.no_grad():
        latent = model.tokenizer.ids_to_latent(ids.reshape(1, ids.shape[0], -1))
    edited = edit_motion(
        model, latent, out.frames[0], spec, transform, terms, editing, text, metadata=out.motion.metadata
    )
    phases["decoding"] = (
        phases.get("decoding", 0.0) + time.perf_counter() - mark - sum(edited.seconds.values())
    )
    for stage, seconds in edited.seconds.items():
        phases[stage] = phases.get(stage, 0.0) + seconds
    record = {
        "logits_steps": out.records[0].logits_steps,
        "control_model": out.records[0].control_model,
        **edited.record,
    }
    return edited.motion, edited.errors, record, edited.latent, phases


def _timeline(
    model: MotionModel,
    timeline: str,
    seed: int,
    terms: list[LossTerm],
    transform: HumanToWorld,
    editing: EditingConfig,
) -> tuple[Motion, list[float], dict[str, Any]]:
    """A body-part timeline (``controlmm.timeline``, a JSON path) generated with the loss terms in
    every pass."""
    motion, info = generate_timeline(
        model,
        as_timeline(timeline),
        seed=seed,
        preset=editing,
        terms=terms,
        transform=transform,
    )
    summary = {k: info[k] for k in ("max_drift_cm", "max_boundary_speed_mps") if k in info}
    return motion, [], {"timeline": summary}


def _check(
    world: CheckWorld,
    traj: RobotTrajectory,
    config: PlanConfig,
    index: int,
    say: Callable[[str], None],
    progress: bool,
) -> Report:
    """A round's simulation checks; the physics execution last, unless the motion starts inside the
    scene (a generated motion is no bad input: its penetration fails the round and is fed back)."""
    check = config.check
    if check.physics:
        try:
            check_start(world, traj.qpos[0], config.physics)
            say(f"round {index}: executing the motion in physics ({traj.num_frames / traj.fps:.1f} s)")
        except ControlMMError as exc:
            say(f"round {index}: no physics execution: {exc}")
            check = replace(check, physics=False)
    return check_trajectory(world, traj, config=check, physics=config.physics, progress=progress)


def _physics_figures(physics: dict[str, Any] | None) -> dict[str, Any] | None:
    """A round's physics verdict and main figures (None without the physics check)."""
    if not physics:
        return None
    keys = ("passed", "fell", "time_up_s", "mean_root_error_m", "max_root_error_m", "max_torque_ratio")
    return {k: physics[k] for k in keys}


def _quiet(message: str) -> None:
    """The stage lines of a fallback's check, left unsaid."""


def _logger(progress: bool, log: TextIO | None) -> Callable[[str], None]:
    stream = log if log is not None else (sys.stderr if progress else None)

    def say(message: str) -> None:
        if stream is not None:
            print(f"controlmm plan: {message}", file=stream, flush=True)

    return say
