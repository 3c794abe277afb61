"""The control signal of one regeneration pass, its loss terms, and the measures of the result.

A pass regenerates one track: its body part over its span ``[s, e)`` is *free*; every other entry
(frame, joint) of the motion is *held* at the reference (what earlier passes fixed):

* held in the world (the generator's dense spatial control, ``mask``): every entry outside the
  free region, when the part does not hold the pelvis (arms, torso, head). When it does (``legs``,
  ``whole_body``), only the frames before the span are held in the world;
* held relative to the body (``hold`` entries, a loss term) when the part holds the pelvis: the other
  joints inside the span keep their position relative to the pelvis and facing of their own frame,
  and every joint after the span keeps its position relative to the pelvis and facing of frame ``e``
  (so the rest of the motion is carried to wherever the track took the body);
* blended (``blend`` entries, a loss term): the free joints in the first and last ``blend_frames``
  frames of the span may leave the reference by at most ``tolerance + rate * d`` metres, ``d`` the
  frames from the span edge. The motion thus leaves and rejoins the held motion no faster than
  ``rate`` (m per frame) more than the reference, so there is no jump at the edges.

Relative positions ("local"): ``p - pelvis_xz(a)`` rotated about Y so that the right-hip -> left-hip
axis of anchor frame ``a`` maps to +X (heights are kept). Every loss is a hinge
``mean(relu(distance - margin)^2)``: exactly 0 once met, so the editors stop early.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from controlmm.control.terms import LossTerm
from controlmm.motion.skeleton import FPS, NUM_JOINTS

LEFT_HIP, RIGHT_HIP, PELVIS = 1, 2, 0
WORLD = -1  # anchor of an entry compared in the world frame


@dataclass(frozen=True)
class Entries:
    """Entries compared one by one: frames (E,), joints (E,), anchors (E,) (-1 = world), margins (E,) m,
    and optionally origins (E,): the joint an anchored entry is measured from (-1 = the pelvis on the floor).
    """

    frames: np.ndarray
    joints: np.ndarray
    anchors: np.ndarray
    margins: np.ndarray
    origins: np.ndarray | None = None

    @classmethod
    def empty(cls) -> Entries:
        z = np.zeros(0, dtype=np.int64)
        return cls(z, z, z, np.zeros(0, dtype=np.float32))

    def shifted(self, shift: int) -> Entries:
        """The same entries with frames and anchors moved by -shift."""
        anchors = np.where(self.anchors >= 0, self.anchors - shift, self.anchors)
        return Entries(self.frames - shift, self.joints, anchors, self.margins, self.origins)

    def __len__(self) -> int:
        return int(self.frames.shape[0])


@dataclass(frozen=True)
class ControlSignal:
    """What one pass holds and frees in a motion of T frames (see the module docstring).

    Attributes:
        free: (T, 22) bool, the track's part over its span.
        mask: (T, 22) bool, entries held at their reference world position (dense control).
        hold: entries held relative to the body (root-moving parts only).
        blend: free entries near the span edges, with growing margins.
        span: (s, e) frames.
    """

    free: np.ndarray
    mask: np.ndarray
    hold: Entries
    blend: Entries
    span: tuple[int, int]

    @property
    def held(self) -> np.ndarray:
        """(T, 22) bool: every entry the pass must keep (world or relative)."""
        return ~self.free


def build_signal(
    num_frames: int,
    joints: tuple[int, ...],
    span: tuple[int, int],
    *,
    root_moves: bool,
    tolerance: float = 0.008,
    blend_frames: int = 10,
    blend_rate: float = 0.05,
) -> ControlSignal:
    """The control signal of a pass regenerating ``joints`` over frames ``span = (s, e)``.

    Args:
        num_frames: T, frames of the motion.
        joints: joint indices of the track's part.
        span: (s, e), 0 <= s < e <= T.
        root_moves: the part holds the pelvis (the rest is then held relative to the body).
        tolerance: margin (m) of the held-relative entries and at the span edges.
        blend_frames: frames at each interior span edge that are blended.
        blend_rate: extra margin per frame away from an edge (m/frame; 0.05 = 1 m/s).
    """
    s, e = span
    if not 0 <= s < e <= num_frames:
        raise ValueError(f"span {span} is not inside 0..{num_frames}")
    free = np.zeros((num_frames, NUM_JOINTS), dtype=bool)
    free[s:e, list(joints)] = True
    if not root_moves:
        mask = ~free
        hold = Entries.empty()
    else:
        mask = np.zeros_like(free)
        mask[:s] = True
        frames, js, anchors = [], [], []
        others = [j for j in range(NUM_JOINTS) if j not in joints]
        for t in range(s, e):
            for j in others:
                frames.append(t)
                js.append(j)
                anchors.append(t)
        if e < num_frames:
            for t in range(e, num_frames):
                for j in range(NUM_JOINTS):
                    frames.append(t)
                    js.append(j)
                    anchors.append(e)
        hold = Entries(
            np.array(frames, dtype=np.int64),
            np.array(js, dtype=np.int64),
            np.array(anchors, dtype=np.int64),
            np.full(len(frames), tolerance, dtype=np.float32),
        )
    frames, js, anchors, margins = [], [], [], []
    width = min(blend_frames, e - s)
    for d in range(1, width + 1):
        for t, edge_anchor, interior in (
            (s + d - 1, WORLD, s > 0),
            (e - d, e if (root_moves and e < num_frames) else WORLD, e < num_frames),
        ):
            if not interior:
                continue
            for j in joints:
                frames.append(t)
                js.append(j)
                anchors.append(edge_anchor)
                margins.append(tolerance + blend_rate * d)
    blend = Entries(
        np.array(frames, dtype=np.int64),
        np.array(js, dtype=np.int64),
        np.array(anchors, dtype=np.int64),
        np.array(margins, dtype=np.float32),
    )
    return ControlSignal(free=free, mask=mask, hold=hold, blend=blend, span=(s, e))


def local_positions(joints: torch.Tensor, entries: Entries) -> torch.Tensor:
    """Positions (..., E, 3) of the entries of joints (..., T, 22, 3), relative where anchored.

    World entries (anchor -1) are returned as they are; an anchored entry is expressed relative to
    the pelvis (horizontal position) and facing (hip axis) of its anchor frame.
    """
    frames = torch.as_tensor(entries.frames, device=joints.device)
    js = torch.as_tensor(entries.joints, device=joints.device)
    anchors = torch.as_tensor(entries.anchors, device=joints.device)
    p = joints[..., frames, js, :]
    safe = anchors.clamp(min=0)
    origin = joints[..., safe, PELVIS, :] * joints.new_tensor([1.0, 0.0, 1.0])
    if entries.origins is not None:
        origins = torch.as_tensor(entries.origins, device=joints.device)
        attached = joints[..., safe, origins.clamp(min=0), :]
        origin = torch.where((origins >= 0)[..., None], attached, origin)
    across = joints[..., safe, LEFT_HIP, :] - joints[..., safe, RIGHT_HIP, :]
    cx, cz = across[..., 0], across[..., 2]
    norm = torch.sqrt(cx * cx + cz * cz + 1e-12)
    cx, cz = cx / norm, cz / norm
    v = p - origin
    local = torch.stack(
        [v[..., 0] * cx + v[..., 2] * cz, v[..., 1], -v[..., 0] * cz + v[..., 2] * cx], dim=-1
    )
    return torch.where((anchors >= 0)[..., None], local, p)


def entry_distances(joints: torch.Tensor, reference: torch.Tensor, entries: Entries) -> torch.Tensor:
    """Distance (..., E) m between the entries of joints (..., T, 22, 3) and of reference (T, 22, 3)."""
    ref = local_positions(reference, entries)
    return (local_positions(joints, entries) - ref).norm(dim=-1)


def hinge_term(
    name: str, target: np.ndarray | torch.Tensor, entries: Entries, weight: float = 1.0
) -> LossTerm:
    """LossTerm ``mean_e relu(distance_e - margin_e)^2`` per sample (0 once every entry is within its margin).

    ``target`` (E, 3): the wanted :func:`local_positions` of the entries (see :func:`reference_targets`).
    Unlike a mean squared error, entries already within their margin pull no more, so the editors
    spend their steps on the worst ones (the stopping rule looks at the worst entry too).
    """
    ref_local = torch.as_tensor(np.asarray(target, dtype=np.float32))
    margins = torch.as_tensor(entries.margins, dtype=torch.float32)

    def fn(joints: torch.Tensor) -> torch.Tensor:
        d = (local_positions(joints, entries) - ref_local.to(joints.device)).norm(dim=-1)
        return torch.relu(d - margins.to(joints.device)).pow(2).mean(-1)

    return LossTerm(name, fn, weight)


def reference_targets(reference: np.ndarray, entries: Entries, shift: int = 0) -> np.ndarray:
    """(E, 3) local positions of the entries in ``reference`` (T', 22, 3), frames and anchors moved by
    -shift."""
    with torch.no_grad():
        return local_positions(
            torch.as_tensor(np.asarray(reference, dtype=np.float32)), entries.shifted(shift)
        ).numpy()


def world_entries(mask: np.ndarray, margin: float) -> Entries:
    """The entries of a (T, 22) mask, compared in the world with one margin."""
    frames, js = np.nonzero(mask)
    return Entries(
        frames.astype(np.int64),
        js.astype(np.int64),
        np.full(len(frames), WORLD, dtype=np.int64),
        np.full(len(frames), margin, dtype=np.float32),
    )


def prompt_entries(
    signal: ControlSignal,
    joints: tuple[int, ...],
    *,
    root_moves: bool,
    attachment: int = PELVIS,
    margin: float = 0.03,
    blend_frames: int = 10,
    blend_rate: float = 0.05,
) -> Entries:
    """The free entries of a pass as soft targets from the track's prompt generated alone over the span.

    Anchors: the ``attachment`` joint and facing of the entry's own frame (the part's pose relative to
    what it hangs from), or, for parts holding the pelvis, the pelvis and facing of the span's first
    frame (the path the part takes the body along).
    Margins grow by ``blend_rate`` per frame towards interior span edges (over ``blend_frames``), where
    the blend toward the held motion takes over.
    """
    s, e = signal.span
    num_frames = signal.free.shape[0]
    frames, js, anchors, margins = [], [], [], []
    origin = -1 if root_moves else attachment
    for t in range(s, e):
        relax = 0
        if s > 0:
            relax = max(relax, blend_frames - (t - s))
        if e < num_frames:
            relax = max(relax, blend_frames - (e - 1 - t))
        for j in joints:
            frames.append(t)
            js.append(j)
            anchors.append(s if root_moves else t)
            margins.append(margin + blend_rate * max(relax, 0))
    return Entries(
        np.array(frames, dtype=np.int64),
        np.array(js, dtype=np.int64),
        np.array(anchors, dtype=np.int64),
        np.array(margins, dtype=np.float32),
        np.full(len(frames), origin, dtype=np.int64),
    )


def signal_terms(
    signal: ControlSignal,
    reference: np.ndarray,
    prompt_clip: np.ndarray | None = None,
    prompt: Entries | None = None,
    tolerance: float = 0.008,
    prompt_weight: float = 0.3,
    prompt_shift: int | None = None,
    held_weight: float = 20.0,
) -> list[LossTerm]:
    """The loss terms of a pass beside its dense control: world-held outliers, body-held entries, edge
    blending and (with ``prompt_clip`` (L, 22, 3), whose frame 0 is frame ``prompt_shift`` of the motion,
    default the span's first frame) the prompt's part."""
    terms = []
    if signal.mask.any():
        held = world_entries(signal.mask, tolerance)
        terms.append(hinge_term("timeline:held", reference_targets(reference, held), held, held_weight))
    for name, entries, weight in (
        ("timeline:hold", signal.hold, held_weight),
        ("timeline:blend", signal.blend, 1.0),
    ):
        if len(entries):
            terms.append(hinge_term(name, reference_targets(reference, entries), entries, weight))
    if prompt_clip is not None and prompt is not None and len(prompt):
        terms.append(
            hinge_term(
                "timeline:prompt",
                reference_targets(
                    prompt_clip, prompt, shift=signal.span[0] if prompt_shift is None else prompt_shift
                ),
                prompt,
                weight=prompt_weight,
            )
        )
    return terms


# -- measures -----------------------------------------------------------------------------------------
def held_drift(joints: np.ndarray, reference: np.ndarray, signal: ControlSignal) -> np.ndarray:
    """(T, 22) metres: how far every held entry moved from the reference (world or relative); 0 if free."""
    out = np.zeros(joints.shape[:2], dtype=np.float64)
    world = np.linalg.norm(joints - reference, axis=-1)
    out[signal.mask] = world[signal.mask]
    if len(signal.hold):
        with torch.no_grad():
            d = entry_distances(
                torch.as_tensor(joints, dtype=torch.float32),
                torch.as_tensor(reference, dtype=torch.float32),
                signal.hold,
            ).numpy()
        out[signal.hold.frames, signal.hold.joints] = d
    return out


def joint_speeds(joints: np.ndarray, fps: float = FPS) -> np.ndarray:
    """(T - 1, 22) m/s: speed of every joint between consecutive frames."""
    return np.linalg.norm(np.diff(np.asarray(joints, dtype=np.float64), axis=0), axis=-1) * fps


def boundary_speed(joints: np.ndarray, frame: int, fps: float = FPS, window: int = 2) -> float:
    """Fastest joint speed (m/s) in the frame steps within ``window`` frames of a boundary frame."""
    speeds = joint_speeds(joints, fps)
    lo, hi = max(frame - window, 0), min(frame + window, speeds.shape[0])
    return float(speeds[lo:hi].max()) if hi > lo else 0.0
