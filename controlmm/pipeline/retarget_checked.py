"""Retargeting checked in MuJoCo, with fallback solver settings where the check fails.

The retargeter (:func:`retarget.retarget_motion`) keeps a planted foot still, the joints in
their ranges and the links apart by construction, but whether the robot's motors can carry
the motion and its stance feet hold under the check's own contact model is only known once
the output is replayed (:func:`sim.check_trajectory`, what ``controlmm validate`` runs).
Where that check fails, another way of placing the feet or the legs often passes (on the
packaged robots: H1's and T1's weak ankles overloaded by a foot rolling over its toes, Apollo's
heavily damped hips and torso in a turn). :func:`retarget_checked` retargets with the given
settings, checks the output, and where it fails retargets again with each of
:data:`FALLBACKS` in turn; of the outputs that pass, the one closest to the human
(:func:`retarget.compare.similarity_fit`) is kept, if it is within ``fit_give`` of the first
output's fit. Otherwise the first output stays, with its failing report. Only failures that
the feet and legs decide (ankle torque, a sliding foot: :data:`RETRIED_KINDS`) are retried.

Only the settings change, never the motion: the plan's feedback rounds
(:mod:`controlmm.pipeline.feedback`) edit the motion itself.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field, replace
from typing import Any

from controlmm.errors import ControlMMError
from controlmm.frames import HumanToWorld
from controlmm.motion.container import Motion
from retarget import RobotTrajectory, SolverConfig, load_robot, retarget_motion
from retarget.compare import similarity_fit
from scenes import load_scene
from sim import CheckConfig, CheckWorld, Report, check_trajectory, make_world


@dataclass(frozen=True)
class Fallback:
    """A named set of :class:`retarget.SolverConfig` fields tried where the check fails."""

    name: str
    solver: dict[str, Any]


FALLBACKS = (
    Fallback("flat contact feet", {"foot_roll": 0.0}),
    Fallback("flat contact feet, lifted", {"foot_roll": 0.0, "foot_lift": 1.0}),
    Fallback("half-rolling feet", {"foot_roll": 0.5}),
    Fallback("half-rolling feet, lifted", {"foot_roll": 0.5, "foot_lift": 1.0}),
    Fallback("legs halfway to the robot's proportions", {"human_leg_share": 0.5}),
)
"""The fallbacks, in the order they are tried. On the six packaged robots and the 21 motions of
``benchmarks/retarget_peers.py --clips 20`` they turn 8 of the 14 outputs that failed the check
into passes (docs/BENCHMARKS.md, 2026-12-05)."""

RETRIED_KINDS = ("torque_limit", "foot_sliding")
"""The failure kinds a fallback may clear: the fallbacks are tried only where every blocking
failure of the first output is one of these. The others stay whatever the feet do: an obstacle
in the way (the retargeter does not see the scene's obstacles: the motion itself must change,
as the plan's feedback rounds do), two links the self-clearance could not keep apart, a motion
that leaves the floor for what the scene does not have (stairs in the empty scene), a
residual force. Nothing else changed in the six robots' 126 runs, and on a heavy model each
fallback costs a retargeting and a check (Valkyrie's real clip: 6.8 s, 62 s with five)."""

FIT_GIVE = 0.25
"""How much (a share of the first output's similarity fit) a passing fallback may fit the
human worse than the first output and still be kept."""


@dataclass(frozen=True)
class Attempt:
    """One retargeting and its check: ``name`` ("default" or a fallback's), whether it
    ``passed``, its blocking failure kinds and its similarity fit (m) to the human."""

    name: str
    passed: bool
    errors: tuple[str, ...]
    fit_m: float

    def to_dict(self) -> dict[str, object]:
        return {"name": self.name, "passed": self.passed, "errors": list(self.errors), "fit_m": self.fit_m}


@dataclass
class CheckedTrajectory:
    """What :func:`retarget_checked` kept: the ``trajectory``, its check ``report``, the
    ``fallback`` it came from (None: the given settings) and every ``attempts`` made."""

    trajectory: RobotTrajectory
    report: Report
    fallback: str | None
    attempts: list[Attempt] = field(default_factory=list)

    def to_dict(self) -> dict[str, object]:
        return {
            "passed": self.report.passed,
            "errors": sorted({f.kind for f in self.report.errors}),
            "fallback": self.fallback,
            "attempts": [a.to_dict() for a in self.attempts],
        }


def retarget_checked(
    motion: Motion,
    robot: str = "g1",
    fps: float = 50.0,
    transform: HumanToWorld | None = None,
    config: SolverConfig | None = None,
    scene: str | CheckWorld = "empty",
    check: CheckConfig | None = None,
    fallbacks: tuple[Fallback, ...] = FALLBACKS,
    fit_give: float = FIT_GIVE,
    solver: str = "batched",
    metrics: bool = True,
) -> CheckedTrajectory:
    """Retarget ``motion`` to ``robot`` (as :func:`retarget.retarget_motion`, which raises on
    bad input), check it in ``scene`` (a scene name or file, or a :class:`sim.CheckWorld` of
    that robot) with ``check`` (default :class:`sim.CheckConfig`), and where it fails try
    each of ``fallbacks`` over ``config`` (default: the robot's mapping's settings); see the
    module and :func:`with_fallbacks`. ``solver``, ``metrics``: as
    :func:`retarget.retarget_motion`'s."""
    _check_fit_give(fit_give)
    world = scene if isinstance(scene, CheckWorld) else make_world(load_scene(scene, robot=robot))
    base = config if config is not None else SolverConfig(**load_robot(robot).mapping.solver)
    traj = retarget_motion(
        motion, robot=robot, fps=fps, transform=transform, config=base, solver=solver, metrics=metrics
    )

    def check_output(out: RobotTrajectory) -> Report:
        return check_trajectory(world, out, config=check)

    return with_fallbacks(
        motion,
        robot,
        traj,
        check_output(traj),
        check_output,
        transform,
        base,
        fallbacks,
        fit_give,
        solver,
        metrics,
    )


def with_fallbacks(
    motion: Motion,
    robot: str,
    trajectory: RobotTrajectory,
    report: Report,
    check: Callable[[RobotTrajectory], Report],
    transform: HumanToWorld | None = None,
    config: SolverConfig | None = None,
    fallbacks: tuple[Fallback, ...] = FALLBACKS,
    fit_give: float = FIT_GIVE,
    solver: str = "batched",
    metrics: bool = True,
    check_scale: bool = True,
) -> CheckedTrajectory:
    """``trajectory`` (``motion`` retargeted to ``robot`` with ``config``, default the mapping's
    settings, and ``transform``) and its ``report``; where that fails on RETRIED_KINDS alone,
    ``motion`` retargeted again with each of ``fallbacks`` (at the trajectory's rate, ``solver``,
    ``metrics`` and ``check_scale`` as :func:`retarget.retarget_motion`'s), each output checked
    by ``check``; the passing one closest to the human within ``fit_give`` (a share of the
    first fit, >= 0, else one line) is kept, else the first. ``controlmm plan`` calls it on
    each round's output."""
    _check_fit_give(fit_give)
    rm = load_robot(robot)
    base = config if config is not None else SolverConfig(**rm.mapping.solver)

    def attempt(name: str, out: RobotTrajectory, verdict: Report) -> Attempt:
        fit = similarity_fit(rm, out.qpos, out.fps, motion.joints, motion.fps).mean
        return Attempt(name, verdict.passed, tuple(sorted({f.kind for f in verdict.errors})), fit)

    first = attempt("default", trajectory, report)
    attempts = [first]
    if report.passed or not set(first.errors) <= set(RETRIED_KINDS):
        return CheckedTrajectory(trajectory, report, None, attempts)
    best: tuple[RobotTrajectory, Report, Attempt] | None = None
    for fallback in fallbacks:
        settings = replace(base, **fallback.solver)
        if settings == base:
            continue
        out = retarget_motion(
            motion,
            robot=robot,
            fps=trajectory.fps,
            transform=transform,
            config=settings,
            solver=solver,
            metrics=metrics,
            check_scale=check_scale,
        )
        verdict = check(out)
        attempts.append(attempt(fallback.name, out, verdict))
        if verdict.passed and attempts[-1].fit_m <= first.fit_m * (1 + fit_give):
            if best is None or attempts[-1].fit_m < best[2].fit_m:
                best = (out, verdict, attempts[-1])
    if best is None:
        return CheckedTrajectory(trajectory, report, None, attempts)
    return CheckedTrajectory(best[0], best[1], best[2].name, attempts)


def _check_fit_give(fit_give: float) -> None:
    if not fit_give >= 0:
        raise ControlMMError(f"fit_give must be 0 or more; got {fit_give}")
