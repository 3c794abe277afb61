"""Stage ``control``: masked consistency training of the motion control model (ControlMM paper, §3.2).

One step on a batch of captioned clips (normalised motion X, lengths m), base transformer and
tokenizer frozen (as the official MaskControl ``ControlTransformer.forward``,
https://github.com/exitudio/MaskControl, except where noted):

1. tokens: base-layer ids of the frozen tokenizer; targets S = R(denorm(X)) (global joints);
2. a control mask sigma (B, T, 22): ``trajectory`` (pelvis), ``random`` (one control joint),
   ``cross`` (random (frame, joint) pairs of the control joints) or ``mixed`` (one of the three per
   sample), from one frame to every frame of the clip;
3. masking with the cosine schedule and BERT corruption (10 % random code, 88 % of the rest [MASK]);
4. the current motion estimate: codebook vectors of the corrupted ids, ``mask_emb_vq`` at [MASK]
   and pads, decoded by the frozen decoder (Paper A.8) -> the control input;
5. logits of the base transformer steered by the control branch (text dropped with probability
   ``cond_drop``, as the paper states; the released code never drops it: its control training puts the
   top-level module in eval mode, and its condition dropout checks that module's ``training`` flag);
6. cross-entropy on every non-pad position;
7. consistency loss: a differentiable estimate of the tokens mapped to codebook space,
   e = p C_0, decoded by the frozen decoder, joints recovered by the differentiable R(.), L1 error on
   the controlled (t, j) entries. ``p`` is the straight-through Gumbel-softmax sample of the paper
   (``estimator="gumbel"``: hard one-hot forward, soft gradient) or the plain softmax of the released
   code (``estimator="softmax"``);
8. loss = alpha CE + (1 - alpha) L_consistency (paper alpha = 0.1).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, replace
from typing import Any, cast

import numpy as np
import torch
import torch.nn.functional as F
from torch import nn

from controlmm.errors import ControlMMError
from controlmm.models.config import CONTROL_JOINT_SETS, ControlConfig
from controlmm.models.layers import cosine_schedule, gumbel_noise, lengths_to_mask, zero_samples
from controlmm.models.mask_transformer import MaskTransformer, token_loss_and_accuracy
from controlmm.models.model_dir import read_manifest, write_manifest
from controlmm.models.motion_control_model import MotionControlModel, control_input, estimate_latent
from controlmm.models.rvqvae import RVQVAE
from controlmm.motion.normalization import Normalizer
from controlmm.motion.recover import features_to_joints
from controlmm.training.model_stage import StageContext
from controlmm.training.stage import VALIDATION_SEED
from controlmm.training.transformer import TextConditionedStage

CONTROL_MODES = ("trajectory", "random", "cross", "mixed")
ESTIMATORS = ("gumbel", "softmax")
DENSITIES = ("uniform", "mixed")


@dataclass(frozen=True)
class ControlTraining:
    """Settings of masked consistency training (``controlmm train control`` options).

    alpha: weight of the cross-entropy; the consistency loss gets 1 - alpha (paper 0.1).
    estimator: ``gumbel`` (straight-through Gumbel-softmax, the paper) or ``softmax`` (released code).
    tau: Gumbel-softmax temperature.
    mode: control sampling: ``trajectory`` (pelvis), ``random`` (one control joint per sample),
        ``cross`` (random (frame, joint) pairs), ``mixed`` (each sample one of the three).
    density: number of controlled frames per sample: ``uniform`` = round(U(0, 1) x 196) clamped to
        1..196 whatever the clip's length (the released code; short clips are often fully controlled);
        ``mixed`` = that or, with probability 1/2, log-uniform over 1..m (sparse keyframes as often as
        dense trajectories).
    cond_drop: probability of training with the empty text (the CFG unconditional pass).
    """

    alpha: float = 0.1
    estimator: str = "gumbel"
    tau: float = 1.0
    mode: str = "mixed"
    density: str = "mixed"
    cond_drop: float = 0.1

    def __post_init__(self) -> None:
        checks = [
            (0.0 <= self.alpha <= 1.0, f"alpha must be in [0, 1]; got {self.alpha}"),
            (
                self.estimator in ESTIMATORS,
                f"unknown estimator '{self.estimator}'; allowed: {', '.join(ESTIMATORS)}",
            ),
            (self.tau > 0, f"tau must be positive; got {self.tau}"),
            (
                self.mode in CONTROL_MODES,
                f"unknown control mode '{self.mode}'; allowed: {', '.join(CONTROL_MODES)}",
            ),
            (self.density in DENSITIES, f"unknown density '{self.density}'; allowed: {', '.join(DENSITIES)}"),
            (0.0 <= self.cond_drop < 1.0, f"cond_drop must be in [0, 1); got {self.cond_drop}"),
        ]
        for ok, message in checks:
            if not ok:
                raise ControlMMError(message)


# -- control masks ----------------------------------------------------------------------------------
def sample_control_mask(
    lengths: torch.Tensor,
    num_frames: int,
    joint_ids: tuple[int, ...],
    mode: str,
    density: str = "uniform",
    generator: torch.Generator | None = None,
) -> torch.Tensor:
    """Random control masks (B, num_frames, 22) bool for clips of ``lengths`` frames (the released
    code's training modes, step 2 of the module docstring).

    Frames are drawn among each clip's valid frames; see :class:`ControlTraining` for the modes.
    """
    b = len(lengths)
    mask = torch.zeros(b, num_frames, 22, dtype=torch.bool)
    # the draw happens on the generator's device (a CUDA generator cannot fill a CPU tensor)
    seed = int(
        torch.randint(
            0,
            2**31 - 1,
            (1,),
            generator=generator,
            device=generator.device if generator is not None else "cpu",
        )
    )
    rng = np.random.default_rng(seed)
    for i, m in enumerate(int(x) for x in lengths):
        m = max(1, min(m, num_frames))
        sample_mode = mode if mode != "mixed" else ("trajectory", "random", "cross")[rng.integers(3)]
        if sample_mode == "trajectory" and 0 not in joint_ids:
            sample_mode = "random"
        if sample_mode == "cross":
            pairs = m * len(joint_ids)
            n = _count(rng, pairs, density, scale=pairs)
            chosen = rng.choice(pairs, size=n, replace=False)
            frames, which = np.divmod(chosen, len(joint_ids))
            mask[i, torch.from_numpy(frames), torch.as_tensor([joint_ids[k] for k in which])] = True
            continue
        joint = 0 if sample_mode == "trajectory" else joint_ids[rng.integers(len(joint_ids))]
        n = _count(rng, m, density, scale=num_frames)
        frames = rng.choice(m, size=n, replace=False)
        mask[i, torch.from_numpy(frames), joint] = True
    return mask.to(lengths.device)


def _count(rng: np.random.Generator, available: int, density: str, scale: int) -> int:
    """How many of ``available`` items to control: round(U scale) in 1..available, or log-uniform."""
    if density == "mixed" and rng.random() < 0.5:
        n = int(math.floor(math.exp(rng.uniform(0.0, math.log(available + 1)))))
    else:
        n = int(round(rng.random() * scale))
    return max(1, min(n, available))


# -- the loss -------------------------------------------------------------------------------------
class ControlLoss(nn.Module):
    """Masked consistency training objective; only ``control``'s parameters are registered/trained."""

    def __init__(
        self,
        control: MotionControlModel,
        base: MaskTransformer,
        tokenizer: RVQVAE,
        normalizer: Normalizer,
        settings: ControlTraining,
    ) -> None:
        super().__init__()
        self.control = control
        self.frozen = _Frozen(base, tokenizer, normalizer)
        self.settings = settings

    def forward(
        self,
        ids: torch.Tensor,
        targets: torch.Tensor,
        cond: torch.Tensor,
        token_lengths: torch.Tensor,
        frame_lengths: torch.Tensor,
        generator: torch.Generator | None = None,
        hard_error: bool = False,
    ) -> tuple[torch.Tensor, dict[str, torch.Tensor]]:
        """Loss and metrics for base ids (B, N), target joints (B, 4N, 22, 3), text (B, text_dim).

        Returns (loss, metrics) with ``ce``, ``acc``, ``ctrl`` (L1, m) and, with ``hard_error``,
        ``hard_err_cm``: the mean joint error at controlled entries when the argmax tokens are decoded.
        """
        base, tokenizer = self.frozen.base, self.frozen.tokenizer
        s = self.settings
        device = ids.device
        b, n = ids.shape
        num_frames = targets.shape[1]
        valid = lengths_to_mask(token_lengths, n)
        ids = torch.where(valid, ids, base.pad_id)
        sigma = sample_control_mask(
            frame_lengths, num_frames, self.control.joint_ids, s.mode, s.density, generator
        ).to(device)
        # masking with the cosine schedule and BERT corruption (step 3 of the module docstring)
        ratio = cosine_schedule(torch.rand(b, device=device, generator=generator))
        num_masked = (n * ratio).round().clamp(min=1)
        order = torch.rand(b, n, device=device, generator=generator).argsort(dim=-1)
        masked = (order < num_masked[:, None]) & valid
        random_sub = masked & (torch.rand(b, n, device=device, generator=generator) < 0.1)
        random_ids = torch.randint(0, base.cfg.nb_code, (b, n), device=device, generator=generator)
        x_ids = torch.where(random_sub, random_ids, ids)
        mask_sub = masked & ~random_sub & (torch.rand(b, n, device=device, generator=generator) < 0.88)
        x_ids = torch.where(mask_sub, base.mask_id, x_ids)
        codebook = tokenizer.codebooks[0]
        with torch.no_grad():
            known = valid & (x_ids != base.mask_id)
            current = self.frozen.joints(estimate_latent(x_ids, codebook, known))
        ctrl_in = control_input(targets, sigma, current, self.control.joint_ids)
        if self.training and s.cond_drop > 0:
            keep = torch.rand(b, device=device, generator=generator) >= s.cond_drop
            cond = zero_samples(cond, keep)
        logits = self.control(base, x_ids, cond, ~valid, ctrl_in)
        labels = torch.where(valid, ids, base.mask_id)  # every non-pad position; mask_id = ignore
        ce, acc = token_loss_and_accuracy(logits, labels, ignore_index=base.mask_id)
        probs = token_probabilities(logits, s.estimator, s.tau, generator)
        latent = (probs @ codebook) * valid[..., None]
        joints = self.frozen.joints(latent)
        weight = sigma[..., None].to(joints.dtype)
        count = weight.sum().clamp(min=1.0) * 3
        ctrl = ((joints - targets).abs() * weight).sum() / count
        loss = s.alpha * ce + (1.0 - s.alpha) * ctrl
        metrics = {"loss": loss.detach(), "ce": ce.detach(), "acc": acc.detach(), "ctrl": ctrl.detach()}
        if hard_error:
            with torch.no_grad():
                hard = self.frozen.joints(codebook[logits.argmax(-1)] * valid[..., None])
                err = (hard - targets).norm(dim=-1)[sigma]
                metrics["hard_err_cm"] = 100.0 * err.mean()
        return loss, metrics


def token_probabilities(
    logits: torch.Tensor, estimator: str, tau: float = 1.0, generator: torch.Generator | None = None
) -> torch.Tensor:
    """Differentiable token choice (B, N, K) for the consistency loss.

    ``gumbel``: straight-through Gumbel-softmax (one-hot sample forward, softmax((l + g) / tau)
    gradient; Paper Eq. 3). ``softmax``: softmax(l / tau), the released code's expectation.
    """
    if estimator == "softmax":
        return torch.softmax(logits / tau, dim=-1)
    soft = torch.softmax((logits + gumbel_noise(logits, generator)) / tau, dim=-1)
    hard = F.one_hot(soft.argmax(-1), soft.shape[-1]).to(soft.dtype)
    return hard - soft.detach() + soft


class _Frozen:
    """The frozen parts, held outside the module tree (not trained, not in state dicts, not in DDP)."""

    def __init__(self, base: MaskTransformer, tokenizer: RVQVAE, normalizer: Normalizer) -> None:
        self.base, self.tokenizer, self.normalizer = base, tokenizer, normalizer

    def joints(self, latent: torch.Tensor) -> torch.Tensor:
        """Latent (B, N, code_dim) -> global joints (B, 4N, 22, 3) through the frozen decoder."""
        return features_to_joints(self.normalizer.denormalize(self.tokenizer.decode_latent(latent)))


# -- the stage ------------------------------------------------------------------------------------
class ControlStage(TextConditionedStage):
    """``controlmm train control``: the motion control model on the frozen tokenizer and transformer."""

    name = "control"
    requires = ("tokenizer", "transformer")
    best_metric = "val_loss"

    def __init__(self, ctx: StageContext) -> None:
        super().__init__(ctx)
        opts = dict(ctx.options)
        joints = opts.pop("joints", None) or ctx.config.control.joints
        if joints not in CONTROL_JOINT_SETS:
            raise ControlMMError(
                f"unknown control joints '{joints}'; allowed: {', '.join(CONTROL_JOINT_SETS)}"
            )
        self.settings = ControlTraining(**{k: v for k, v in opts.items() if v is not None})
        self._set_control_config(replace(ctx.config.control, joints=joints))
        self.base_transformer = ctx.trained_parts().transformer.eval()

    def _set_control_config(self, control: ControlConfig) -> None:
        """Use ``control`` for the branch (written to model.json by :meth:`create`)."""
        ctx = self.ctx
        if ctx.resume and control != ctx.config.control:
            raise ControlMMError(
                f"the checkpoint being resumed trains the '{ctx.config.control.joints}' control "
                f"model; --joints {control.joints} does not match (use --force to start over)"
            )
        ctx.config = replace(ctx.config, control=control)

    def create(self) -> None:
        """Record the control branch's configuration in model.json (the part is built from it)."""
        super().create()
        manifest = read_manifest(self.ctx.model_dir)
        manifest["config"]["control"] = asdict(self.ctx.config.control)
        write_manifest(self.ctx.model_dir, manifest)

    def build_model(self) -> nn.Module:
        return MotionControlModel(self.ctx.config).init_from_base(self.base_transformer)

    def loss_module(self, model: nn.Module) -> nn.Module:
        return ControlLoss(
            cast(MotionControlModel, model),
            self.base_transformer,
            self.tokenizer,
            self.ctx.normalizer,
            self.settings,
        )

    def targets(self, motion: torch.Tensor) -> torch.Tensor:
        """(B, T, 263) normalised motions -> (B, T, 22, 3) global joints (the control targets)."""
        return features_to_joints(self.ctx.normalizer.denormalize(motion))

    def prepare(self, batch: Any) -> tuple:
        motion, lengths, caption = batch
        device = self.ctx.device
        motion = motion.to(device, non_blocking=True)
        with torch.no_grad():
            ids = self.tokens(motion)[..., 0]
            targets = self.targets(motion)
        lengths = lengths.to(device)
        return ids, targets, self.text_vectors[caption.to(device)], lengths // self.unit, lengths

    @torch.no_grad()
    def validate(self, model: nn.Module) -> dict[str, float]:
        gen = torch.Generator(self.ctx.device).manual_seed(VALIDATION_SEED + 4)
        loss_module = self.loss_module(model).eval()
        sums: dict[str, float] = {}
        n = 0
        for batch in self.val_batches():
            _, metrics = loss_module(*batch, generator=gen, hard_error=True)
            size = len(batch[0])
            for k, v in metrics.items():
                sums[k] = sums.get(k, 0.0) + float(v) * size
            n += size
        return {f"val_{k}": v / n for k, v in sums.items()}

    def record(self) -> dict[str, Any]:
        return super().record() | {
            "control": asdict(self.ctx.config.control),
            "consistency_training": asdict(self.settings),
        }
