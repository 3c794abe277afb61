"""Building blocks shared by the motion families: a randomised person, standing and
locomotion plans, arm gestures.

Every family builds a :class:`~controlmm.corpus.body.BodyPlan` with these helpers, edits
what makes it special (a waving arm, a lowered pelvis...) and calls :func:`finish`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.ndimage import gaussian_filter1d

from controlmm.corpus.body import ArmPlan, BodyPlan, assemble, chest_target, standing_pelvis_height
from controlmm.corpus.curves import gentle_noise, window
from controlmm.corpus.feet import FootTrack, Stance, foot_track, stance_bump, swing_bump
from controlmm.corpus.gait import Gait, RootPath, plan_footholds
from controlmm.corpus.rig import SIDE_SIGN, heading_vectors
from controlmm.motion.skeleton import FPS, MAX_FRAMES, MIN_FRAMES

SIDES = ("left", "right")


def frames_for(seconds: float) -> int:
    """Raw frames to generate for a clip of about ``seconds`` (HumanML3D processing drops one
    frame, so the result is 41..197 raw frames -> 40..196 feature frames)."""
    n = int(round(seconds * FPS))
    return int(np.clip(n, MIN_FRAMES, MAX_FRAMES)) + 1


def times(n_raw: int) -> np.ndarray:
    """Frame times (s) of ``n_raw`` raw frames."""
    return np.arange(n_raw) / FPS


@dataclass
class Person:
    """Who moves, and how they stand: randomised per clip."""

    width: float
    toe_out: float
    extension: float
    lean: float
    head_pitch: float
    swing: float
    stagger: float
    yaw0: float

    @classmethod
    def sample(cls, rng: np.random.Generator) -> Person:
        return cls(
            width=rng.uniform(0.16, 0.26),
            toe_out=rng.uniform(0.02, 0.14),
            extension=rng.uniform(0.984, 0.994),
            lean=rng.uniform(-0.02, 0.07),
            head_pitch=rng.uniform(-0.08, 0.12),
            swing=rng.uniform(0.35, 0.7),
            stagger=rng.uniform(-0.05, 0.05),
            yaw0=rng.uniform(-np.pi, np.pi),
        )

    @property
    def stand_height(self) -> float:
        return standing_pelvis_height(self.extension)

    def initial_feet(self, xz: np.ndarray, yaw: float) -> dict[str, tuple[np.ndarray, float]]:
        """Standing footholds around ``xz`` facing ``yaw``."""
        fwd, left = heading_vectors(np.array(yaw))
        out = {}
        for side in SIDES:
            s = SIDE_SIGN[side]
            pos = xz + s * 0.5 * self.width * left[[0, 2]] + s * 0.5 * self.stagger * fwd[[0, 2]]
            out[side] = (pos, yaw + s * self.toe_out)
        return out


def idle_arms(rng: np.random.Generator, t: np.ndarray) -> dict[str, ArmPlan]:
    """Relaxed hanging arms with a little sway."""
    arms = {}
    for side in SIDES:
        arm = ArmPlan.hanging(len(t), side, rng)
        arm.flex = arm.flex + gentle_noise(rng, t, 0.04)
        arm.abd = arm.abd + gentle_noise(rng, t, 0.02)
        arm.elbow = np.maximum(arm.elbow + gentle_noise(rng, t, 0.05), 0.08)
        arms[side] = arm
    return arms


def balance(rng: np.random.Generator, t: np.ndarray, width: float) -> tuple[np.ndarray, np.ndarray]:
    """Postural sway of a person standing (T,) each, metres in the heading frame: a slow drift of
    the pelvis over the feet (about 1 cm, 0.08-0.3 Hz) plus, in clips over 3 s, one or two weight
    shifts onto one leg (25-45 % of the way to that foot, eased in over 0.6-1.2 s, held 0.5-2 s).

    Returns the lateral (+ left) and fore-aft (+ forward) pelvis offsets."""
    lateral = gentle_noise(rng, t, rng.uniform(0.006, 0.014), (0.08, 0.3))
    fore = gentle_noise(rng, t, rng.uniform(0.004, 0.01), (0.08, 0.3))
    shifts = int(rng.choice([0, 1, 2], p=[0.25, 0.5, 0.25])) if t[-1] > 3.0 else int(rng.random() < 0.4)
    side = float(rng.choice([-1.0, 1.0]))
    for _ in range(shifts):
        rise, hold = rng.uniform(0.6, 1.2), rng.uniform(0.5, 2.0)
        start = rng.uniform(0.0, max(t[-1] - 2.0 * rise - hold, 0.1))
        amount = side * rng.uniform(0.25, 0.45) * 0.5 * width
        lateral = lateral + amount * window(t, start, start + 2.0 * rise + hold, rise)
        side = -side
    return lateral, fore


def standing_plan(
    rng: np.random.Generator,
    person: Person,
    t: np.ndarray,
    stances: dict[str, list[Stance]] | None = None,
    still: np.ndarray | None = None,
) -> BodyPlan:
    """A person standing in place (feet planted, breathing, postural sway and weight shifts of the
    pelvis with the trunk balancing over it, small sway of head and arms).

    ``stances`` overrides the feet (e.g. a step back before kneeling); ``still`` (T,) in [0, 1]
    scales the standing sway (0 while walking)."""
    n = len(t)
    yaw = np.full(n, person.yaw0)
    if stances is None:
        feet0 = person.initial_feet(np.zeros(2), person.yaw0)
        stances = {s: [Stance(-np.inf, np.inf, feet0[s][0], feet0[s][1])] for s in SIDES}
    feet = {s: foot_track(s, stances[s], t) for s in SIDES}
    root = 0.5 * (feet["left"].ankle + feet["right"].ankle)[:, [0, 2]]
    root = gaussian_filter1d(root, 3.0, axis=0, mode="nearest")
    height = np.full(n, person.stand_height) + gentle_noise(rng, t, 0.004, (0.2, 0.4))
    lateral, fore = balance(rng, t, person.width)
    weight = np.ones(n) if still is None else np.clip(still, 0.0, 1.0)
    lateral, fore = lateral * weight, fore * weight
    shift = np.zeros((n, 3))
    shift[:, 0], shift[:, 2] = lateral, fore
    return BodyPlan(
        fps=float(FPS),
        root_xz=root,
        yaw=yaw,
        feet=feet,
        pelvis_height=height,
        arms=idle_arms(rng, t),
        pelvis_shift=shift,
        # The loaded hip rises (the free side drops) and the trunk leans back over the feet.
        pelvis_roll=-1.5 * lateral,
        pelvis_pitch=np.full(n, 0.5 * person.lean) + gentle_noise(rng, t, 0.01),
        spine_pitch=np.full(n, 0.5 * person.lean) + gentle_noise(rng, t, 0.015) - 0.6 * fore,
        spine_roll=gentle_noise(rng, t, 0.015) - 1.2 * lateral,
        spine_twist=gentle_noise(rng, t, 0.03),
        head_pitch=np.full(n, person.head_pitch) + gentle_noise(rng, t, 0.04),
        head_yaw=gentle_noise(rng, t, 0.08),
    )


@dataclass
class Style:
    """How a locomotion looks: gait kind and body attitude."""

    kind: str = "walk"  # walk | jog | run | crouch
    bob: float = 0.03  # vertical pelvis oscillation (m)
    drop: float = 0.015  # pelvis lowered while moving (m)
    lean: float = 0.04  # forward lean while moving (rad)
    arm_swing: float = 1.0  # multiplies the person's arm swing
    elbow: float = 0.0  # extra elbow flexion while moving (rad)


def locomotion_plan(
    rng: np.random.Generator,
    person: Person,
    t: np.ndarray,
    path: RootPath,
    gait: Gait,
    style: Style,
    stances: dict[str, list[Stance]] | None = None,
) -> BodyPlan:
    """A person travelling along ``path`` with ``gait``; returns the plan (not yet assembled)."""
    if stances is None:
        stances = plan_footholds(
            path, gait, float(FPS), initial=person.initial_feet(path.xz[0], float(path.yaw[0]))
        )
    feet = {s: foot_track(s, stances[s], t) for s in SIDES}
    act = activity(feet, t)
    plan = standing_plan(rng, person, t, stances=stances, still=1.0 - act)
    plan.root_xz = path.xz
    plan.yaw = path.yaw.copy()
    speed = np.linalg.norm(np.gradient(path.xz, axis=0), axis=-1) * FPS
    if style.kind in ("jog", "run"):
        comp = stance_bump(feet, t)
        plan.pelvis_height = person.stand_height - act * (style.drop + style.bob * comp)
        plan.sway = 0.12
    else:
        plan.pelvis_height = person.stand_height - act * style.drop + style.bob * swing_bump(feet, t)
    plan.pelvis_height = plan.pelvis_height + gentle_noise(rng, t, 0.003)
    lean = style.lean * act
    plan.pelvis_pitch = plan.get("pelvis_pitch") + 0.5 * lean
    plan.spine_pitch = plan.get("spine_pitch") + 0.5 * lean
    plan.head_pitch = plan.get("head_pitch") - 0.3 * lean
    plan.head_yaw = plan.get("head_yaw") * (1.0 - 0.7 * act)
    for side in SIDES:
        arm = plan.arms[side]
        arm.swing = person.swing * style.arm_swing * act
        arm.elbow = arm.elbow + style.elbow * act
        if style.kind in ("jog", "run"):
            arm.abd = arm.abd + 0.08 * act
            arm.twist = arm.twist + 0.4 * act
    plan.extras["speed"] = speed
    plan.extras["activity"] = act
    return plan


def activity(feet: dict[str, FootTrack], t: np.ndarray, sigma: float = 4.0) -> np.ndarray:
    """How much the person is stepping, in [0, 1] per frame (smoothed 'a foot is swinging')."""
    swinging = ~(feet["left"].planted & feet["right"].planted)
    a = gaussian_filter1d(swinging.astype(np.float64), sigma, mode="nearest") * 2.5
    return np.clip(a, 0.0, 1.0)


def finish(plan: BodyPlan) -> np.ndarray:
    """Assemble the plan into joints (T, 22, 3) float64."""
    return assemble(plan)


def set_ik(
    arm: ArmPlan,
    weight: np.ndarray,
    target: np.ndarray,
    pole: np.ndarray | None = None,
    elevation: np.ndarray | None = None,
    arc: tuple[float, float, float] | None = None,
) -> None:
    """Blend an arm towards a wrist target (chest frame, relative to the shoulder) with
    ``weight`` (T,) in [0, 1]; keeps the existing target where the weight is 0. ``arc``
    (chest frame, m) bows the path while the weight changes (e.g. raise the arm in front
    of the body rather than through the shoulder)."""
    w = np.clip(weight, 0.0, 1.0)
    if arc is not None:
        target = target + (4.0 * w * (1.0 - w))[:, None] * np.asarray(arc)
    arm.target = np.where(w[:, None] > 0, target, arm.target)
    if pole is not None:
        arm.pole = np.where(w[:, None] > 0, pole, arm.pole)
    arm.ik = np.maximum(arm.ik, w)
    if elevation is not None:
        arm.elevation = arm.elevation + elevation * w
    arm.swing = arm.swing * (1.0 - w)


def set_world_ik(
    plan: BodyPlan,
    side: str,
    weight: np.ndarray,
    world: np.ndarray,
    pole: np.ndarray,
    elevation: np.ndarray | None = None,
) -> None:
    """Like :func:`set_ik` with a wrist target in world coordinates (T, 3) or (3,) (an object on
    the floor, a thigh, a wall): converted to the chest frame of the plan as it stands, so call it
    after the trunk (pelvis, spine) is final. ``pole`` is in the chest frame."""
    arm = plan.arms[side]
    if elevation is not None:
        arm.elevation = arm.elevation + elevation * np.clip(weight, 0.0, 1.0)
    set_ik(arm, weight, chest_target(plan, side, world), pole)


def axes(yaw: float) -> tuple[np.ndarray, np.ndarray]:
    """Forward and left ground vectors (2,) as (x, z) of a heading ``yaw``."""
    fwd, left = heading_vectors(np.array(yaw))
    return fwd[[0, 2]], left[[0, 2]]
