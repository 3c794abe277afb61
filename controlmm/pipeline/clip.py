"""Editing a recorded clip to fit a scene: the clip's tokens, a closeness term, the displacement.

``controlmm plan --motion FILE`` does not generate: it reads the clip (any format of
:func:`controlmm.motion.load_motion`), encodes it with the model's tokenizer (the RVQ-VAE's token
ids, whose codebook vectors sum to the decoder latent z0) and codebook-edits that latent against the
scene's obstacle and floor losses, the control spec and the simulation feedback of every round,
like a generated motion (:class:`ClipEditor`).

The edit is applied to the clip as a change: the motion of a latent z is

    joints(z) = clip + D(z) - D(z0)        (D: decoder + HumanML3D recovery, human frame)

so an unedited clip is reproduced exactly, whatever the tokenizer's own reconstruction error
(``tokens_only`` in the report: the demo model's tokenizer, trained on the procedural corpus, is
several centimetres off on real mocap), and the decoder supplies a smooth, body-coordinated basis
of changes. One more loss term keeps the motion on the clip (``d`` the joints' displacement from the
clip, ``p`` the pelvis's horizontal part of it):

    closeness = mean over frames and joints of max(|d - p| - tol, 0)^2
                + 0.1 * mean over frames of max(|p| - tol, 0)^2                               (m^2)

so the pose counts fully and the path a tenth: going around an obstacle with the clip's poses is cheap.

It is quadratic while the obstacle, floor and feedback losses are linear in the penetration
depth, so near a constraint the constraint wins and the closeness term only decides everything
the constraints leave free: the motion stays as close to the clip as the constraints allow.
:func:`displacement` measures what the edit moved: per frame, the mean and the largest joint
distance to the clip (metres, human frame).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import torch

from controlmm.atomic import atomic_path
from controlmm.control.spec import ControlSpec
from controlmm.control.terms import LossTerm
from controlmm.editing.codebook_editing import codebook_editing
from controlmm.editing.foot_contact import foot_contact_run
from controlmm.editing.objective import Objective
from controlmm.editing.presets import EditingConfig
from controlmm.errors import ControlMMError
from controlmm.frames import HumanToWorld
from controlmm.generate.controlled import decode_latent, latent_to_positions
from controlmm.models.model_dir import MotionModel
from controlmm.motion.container import Motion
from controlmm.motion.io import load_motion
from controlmm.motion.skeleton import FPS, JOINT_NAMES, MIN_FRAMES
from controlmm.pipeline.refine import EditedMotion, control_targets

MAX_CLIP_SECONDS = 30.0
"""Longest clip a plan edits (600 frames at 20 fps): a longer clip is cut (with a warning) unless a
window is chosen."""
CLOSENESS_TOLERANCE_M = 0.01
"""Joint distance to the clip that costs nothing (the closeness term's dead zone)."""
PATH_WEIGHT = 0.1
"""Weight of the pelvis's horizontal path against the pose in the closeness term."""


def load_clip(
    path: str, options: dict[str, Any], start_s: float = 0.0, seconds: float | None = None
) -> Motion:
    """The clip as a HumanML3D Motion with features (20 fps, starting at the origin facing +Z),
    cut to ``[start_s, start_s + seconds)`` (at most :data:`MAX_CLIP_SECONDS`: a longer rest of the
    clip is cut there, and ``metadata["window_note"]`` says so); one-line errors for a window outside
    the clip or one too short to edit."""
    motion = load_motion(path, **options).with_features()
    frames = motion.num_frames
    first = int(round(start_s * FPS))
    if not 0 <= first < frames:
        raise ControlMMError(
            f"--motion-start {start_s:g} s is outside the clip '{path}' (0 to {frames / FPS:.2f} s)"
        )
    count = frames - first if seconds is None else min(int(round(seconds * FPS)), frames - first)
    if count < MIN_FRAMES:
        raise ControlMMError(
            f"the clip '{path}' from {start_s:g} s holds {count / FPS:.2f} s; a plan needs at least "
            f"{MIN_FRAMES / FPS:g} s ({MIN_FRAMES} frames at {FPS} fps)"
        )
    note = None
    if count > MAX_CLIP_SECONDS * FPS:
        note = (
            f"the clip '{path}' runs {count / FPS:.1f} s from {start_s:g} s; a plan edits at most "
            f"{MAX_CLIP_SECONDS:g} s, so {start_s:g}-{start_s + MAX_CLIP_SECONDS:g} s is edited "
            "(choose another window with --motion-start S --seconds S)"
        )
        count = int(MAX_CLIP_SECONDS * FPS)
    if first == 0 and count == frames:
        return motion
    assert motion.features is not None  # with_features() above
    metadata = {**motion.metadata, "window_s": [first / FPS, (first + count) / FPS]}
    if note:
        metadata["window_note"] = note
    # Recovered from the window's features, so that the window starts at the origin like the model's output.
    return Motion.from_features(motion.features[first : first + count], text=motion.text, metadata=metadata)


def encode_clip(model: MotionModel, motion: Motion) -> tuple[torch.Tensor, torch.Tensor]:
    """(decoder latent (1, N, code_dim), token ids (1, N, Q)) of a Motion with features.

    The features are normalised with the model's statistics, padded to whole tokens by repeating the
    last frame, and quantised by the tokenizer (RVQ-VAE encoder + residual quantiser).
    """
    if motion.features is None:
        raise ControlMMError("the clip has no features (HumanML3D processing): load it with with_features()")
    unit = model.config.tokenizer.downsample
    feats = motion.features
    pad = (-len(feats)) % unit
    if pad:
        feats = np.concatenate([feats, np.repeat(feats[-1:], pad, axis=0)])
    x = torch.as_tensor(model.normalizer.normalize(feats), dtype=torch.float32, device=model.device)[None]
    with torch.no_grad():
        ids = model.tokenizer.encode(x)
        latent = model.tokenizer.ids_to_latent(ids)
    return latent, ids


class ClipEditor:
    """Codebook editing of a recorded clip, applied to the clip as a change (module docstring).

    ``ClipEditor(model, clip)`` encodes the clip (:func:`encode_clip`); :meth:`edit` edits a latent
    (the clip's own, ``editor.latent``, in round 0; the previous round's after it).
    """

    def __init__(self, model: MotionModel, clip: Motion) -> None:
        self.model = model
        self.clip = clip
        self.frames = clip.num_frames
        self.latent, self.ids = encode_clip(model, clip)
        device = self.latent.device
        self.reference = torch.as_tensor(clip.joints, dtype=torch.float32, device=device)[None]
        with torch.no_grad():
            self.base = latent_to_positions(model, self.latent)[:, : self.frames]

    def decode(self, latent: torch.Tensor) -> torch.Tensor:
        """Joints (B, T, 22, 3) of latents (B, N, code_dim): the clip plus the decoded change from z0."""
        return self.reference + latent_to_positions(self.model, latent)[:, : self.frames] - self.base

    def tokens_only(self) -> Displacement:
        """How far the tokenizer's own reconstruction D(z0) is from the clip."""
        return reconstruction(self.model, self.latent, self.clip)

    def edit(
        self,
        latent: torch.Tensor,
        spec: ControlSpec | None,
        transform: HumanToWorld,
        terms: list[LossTerm],
        config: EditingConfig,
        text: str,
        metadata: dict[str, Any] | None = None,
    ) -> EditedMotion:
        """Codebook-edit ``latent`` (1, N, code_dim) against the spec and ``terms`` (like
        :func:`controlmm.pipeline.refine.edit_motion`), the motion decoded as a change of the clip."""
        targets, mask = control_targets(spec, self.frames, transform)
        device = latent.device
        objective = Objective(
            targets=targets.to(device),
            mask=mask.to(device),
            terms=terms,
            tolerance=config.tolerance,
            loss_tolerance=config.loss_tolerance,
            hinge_weight=config.hinge_weight,
        )
        steps, kept = 0, False
        if objective.active and config.codebook_steps > 0:
            with torch.enable_grad():
                outcome = codebook_editing(latent, self.decode, objective, config)
            latent, kept_t = foot_contact_run(outcome.param.detach(), self.decode, objective, config)
            steps, kept = int(outcome.steps[0]), bool(kept_t[0])
        with torch.no_grad():
            joints_t = self.decode(latent)
            values = objective.term_values(joints_t)
            _, done, max_err = objective.evaluate(joints_t)
        joints = joints_t[0].cpu().numpy().astype(np.float32)
        errors: list[float] = []
        extras: dict[str, np.ndarray] = {}
        if spec is not None:
            t_np, m_np = targets[0].numpy(), mask[0].numpy()
            errors = [
                float(np.linalg.norm(joints[c.frame, c.joint] - t_np[c.frame, c.joint]))
                for c in spec.constraints
            ]
            extras = {
                "control_mask": m_np,
                "control_targets": t_np,
                "control_errors": np.asarray(errors, np.float32),
            }
        record = {
            "codebook_steps": steps,
            "codebook_budget": config.codebook_steps,
            "converged": bool(done[0]),
            "max_error_m": max(errors, default=0.0),
            "contact_kept": kept,
            "losses": {k: float(v[0]) for k, v in values.items()},
            "decoding": "clip + D(z) - D(z0)",
        }
        motion = Motion(
            joints=joints, fps=float(FPS), text=text, metadata=dict(metadata or {}), extras=extras
        )
        return EditedMotion(latent=latent, motion=motion, errors=errors, record=record)


def closeness_term(
    reference: np.ndarray,
    weight: float = 1.0,
    tolerance: float = CLOSENESS_TOLERANCE_M,
    path_weight: float = PATH_WEIGHT,
) -> LossTerm:
    """The loss term that keeps joints (B, T, 22, 3) near ``reference`` (T, 22, 3) (module docstring).

    The pose (every joint relative to the pelvis's horizontal position) counts fully and the
    horizontal path of the pelvis ``path_weight`` times, so a detour around an obstacle that keeps the
    clip's poses costs little while a changed pose costs a lot."""
    ref = torch.as_tensor(np.asarray(reference), dtype=torch.float32)

    def excess(delta: torch.Tensor) -> torch.Tensor:
        return torch.relu((delta.square().sum(-1) + 1e-12).sqrt() - tolerance).square()

    def fn(joints: torch.Tensor) -> torch.Tensor:
        r = ref.to(device=joints.device, dtype=joints.dtype)[: joints.shape[1]]
        delta = joints[:, : len(r)] - r  # (B, T, 22, 3)
        path = delta[:, :, :1] * delta.new_tensor([1.0, 0.0, 1.0])  # the pelvis's horizontal shift
        pose = excess(delta - path).flatten(1).mean(-1)
        return pose + path_weight * excess(path[:, :, 0]).mean(-1)

    return LossTerm("closeness:clip", fn, weight=weight)


@dataclass
class Displacement:
    """How far an edited motion's joints are from the clip's (metres, human frame).

    Attributes:
        per_frame_mean: (T,) mean over the 22 joints; per_frame_max: (T,) the largest.
        mean_m, max_m: over every frame and joint; max_frame, max_joint: where the largest is.
    """

    per_frame_mean: np.ndarray
    per_frame_max: np.ndarray
    mean_m: float
    max_m: float
    max_frame: int
    max_joint: str

    def to_dict(self, per_frame: bool = True) -> dict[str, Any]:
        out: dict[str, Any] = {
            "mean_m": round(self.mean_m, 5),
            "max_m": round(self.max_m, 5),
            "max_frame": self.max_frame,
            "max_joint": self.max_joint,
        }
        if per_frame:
            out["per_frame_mean_m"] = [round(float(v), 5) for v in self.per_frame_mean]
            out["per_frame_max_m"] = [round(float(v), 5) for v in self.per_frame_max]
        return out

    def summary(self) -> str:
        return (
            f"clip: joints moved {self.mean_m * 100:.1f} cm on average from the recorded clip, at most "
            f"{self.max_m * 100:.1f} cm ({self.max_joint}, frame {self.max_frame} at {FPS} fps)"
        )


def displacement(edited: np.ndarray, clip: np.ndarray) -> Displacement:
    """Joint displacement of ``edited`` (T, 22, 3) from ``clip`` (T', 22, 3) over their common frames."""
    t = min(len(edited), len(clip))
    dist = np.linalg.norm(np.asarray(edited[:t], np.float64) - np.asarray(clip[:t], np.float64), axis=-1)
    frame, joint = np.unravel_index(int(np.argmax(dist)), dist.shape)
    return Displacement(
        per_frame_mean=dist.mean(axis=1),
        per_frame_max=dist.max(axis=1),
        mean_m=float(dist.mean()),
        max_m=float(dist.max()),
        max_frame=int(frame),
        max_joint=JOINT_NAMES[int(joint)],
    )


def reconstruction(model: MotionModel, latent: torch.Tensor, clip: Motion) -> Displacement:
    """How far the clip's tokens alone (decoded, before editing) are from the clip."""
    joints, _ = decode_latent(model, latent, clip.num_frames)
    return displacement(joints, clip.joints)


def plot_displacement(
    rounds: list[tuple[int, Displacement]], chosen: int, path: str, reconstructed: Displacement | None = None
) -> None:
    """Per-frame mean and largest joint displacement from the clip for every round (PNG, atomic)."""
    import matplotlib  # only for plots; the Agg backend is chosen before pyplot loads

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(2, 1, figsize=(9, 5.5), sharex=True)
    for ax, attr, label in ((axes[0], "per_frame_mean", "mean"), (axes[1], "per_frame_max", "max")):
        if reconstructed is not None:
            values = getattr(reconstructed, attr) * 100
            ax.plot(np.arange(len(values)) / FPS, values, color="grey", ls=":", lw=1, label="tokens only")
        for index, disp in rounds:
            values = getattr(disp, attr) * 100
            width, alpha = (2.0, 1.0) if index == chosen else (1.0, 0.5)
            ax.plot(np.arange(len(values)) / FPS, values, lw=width, alpha=alpha, label=f"round {index}")
        ax.set_ylabel(f"{label} joint displacement (cm)")
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize=8, loc="upper right")
    axes[1].set_xlabel("time (s)")
    fig.suptitle("edited motion vs the recorded clip (human joints)")
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=110, format="png")
    plt.close(fig)
