"""Stage ``tokenizer``: the RVQ-VAE on random 64-frame windows (MoMask ``train_vq.py``).

Loss = SmoothL1(x_hat, x) + 0.5 SmoothL1 on the RIC positions (dims 4:67) + 0.02 commitment (MoMask's),
plus two terms of ours that keep what the probes and users look at:

* limb ends: SmoothL1 on the RIC positions of the ankles, feet and wrists; at the ``demo`` preset's
  weight (6 over 18 dims) each of those dims counts about 30 times more than in MoMask's terms.
  Punches, claps and waves are wrist swings of a few centimetres at 2-3 Hz and kicks brief ankle
  peaks: under MoMask's loss punches passed 73 % of their probes after encode-decode, and a head term
  alone cost them more (claps 13 %, waves 0 %);
* head direction: a nearly-L1 SmoothL1 (beta 0.02) on the neck -> head vector. A head turned against the
  shoulders moves the head joint only 6-7 cm; under MoMask's terms the tokenizer averaged such turns away
  (the look-around family's 36-55 degree turns came back as 2-6 degrees, 0 % of its probes), and a
  quadratic term on the head's position alone traded them against the wrists.

Their weights are the tokenizer schedule's ``limb_end_weight`` and ``head_weight`` (0 and 0, MoMask's
loss, unless the preset sets them: ``demo`` has 6 and 2, chosen with ``controlmm eval probes
--tokenizer-only`` on the 49-family corpus; docs/BENCHMARKS.md, "Tokenizer loss").
Validation on fixed windows of the val split: the same loss; MPJPE in mm as MoMask computes it
(joints recovered from the features, each frame aligned at the pelvis; ``val_mpjpe_mm``, the metric that
selects the exported weights); the error of the unaligned global joints (``val_global_mpjpe_mm``, windows
start at the origin); the share of base-layer codes in use.
"""

from __future__ import annotations

from typing import Any, cast

import torch
import torch.nn.functional as F
from torch import nn

from controlmm.data.datasets import WindowDataset
from controlmm.data.humanml3d import HumanML3D
from controlmm.models.model_dir import MotionModel
from controlmm.models.rvqvae import RVQVAE
from controlmm.motion.recover import features_to_joints
from controlmm.training.model_stage import ModelStage, StageContext
from controlmm.training.stage import VALIDATION_SEED

RIC = slice(4, 67)


def ric_dims(*joints: int) -> list[int]:
    """Feature dims of the RIC positions of joints >= 1 (joint j: dims 4 + 3 (j - 1) to 6 + 3 (j - 1))."""
    return [4 + 3 * (j - 1) + k for j in joints for k in range(3)]


LIMB_ENDS = ric_dims(7, 8, 10, 11, 20, 21)
"""RIC dims of the ankles (7, 8), feet (10, 11) and wrists (20, 21)."""
NECK, HEAD = ric_dims(12), ric_dims(15)
HEAD_BETA = 0.02
"""SmoothL1 beta (normalised units) of the neck -> head vector term: nearly L1."""


def head_direction_loss(recon: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
    """Nearly-L1 error of the neck -> head vector in RIC, (..., 263) normalised features -> scalar."""
    r = recon[..., HEAD] - recon[..., NECK]
    t = target[..., HEAD] - target[..., NECK]
    return F.smooth_l1_loss(r, t, beta=HEAD_BETA)


def reconstruction_loss(
    recon: torch.Tensor,
    target: torch.Tensor,
    commit: torch.Tensor,
    limb_end_weight: float = 0.0,
    head_weight: float = 0.0,
) -> torch.Tensor:
    """The tokenizer's loss (see the module) of (B, T, 263) normalised features and the commitment;
    the two extra terms' weights (0, 0: MoMask's loss)."""
    recon = recon.float()
    loss = (
        F.smooth_l1_loss(recon, target)
        + 0.5 * F.smooth_l1_loss(recon[..., RIC], target[..., RIC])
        + 0.02 * commit
    )
    if limb_end_weight:
        loss = loss + limb_end_weight * F.smooth_l1_loss(recon[..., LIMB_ENDS], target[..., LIMB_ENDS])
    if head_weight:
        loss = loss + head_weight * head_direction_loss(recon, target)
    return loss


def mpjpe(pred: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
    """MoMask's MPJPE (m): joints (..., T, 22, 3) aligned at the pelvis in every frame, mean distance."""
    pred = pred - pred[..., :1, :]
    target = target - target[..., :1, :]
    return (pred - target).norm(dim=-1).mean()


class TokenizerLoss(nn.Module):
    def __init__(self, model: RVQVAE, limb_end_weight: float = 0.0, head_weight: float = 0.0) -> None:
        super().__init__()
        self.model = model
        self.limb_end_weight, self.head_weight = limb_end_weight, head_weight

    def forward(self, x: torch.Tensor) -> tuple[torch.Tensor, dict[str, torch.Tensor]]:
        """Reconstruction loss of (B, T, 263) normalised windows; (loss, metrics)."""
        recon, commit, perplexity, _ = self.model(x)
        loss = reconstruction_loss(recon, x, commit, self.limb_end_weight, self.head_weight)
        return loss, {"loss": loss.detach(), "commit": commit.detach(), "perplexity": perplexity.detach()}


class TokenizerStage(ModelStage):
    name = "tokenizer"
    requires = ()
    best_metric = "val_mpjpe_mm"

    def __init__(self, ctx: StageContext) -> None:
        super().__init__(ctx)
        schedule = ctx.config.schedules.get("tokenizer")
        window = schedule.window if schedule is not None else 64
        self.limb_end_weight = schedule.limb_end_weight if schedule is not None else 0.0
        self.head_weight = schedule.head_weight if schedule is not None else 0.0
        step = ctx.config.tokenizer.downsample
        self.window = window - window % step
        data = ctx.data
        self.train_motions = data.motions("train", self.window, progress=ctx.progress)
        self.val_motions = data.motions("val", self.window, progress=ctx.progress)

    def build_model(self) -> nn.Module:
        return RVQVAE(self.ctx.config.tokenizer)

    def train_dataset(self) -> WindowDataset:
        return WindowDataset(self.train_motions, self.ctx.normalizer, self.window, seed=self.ctx.seed)

    def loss_module(self, model: nn.Module) -> nn.Module:
        return TokenizerLoss(cast(RVQVAE, model), self.limb_end_weight, self.head_weight)

    def prepare(self, batch: Any) -> tuple:
        return (batch.to(self.ctx.device, non_blocking=True),)

    @torch.no_grad()
    def validate(self, model: nn.Module) -> dict[str, float]:
        val = WindowDataset(self.val_motions, self.ctx.normalizer, self.window, seed=VALIDATION_SEED + 1)
        losses, errors, global_errors = [], [], []
        used = torch.zeros(self.ctx.config.tokenizer.nb_code, dtype=torch.bool)
        device = self.ctx.device
        for start in range(0, len(val), 64):
            x = torch.stack([val[(i, 0)] for i in range(start, min(len(val), start + 64))]).to(device)
            recon, commit, _, ids = model(x)
            loss = reconstruction_loss(recon, x, commit, self.limb_end_weight, self.head_weight)
            losses.append(float(loss) * len(x))
            joints_hat = features_to_joints(self.ctx.normalizer.denormalize(recon))
            joints = features_to_joints(self.ctx.normalizer.denormalize(x))
            errors.append(float(mpjpe(joints_hat, joints)) * len(x))
            global_errors.append(float((joints_hat - joints).norm(dim=-1).mean()) * len(x))
            used[ids[..., 0].flatten().cpu()] = True
        n = len(val)
        return {
            "val_loss": sum(losses) / n,
            "val_mpjpe_mm": 1000.0 * sum(errors) / n,
            "val_global_mpjpe_mm": 1000.0 * sum(global_errors) / n,
            "code_usage": float(used.float().mean()),
        }

    def extra_state(self, model: nn.Module) -> dict[str, Any]:
        return {"ema": cast(RVQVAE, model).quantizer.ema_state()}

    def load_extra_state(self, model: nn.Module, state: dict[str, Any]) -> None:
        if "ema" in state:
            cast(RVQVAE, model).quantizer.load_ema_state(state["ema"])

    def record(self) -> dict[str, Any]:
        return {
            "train_motions": len(self.train_motions),
            "val_motions": len(self.val_motions),
            "window": self.window,
        }


@torch.no_grad()
def reconstruction_metrics(model: MotionModel, data: HumanML3D, split: str = "test") -> dict[str, float]:
    """Tokenizer reconstruction of whole motions of a split (MoMask's VQ evaluation).

    Every motion (40 <= T < 200 frames, cropped to a multiple of 4) is encoded with all RVQ layers and
    decoded; returns MPJPE (pelvis-aligned, mm), global MPJPE (mm) and the number of motions.

    Args:
        model: a loaded :class:`~controlmm.models.MotionModel` with a tokenizer.
        data: a :class:`~controlmm.data.HumanML3D` directory.
    """
    tokenizer, norm = model.tokenizer, model.normalizer
    unit = model.config.tokenizer.downsample
    errors, global_errors = [], []
    for motion_id in data.split_ids(split):
        motion = data.load_motion(motion_id)
        if not 40 <= len(motion) < 200:
            continue
        frames = len(motion) // unit * unit
        x = torch.from_numpy(norm.normalize(motion[:frames])).float()[None].to(model.device)
        recon = tokenizer.decode(tokenizer.encode(x))
        joints_hat = features_to_joints(norm.denormalize(recon))[0]
        joints = features_to_joints(norm.denormalize(x))[0]
        errors.append(float(mpjpe(joints_hat, joints)))
        global_errors.append(float((joints_hat - joints).norm(dim=-1).mean()))
    if not errors:
        return {"motions": 0}
    return {
        "mpjpe_mm": 1000.0 * sum(errors) / len(errors),
        "global_mpjpe_mm": 1000.0 * sum(global_errors) / len(global_errors),
        "motions": len(errors),
    }
