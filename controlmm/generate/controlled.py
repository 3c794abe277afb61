"""Text + spatial control (+ any loss terms) -> motion: ControlMM generation with editing.

```python
from controlmm.control import ControlSpec
from controlmm.generate import generate_controlled, load_model

model = load_model()                                   # the embedded default (with its control model)
spec = ControlSpec.load("spec.json")
out = generate_controlled(model, "a person walks forward", control=spec, preset="accurate", seed=0)
out.motions[0].joints                                  # (T, 22, 3)
out.errors[0]                                          # (K,) metres, one per constraint of the spec
out.records[0].codebook_steps                          # editing steps used
```

Per batch (ControlMM paper §3.3 and A.2-A.4; docs/control.md):

1. iterative masked decoding of the base layer (10 iterations, CFG 4). With the motion control model,
   each iteration's logits come from the base transformer steered by the control branch, whose input is
   built from the targets and the motion the committed tokens imply (masked positions: ``mask_emb_vq``);
2. logits editing of every iteration's logits before its tokens are sampled (``logits_steps``);
3. residual layers predicted from the final base ids (arg-max, as the official code), so they always
   match the edited base tokens;
4. codebook editing of the summed decoder latent (``codebook_steps``);
5. decoding, recovery of the joints, and the error of every constraint.

Every editor minimises the same :class:`~controlmm.editing.objective.Objective`: the control loss of
the targets plus any extra :class:`~controlmm.control.terms.LossTerm` (obstacle SDF losses, floor and
simulation-feedback losses...) on the joints (B, T, 22, 3) of frames 0..T-1, and stops early once every
constraint is within the tolerance (1 cm) and every other term is ~0.
"""

from __future__ import annotations

import math
import secrets
import time
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
import torch
import torch.nn.functional as F
from tqdm import tqdm

from controlmm.control.spec import ControlSpec
from controlmm.control.terms import LossTerm
from controlmm.editing.codebook_editing import codebook_editing
from controlmm.editing.foot_contact import foot_contact_run
from controlmm.editing.logits_editing import logits_editing
from controlmm.editing.objective import Objective
from controlmm.editing.presets import EditingConfig, editing_preset
from controlmm.errors import ControlMMError, ShapeError
from controlmm.frames import HumanToWorld
from controlmm.generate.api import frames_for, latent_to_features
from controlmm.generate.masked_decoding import DecodeOptions, DecodeState, LogitsFn, masked_decode
from controlmm.generate.residual_decoding import residual_decode
from controlmm.models.model_dir import MotionModel
from controlmm.models.motion_control_model import MotionControlModel, control_input, estimate_latent
from controlmm.motion.container import Motion
from controlmm.motion.recover import features_to_joints
from controlmm.motion.skeleton import FPS, JOINT_NAMES, MAX_FRAMES, NUM_JOINTS
from controlmm.seeds import check_seed
from controlmm.text.base import check_texts

POSITION_DIMS = 67  # feature dims R(.) reads: root velocity/height and the RIC positions


@dataclass
class EditingRecord:
    """What the control model and the editors did for one motion."""

    preset: str
    control_model: bool
    budget: dict[str, Any] = field(
        default_factory=dict
    )  # step budgets, optimiser and tolerances of the preset
    logits_steps: list[int] = field(default_factory=list)  # per decoding iteration
    codebook_steps: int = 0
    contact_kept: bool = False  # the foot-contact run's latent was kept (EditingConfig.contact_steps > 0)
    converged: bool = False  # every constraint within tolerance and every other term ~0 at the end
    max_error: float = 0.0  # worst constraint error (m) of the final motion
    losses: dict[str, float] = field(default_factory=dict)  # final value of every loss term
    seconds: float = 0.0  # wall time of the batch this motion was generated in, divided by its size
    cpu_seconds: float = 0.0  # CPU time of this process (all threads) for the batch, divided by its size
    phases: dict[str, float] = field(default_factory=dict)  # wall s per stage (text, decoding, editors)

    @property
    def total_steps(self) -> int:
        return int(sum(self.logits_steps)) + int(self.codebook_steps)

    def to_json(self) -> dict[str, Any]:
        return {
            "preset": self.preset,
            "control_model": self.control_model,
            "budget": dict(self.budget),
            "logits_steps": list(self.logits_steps),
            "codebook_steps": int(self.codebook_steps),
            "contact_kept": bool(self.contact_kept),
            "converged": bool(self.converged),
            "max_error_m": float(self.max_error),
            "losses": dict(self.losses),
            "seconds": round(self.seconds, 3),
            "cpu_seconds": round(self.cpu_seconds, 3),
            "phases_s": {k: round(v, 3) for k, v in self.phases.items()},
        }


@dataclass
class ControlledGeneration:
    """Motions with the error of every constraint and the editing record of each.

    ``errors[i]`` (K_i,) metres: one per constraint of spec i, in spec order (with ``targets``/``mask``
    input: one per controlled (frame, joint) entry in (frame, joint) order, listed in ``constraints[i]``).
    """

    motions: list[Motion]
    errors: list[np.ndarray]
    constraints: list[list[tuple[int, int]]]  # (joint, frame) of each error
    records: list[EditingRecord]
    texts: list[str]
    frames: list[int]
    seed: int
    ids: list[torch.Tensor] = field(default_factory=list)  # (N_i, q) token ids of each motion

    @property
    def motion(self) -> Motion:
        return self.motions[0]


def generate_controlled(
    model: MotionModel,
    text: str | Sequence[str],
    *,
    control: ControlSpec | Sequence[ControlSpec | None] | None = None,
    targets: np.ndarray | torch.Tensor | None = None,
    mask: np.ndarray | torch.Tensor | None = None,
    terms: Sequence[LossTerm] = (),
    preset: str | EditingConfig = "accurate",
    seconds: float | Sequence[float] | None = None,
    frames: int | Sequence[int] | None = None,
    seed: int | None = None,
    transform: HumanToWorld | None = None,
    options: DecodeOptions | None = None,
    residual_cfg_scale: float = 5.0,
    batch_size: int = 16,
    progress: bool = False,
) -> ControlledGeneration:
    """Generate one motion per prompt meeting spatial constraints and any extra loss terms.

    Args:
        model: a loaded model; its ``control`` part (``control.pt``) is used when present and the preset
            asks for it (otherwise editing alone does the work).
        text: a prompt or a list of prompts.
        control: a :class:`ControlSpec` for every prompt, or one per prompt (None = unconstrained).
        targets, mask: instead of ``control``: target joints (T, 22, 3) or (B, T, 22, 3) in the human
            frame and a bool mask (T, 22) or (B, T, 22) of the controlled entries.
        terms: extra loss terms on the joints (B, T, 22, 3) (human frame, frames 0..T-1 of each
            motion), e.g. obstacle SDF losses; minimised by both editors together with the control loss.
            Prompts of different lengths are then generated in separate batches (each term sees
            exactly its motion's frames).
        preset: ``fast``, ``medium``, ``accurate`` or an :class:`EditingConfig`.
        seconds / frames: motion lengths (40..196 frames). Default: the frame count T of ``targets``;
            with a spec 6 s, or longer to cover the last constrained frame (up to 196).
        seed: reproducibility (None: random, recorded).
        transform: placement of the human in the world, for ``coords: world`` specs.
        options: base-layer sampling (default ``DecodeOptions()``: the MoMask defaults).
        batch_size: prompts decoded together.

    Returns:
        :class:`ControlledGeneration`.
    """
    texts = check_texts(text)
    if not texts:
        raise ControlMMError("no text given")
    options = DecodeOptions() if options is None else options
    config = editing_preset(preset)
    preset_name = config.name
    count = len(texts)
    specs = _specs(control, count)
    dense_t, dense_m, dense_frames = _dense_targets(targets, mask, count)
    if specs is not None and dense_t is not None:
        raise ControlMMError("give the control as a ControlSpec or as targets + mask, not both")
    if dense_t is not None and seconds is None and frames is None:
        frames = dense_frames  # targets (T, 22, 3) describe a motion of T frames
    lengths = _lengths(count, seconds, frames, specs, dense_m)
    pairs: list[list[tuple[int, int]]] = []
    full_t = np.zeros((count, MAX_FRAMES, NUM_JOINTS, 3), dtype=np.float32)
    full_m = np.zeros((count, MAX_FRAMES, NUM_JOINTS), dtype=bool)
    for i, f in enumerate(lengths):
        spec = specs[i] if specs is not None else None
        if spec is not None:
            t, m = spec.dense(f, transform)
            full_t[i, :f], full_m[i, :f] = t, m
            pairs.append([(c.joint, c.frame) for c in spec.constraints])
        elif dense_t is not None and dense_m is not None:
            if dense_m[i, f:].any():
                frame = int(np.argwhere(dense_m[i, f:])[0][0]) + f
                raise ControlMMError(
                    f"a controlled entry at frame {frame} is outside the motion (frames 0..{f - 1})"
                )
            full_t[i, :f], full_m[i, :f] = dense_t[i, :f], dense_m[i, :f]
            pairs.append([(int(j), int(t)) for t, j in np.argwhere(dense_m[i, :f])])
        else:
            pairs.append([])
    if options.iterations < 1:
        raise ControlMMError(f"iterations must be at least 1; got {options.iterations}")
    seed = secrets.randbits(31) if seed is None else check_seed(seed)
    generator = torch.Generator(device=model.device).manual_seed(int(seed))
    chunks = _chunks(lengths, batch_size, by_length=bool(terms))
    results: dict[int, tuple[np.ndarray, np.ndarray, EditingRecord, torch.Tensor]] = {}
    bar = tqdm(total=count, desc="generate", unit="motion", disable=not progress, leave=False)
    for chunk in chunks:
        chunk_joints, chunk_features, chunk_records, chunk_tokens = _generate_chunk(
            model,
            [texts[i] for i in chunk],
            [lengths[i] for i in chunk],
            torch.from_numpy(full_t[chunk]),
            torch.from_numpy(full_m[chunk]),
            terms,
            config,
            preset_name,
            options,
            residual_cfg_scale,
            generator,
        )
        for k, i in enumerate(chunk):
            results[i] = (chunk_joints[k], chunk_features[k], chunk_records[k], chunk_tokens[k])
        bar.update(len(chunk))
    bar.close()
    motions, errors, records, ids = [], [], [], []
    for i in range(count):
        joints, features, record, tokens = results[i]
        f = lengths[i]
        err = np.array(
            [np.linalg.norm(joints[fr, j] - full_t[i, fr, j]) for j, fr in pairs[i]], dtype=np.float64
        )
        meta = {
            "seed": int(seed),
            "index": i,
            "model": str(model.directory or ""),
            "preset": model.config.preset,
            "frames": f,
            "cfg_scale": options.cfg_scale,
            "iterations": options.iterations,
            "control": _control_metadata(specs[i] if specs else None, pairs[i], err, record, preset_name),
        }
        extras = {}
        if pairs[i]:
            extras = {
                "control_mask": full_m[i, :f].copy(),
                "control_targets": full_t[i, :f].copy(),
                "control_errors": err.astype(np.float32),
            }
        motions.append(
            Motion(
                joints=joints[:f],
                fps=float(FPS),
                features=features[:f],
                text=texts[i],
                metadata=meta,
                extras=extras,
            )
        )
        errors.append(err)
        records.append(record)
        ids.append(tokens)
    return ControlledGeneration(
        motions=motions,
        errors=errors,
        constraints=pairs,
        records=records,
        texts=texts,
        frames=lengths,
        seed=int(seed),
        ids=ids,
    )


# -- one batch --------------------------------------------------------------------------------------
def _generate_chunk(
    model: MotionModel,
    texts: list[str],
    lengths: list[int],
    targets: torch.Tensor,
    mask: torch.Tensor,
    terms: Sequence[LossTerm],
    config: EditingConfig,
    preset_name: str,
    options: DecodeOptions,
    residual_cfg_scale: float,
    generator: torch.Generator,
) -> tuple[list[np.ndarray], list[np.ndarray], list[EditingRecord], list[torch.Tensor]]:
    """Decode, edit and evaluate one batch: per motion its joints (T_span, 22, 3) and features
    (T_span, 263) over the frames the decoder produces, its :class:`EditingRecord` and its token ids
    (N_i, q)."""
    started, cpu_started = time.perf_counter(), time.process_time()
    device = model.device
    unit = model.config.tokenizer.downsample
    token_lengths = torch.tensor([math.ceil(f / unit) for f in lengths], device=device)
    n = int(token_lengths.max())
    span = n * unit  # frames the decoder produces
    t_max = max(lengths)
    targets, mask = targets[:, :span].to(device), mask[:, :span].to(device)
    objective = Objective(
        targets=targets[:, :t_max],
        mask=mask[:, :t_max],
        terms=terms,
        tolerance=config.tolerance,
        loss_tolerance=config.loss_tolerance,
        hinge_weight=config.hinge_weight,
        difference_weight=config.difference_weight,
    )
    phase = {
        "text": 0.0,
        "decoding": 0.0,
        "logits_editing": 0.0,
        "codebook_editing": 0.0,
        "foot_contact": 0.0,
    }
    mark = time.perf_counter()
    cond = model.encode_text(texts)
    phase["text"] = time.perf_counter() - mark
    tokenizer, transformer = model.tokenizer, model.transformer
    codebook = tokenizer.codebooks[0]
    control = model.parts.get("control") if config.control_model else None
    if control is not None and not isinstance(control, MotionControlModel):
        raise ControlMMError(
            f"the model's control part is a {type(control).__name__}, not a MotionControlModel"
        )
    b = len(texts)
    logit_steps: list[torch.Tensor] = []

    def decode(latent: torch.Tensor) -> torch.Tensor:
        return latent_to_positions(model, latent)[:, :t_max]

    control_logits: LogitsFn | None = None
    if control is not None and bool(mask.any()):

        def steered_logits(ids: torch.Tensor, state: DecodeState) -> torch.Tensor:
            known = ~state.is_mask & ~state.padding_mask
            current = latent_to_positions(model, estimate_latent(ids, codebook, known))
            ctrl_in = control_input(targets, mask, current, control.joint_ids)
            return control.cfg_logits(transformer, ids, cond, state.padding_mask, ctrl_in, options.cfg_scale)

        control_logits = steered_logits
    use_control = control_logits is not None

    logits_objective = replace(
        objective,
        tolerance=max(config.logits_tolerance, config.tolerance),
        stop_on="mean",
        hinge_weight=0.0,
        difference_weight=0.0,
    )
    warm_config = replace(config, logits_patience=config.logits_warm_patience)

    carried: list[torch.Tensor] = []  # the previous iteration's edit (edited - predicted logits)

    def edit_logits(logits: torch.Tensor, state: DecodeState) -> torch.Tensor:
        started = time.perf_counter()
        known = ~state.is_mask & ~state.padding_mask
        fixed = torch.where(known[..., None], codebook[torch.where(known, state.ids, 0)], 0.0)
        start, settings = logits, config
        if carried:  # warm start: the positions still masked keep the edit the last iteration found
            start = logits + torch.where(state.is_mask[..., None], carried[-1], 0.0)
            settings = warm_config
        with torch.enable_grad():
            outcome = logits_editing(
                start, state.is_mask, fixed, codebook, decode, logits_objective, settings, generator
            )
        if config.logits_warm_start:
            carried[:] = [outcome.param - logits]
        logit_steps.append(outcome.steps)
        phase["logits_editing"] += time.perf_counter() - started
        return outcome.param

    editing = objective.active
    mark = time.perf_counter()
    base = masked_decode(
        transformer,
        cond,
        token_lengths,
        options,
        generator,
        logits_fn=control_logits,
        logits_hook=edit_logits if editing and config.logits_steps > 0 else None,
    )
    ids = base.ids[..., None]
    if model.residual is not None:
        ids, _ = residual_decode(
            model.residual,
            base.ids,
            cond,
            token_lengths,
            residual_cfg_scale,
            temperature=0.0,
            topk=None,
            generator=generator,
        )
    with torch.no_grad():
        latent = tokenizer.ids_to_latent(ids)
    phase["decoding"] += time.perf_counter() - mark - phase["logits_editing"]
    codebook_steps = torch.zeros(b, dtype=torch.long)
    contact_kept = torch.zeros(b, dtype=torch.bool)
    if editing and config.codebook_steps > 0:
        mark = time.perf_counter()
        with torch.enable_grad():
            outcome = codebook_editing(latent, decode, objective, config)
        latent, codebook_steps = outcome.param, outcome.steps.cpu()
        phase["codebook_editing"] = time.perf_counter() - mark
        mark = time.perf_counter()
        latent, kept = foot_contact_run(latent, decode, objective, config)
        contact_kept = kept.cpu()
        phase["foot_contact"] = time.perf_counter() - mark
    mark = time.perf_counter()
    with torch.no_grad():
        features = latent_to_features(model, latent)
        joints = features_to_joints(features)
        values = {k: v.cpu() for k, v in objective.term_values(joints[:, :t_max]).items()}
        _, done, max_err = objective.evaluate(joints[:, :t_max])
    phase["decoding"] += time.perf_counter() - mark
    seconds = (time.perf_counter() - started) / b
    cpu_seconds = (time.process_time() - cpu_started) / b
    budget = {
        "logits_steps": config.logits_steps,
        "codebook_steps": config.codebook_steps,
        "codebook_optimizer": config.codebook_optimizer,
        "tolerance_m": config.tolerance,
        "logits_tolerance_m": config.logits_tolerance,
        "contact_steps": config.contact_steps,
    }
    records = []
    for i in range(b):
        records.append(
            EditingRecord(
                preset=preset_name,
                control_model=use_control,
                budget=budget,
                logits_steps=[int(s[i]) for s in logit_steps],
                codebook_steps=int(codebook_steps[i]),
                contact_kept=bool(contact_kept[i]),
                converged=bool(done[i]) if editing else True,
                max_error=float(max_err[i]),
                losses={k: float(v[i]) for k, v in values.items()},
                seconds=seconds,
                cpu_seconds=cpu_seconds,
                phases={k: v / b for k, v in phase.items() if v > 0},
            )
        )
    joints_np = joints.cpu().numpy()
    features_np = features.cpu().numpy()
    tokens = [ids[i, : int(token_lengths[i])].cpu() for i in range(b)]
    return list(joints_np), list(features_np), records, tokens


def latent_to_positions(model: MotionModel, latent: torch.Tensor) -> torch.Tensor:
    """Latent (B, N, code_dim) -> global joints (B, 4N, 22, 3), computing only the decoder outputs R(.) reads.

    Same values as :func:`~controlmm.generate.latent_to_joints`; the last decoder convolution is
    evaluated for the first 67 feature dims only (the rest never reach the joints), which saves time
    in the editing loops.
    """
    decoder = model.tokenizer.decoder
    x = latent.permute(0, 2, 1)
    for layer in decoder.model[:-1]:
        x = layer(x)
    last = decoder.model[-1]
    y = F.conv1d(
        x,
        last.weight[:POSITION_DIMS],
        last.bias[:POSITION_DIMS],
        stride=last.stride,
        padding=last.padding,
        dilation=last.dilation,
    ).permute(0, 2, 1)
    norm = model.normalizer
    mean = torch.as_tensor(norm.mean[:POSITION_DIMS], dtype=y.dtype, device=y.device)
    std = torch.as_tensor(norm.std[:POSITION_DIMS], dtype=y.dtype, device=y.device)
    positions = y * std + mean
    rest = positions.new_zeros(positions.shape[:-1] + (norm.mean.shape[0] - POSITION_DIMS,))
    return features_to_joints(torch.cat([positions, rest], dim=-1))


def decode_latent(model: MotionModel, latent: torch.Tensor, frames: int) -> tuple[np.ndarray, np.ndarray]:
    """(joints (T, 22, 3), features (T, 263)) numpy of the first ``frames`` frames of a latent
    (1, N, code_dim)."""
    with torch.no_grad():
        features = latent_to_features(model, latent)[:, :frames]
        joints = features_to_joints(features)
    return joints[0].cpu().numpy(), features[0].cpu().numpy()


def edit_latent(
    model: MotionModel, latent: torch.Tensor, frames: int, objective: Objective, config: EditingConfig
) -> tuple[torch.Tensor, dict[str, Any]]:
    """Codebook editing of one motion's decoder latent (1, N, code_dim) so that its first ``frames``
    frames meet ``objective``, outside the decoding loop (the plan's feedback rounds, timeline passes).

    Returns the edited latent and a record: ``steps``, ``converged``, ``max_error_m``, ``contact_kept``
    (the foot-contact run's latent was kept, :mod:`controlmm.editing.foot_contact`), the final value
    of every loss term (``losses``) and the wall seconds of each run (``seconds``: ``codebook_editing``,
    ``foot_contact``).
    """
    if not objective.active or config.codebook_steps == 0:
        return latent, {"steps": 0, "converged": True, "max_error_m": 0.0, "losses": {}, "seconds": {}}

    def decode(z: torch.Tensor) -> torch.Tensor:
        return latent_to_positions(model, z)[:, :frames]

    started = time.perf_counter()
    with torch.enable_grad():
        outcome = codebook_editing(latent, decode, objective, config)
    middle = time.perf_counter()
    edited, kept = foot_contact_run(outcome.param.detach(), decode, objective, config)
    with torch.no_grad():
        joints = decode(edited)
        values = objective.term_values(joints)
        _, done, max_err = objective.evaluate(joints)
    seconds = {"codebook_editing": middle - started, "foot_contact": time.perf_counter() - middle}
    return edited, {
        "steps": int(outcome.steps[0]),
        "converged": bool(done[0]),
        "max_error_m": float(max_err[0]),
        "contact_kept": bool(kept[0]),
        "losses": {k: float(v[0]) for k, v in values.items()},
        "seconds": seconds,
    }


# -- inputs -----------------------------------------------------------------------------------------
def _specs(
    control: ControlSpec | Sequence[ControlSpec | None] | None, count: int
) -> list[ControlSpec | None] | None:
    if control is None:
        return None
    if isinstance(control, ControlSpec):
        return [control] * count
    specs = list(control)
    if len(specs) != count:
        raise ControlMMError(f"{len(specs)} control specs given for {count} prompts")
    for s in specs:
        if s is not None and not isinstance(s, ControlSpec):
            raise ControlMMError(f"control must be ControlSpec objects (or None); got {type(s).__name__}")
    return specs


def _dense_targets(
    targets: np.ndarray | torch.Tensor | None, mask: np.ndarray | torch.Tensor | None, count: int
) -> tuple[np.ndarray | None, np.ndarray | None, int]:
    """Targets and mask padded to 196 frames, and the frame count they were given with."""
    if targets is None and mask is None:
        return None, None, 0
    if targets is None or mask is None:
        raise ControlMMError("targets and mask go together")
    t = targets.detach().cpu().numpy() if isinstance(targets, torch.Tensor) else np.asarray(targets)
    m = mask.detach().cpu().numpy() if isinstance(mask, torch.Tensor) else np.asarray(mask)
    if t.ndim == 3:
        t = np.broadcast_to(t, (count,) + t.shape)
    if m.ndim == 2:
        m = np.broadcast_to(m, (count,) + m.shape)
    if t.ndim != 4 or t.shape[0] != count or t.shape[2:] != (NUM_JOINTS, 3):
        raise ShapeError(
            f"targets must have shape (T, 22, 3) or ({count}, T, 22, 3); got {np.shape(targets)}"
        )
    if m.shape != t.shape[:3]:
        raise ShapeError(f"mask must have shape {t.shape[1:3]} or {t.shape[:3]}; got {np.shape(mask)}")
    if t.shape[1] > MAX_FRAMES:
        raise ShapeError(f"targets cover {t.shape[1]} frames; at most {MAX_FRAMES} are allowed")
    m = m.astype(bool)
    if not np.all(np.isfinite(t[m])):
        raise ShapeError("controlled targets contain NaN/inf")
    padded_t = np.zeros((count, MAX_FRAMES, NUM_JOINTS, 3), dtype=np.float32)
    padded_m = np.zeros((count, MAX_FRAMES, NUM_JOINTS), dtype=bool)
    padded_t[:, : t.shape[1]] = np.where(m[..., None], t, 0.0)
    padded_m[:, : t.shape[1]] = m
    return padded_t, padded_m, int(t.shape[1])


def _lengths(
    count: int,
    seconds: float | Sequence[float] | None,
    frames: int | Sequence[int] | None,
    specs: list[ControlSpec | None] | None,
    dense_m: np.ndarray | None,
) -> list[int]:
    """Lengths from seconds/frames, or the default 6 s stretched to cover the last constrained frame."""
    if seconds is not None or frames is not None:
        return frames_for(count, seconds, frames)
    default = frames_for(count)
    last = [-1] * count
    if specs is not None:
        last = [s.last_frame if s is not None else -1 for s in specs]
    elif dense_m is not None:
        last = [int(np.flatnonzero(m.any(-1)).max()) if m.any() else -1 for m in dense_m]
    out = []
    for d, lf in zip(default, last, strict=True):
        if lf >= MAX_FRAMES:
            raise ControlMMError(
                f"a constraint at frame {lf} is beyond the longest motion (frames 0..{MAX_FRAMES - 1})"
            )
        out.append(max(d, lf + 1))
    return out


def _chunks(lengths: list[int], batch_size: int, by_length: bool) -> list[list[int]]:
    """Indices in batches; with ``by_length`` every batch holds one length only."""
    if batch_size < 1:
        raise ControlMMError(f"batch_size must be at least 1; got {batch_size}")
    order = list(range(len(lengths)))
    if not by_length:
        return [order[i : i + batch_size] for i in range(0, len(order), batch_size)]
    groups: dict[int, list[int]] = {}
    for i in order:
        groups.setdefault(lengths[i], []).append(i)
    return [g[i : i + batch_size] for g in groups.values() for i in range(0, len(g), batch_size)]


def _control_metadata(
    spec: ControlSpec | None,
    pairs: list[tuple[int, int]],
    errors: np.ndarray,
    record: EditingRecord,
    preset: str,
) -> dict[str, Any]:
    data: dict[str, Any] = {
        "preset": preset,
        "editing": record.to_json(),
        "constraints": [
            {"joint": JOINT_NAMES[j], "frame": f, "error_cm": round(100 * float(e), 4)}
            for (j, f), e in zip(pairs, errors, strict=True)
        ],
    }
    if spec is not None:
        data["spec"] = spec.source if spec.source else spec.to_dict()
    if len(errors):
        data["max_error_cm"] = round(100 * float(errors.max()), 4)
        data["mean_error_cm"] = round(100 * float(errors.mean()), 4)
    return data
