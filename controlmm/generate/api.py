"""Text -> motion with a loaded model: lengths, seeds, batching, decoding to motions."""

from __future__ import annotations

import math
import numbers
import secrets
from collections.abc import Sequence
from dataclasses import dataclass, field

import torch

from controlmm.errors import ControlMMError
from controlmm.generate.masked_decoding import DecodeOptions, masked_decode
from controlmm.generate.residual_decoding import residual_decode
from controlmm.generate.token_view import token_view_logits_fn
from controlmm.models.model_dir import MotionModel
from controlmm.motion.container import Motion
from controlmm.motion.recover import features_to_joints
from controlmm.motion.skeleton import FPS, MAX_FRAMES, MIN_FRAMES
from controlmm.seeds import check_seed
from controlmm.text.base import check_texts


def frames_for(
    count: int, seconds: float | Sequence[float] | None = None, frames: int | Sequence[int] | None = None
) -> list[int]:
    """Motion lengths in frames for ``count`` prompts from seconds (x 20 fps, rounded) or frames.

    Allowed: 40..196 frames (2.0..9.8 s), the range the models are trained on. Default: 6 s.
    """
    if seconds is not None and frames is not None:
        raise ControlMMError("give the length in seconds or in frames, not both")
    if frames is None:
        secs = [6.0] * count if seconds is None else seconds
        secs = [secs] * count if isinstance(secs, (int, float)) else list(secs)
        for s in secs:
            if not isinstance(s, (int, float)) or not math.isfinite(s):
                raise ControlMMError(f"length {s!r} s is not a number")
        frames = [int(round(float(s) * FPS)) for s in secs]
        unit = "s"
    else:
        frames = [frames] * count if isinstance(frames, (int, numbers.Integral)) else list(frames)
        unit = "frames"
    if len(frames) != count:
        raise ControlMMError(f"{len(frames)} lengths given for {count} prompts")
    for f in frames:
        if isinstance(f, bool) or not isinstance(f, numbers.Integral) or not MIN_FRAMES <= f <= MAX_FRAMES:
            shown = f"{f / FPS:g} s ({f} frames)" if unit == "s" and isinstance(f, int) else f"{f} frames"
            raise ControlMMError(
                f"length {shown} is out of range; allowed {MIN_FRAMES}..{MAX_FRAMES} frames "
                f"({MIN_FRAMES / FPS:g}..{MAX_FRAMES / FPS:g} s at {FPS} fps)"
            )
    return [int(f) for f in frames]


def latent_to_features(model: MotionModel, latent: torch.Tensor) -> torch.Tensor:
    """Decoder latent (B, N, code_dim) -> denormalised features (B, 4N, 263); differentiable."""
    return model.normalizer.denormalize(model.tokenizer.decode_latent(latent))


def latent_to_joints(model: MotionModel, latent: torch.Tensor) -> torch.Tensor:
    """Decoder latent (B, N, code_dim) -> global joints (B, 4N, 22, 3), human frame; differentiable."""
    return features_to_joints(latent_to_features(model, latent))


@dataclass
class GenerationResult:
    """Motions plus every intermediate a caller may want to inspect or edit.

    ``ids`` (B, N, q) hold -1 at pads; ``base_logits`` (B, N, K) are the last iteration's base-layer
    logits; ``residual_logits`` one (B, N, K+1) tensor per residual layer; ``latent`` (B, N, code_dim)
    the decoder input (sum of the codebook vectors of ``ids``). Token n covers frames 4n..4n+3.
    """

    motions: list[Motion]
    texts: list[str]
    frames: list[int]
    seed: int
    ids: torch.Tensor
    base_logits: torch.Tensor
    residual_logits: list[torch.Tensor] = field(default_factory=list)
    latent: torch.Tensor | None = None

    @property
    def motion(self) -> Motion:
        return self.motions[0]


@torch.no_grad()
def generate(
    model: MotionModel,
    text: str | Sequence[str],
    seconds: float | Sequence[float] | None = None,
    frames: int | Sequence[int] | None = None,
    seed: int | None = None,
    options: DecodeOptions | None = None,
    use_residual: bool = True,
    residual_cfg_scale: float = 5.0,
    residual_temperature: float = 1.0,
    residual_topk: float | None = 0.9,
    residual_layers: int | None = None,
    batch_size: int = 64,
    token_view: bool = True,
) -> GenerationResult:
    """Generate one motion per prompt.

    Args:
        model: from :func:`~controlmm.models.load_model`.
        text: a prompt or a list of prompts.
        seconds / frames: length per prompt (scalar or list); default 6 s; 40..196 frames.
        seed: makes the result reproducible (None: a random seed, recorded in the metadata).
        options: base-layer decoding (default ``DecodeOptions()``: iterations 10, CFG 4, temperature 1,
            top-k 0.9).
        use_residual: add the residual layers when the model has a residual transformer.
        residual_layers: how many residual layers to predict (default all, Q - 1).
        batch_size: prompts decoded together.
        token_view: when the model has a token-state transformer (``config.token_view``), mix its
            log-probabilities with the sentence-vector transformer's (:mod:`controlmm.generate.token_view`);
            False: the sentence-vector transformer alone.
    """
    options = DecodeOptions() if options is None else options
    texts = check_texts(text)
    if not texts:
        raise ControlMMError("no text given")
    lengths = frames_for(len(texts), seconds, frames)
    if options.iterations < 1:
        raise ControlMMError(f"iterations must be at least 1; got {options.iterations}")
    max_layers = model.config.tokenizer.num_quantizers - 1
    if residual_layers is not None and not 0 <= residual_layers <= max_layers:
        raise ControlMMError(f"residual_layers must be in 0..{max_layers}; got {residual_layers}")
    seed = secrets.randbits(31) if seed is None else check_seed(seed)
    device = model.device
    generator = torch.Generator(device=device).manual_seed(int(seed))
    unit = model.config.tokenizer.downsample
    residual = model.residual if use_residual else None
    motions, id_chunks, base_chunks, res_chunks, latent_chunks = [], [], [], [], []
    for start in range(0, len(texts), batch_size):
        chunk_texts = texts[start : start + batch_size]
        chunk_frames = lengths[start : start + batch_size]
        cond, states = (
            model.encode_text_views(chunk_texts) if token_view else (model.encode_text(chunk_texts), None)
        )
        token_lengths = torch.tensor([math.ceil(f / unit) for f in chunk_frames], device=device)
        views = token_view_logits_fn(model, chunk_texts, options.cfg_scale, states) if token_view else None
        base = masked_decode(model.transformer, cond, token_lengths, options, generator, logits_fn=views)
        res_logits: list[torch.Tensor] = []
        if residual is not None:
            ids, res_logits = residual_decode(
                residual,
                base.ids,
                cond,
                token_lengths,
                residual_cfg_scale,
                residual_temperature,
                residual_topk,
                generator,
                residual_layers,
            )
        else:
            ids = base.ids[..., None]
        latent = model.tokenizer.ids_to_latent(ids)
        features = latent_to_features(model, latent)
        joints = features_to_joints(features)
        for i, (prompt, f) in enumerate(zip(chunk_texts, chunk_frames, strict=True)):
            meta = {
                "seed": int(seed),
                "index": start + i,
                "model": str(model.directory or ""),
                "preset": model.config.preset,
                "cfg_scale": options.cfg_scale,
                "temperature": options.temperature,
                "topk": options.topk,
                "iterations": options.iterations,
                "residual": residual is not None,
                "residual_layers": residual_layers,
                "frames": f,
                "token_view": views is not None,
            }
            motions.append(
                Motion(
                    joints=joints[i, :f].cpu().numpy(),
                    fps=float(FPS),
                    features=features[i, :f].cpu().numpy(),
                    text=prompt,
                    metadata=meta,
                )
            )
        id_chunks.append(ids)
        base_chunks.append(base.logits)
        res_chunks.append(res_logits)
        latent_chunks.append(latent)
    return GenerationResult(
        motions=motions,
        texts=texts,
        frames=lengths,
        seed=int(seed),
        ids=_cat_padded(id_chunks, -1),
        base_logits=_cat_padded(base_chunks, 0.0),
        residual_logits=[_cat_padded([c[q] for c in res_chunks], 0.0) for q in range(len(res_chunks[0]))],
        latent=_cat_padded(latent_chunks, 0.0),
    )


def _cat_padded(chunks: list[torch.Tensor], value: float) -> torch.Tensor:
    """Concatenate along the batch, padding the token axis (dim 1) to the longest chunk."""
    n = max(c.shape[1] for c in chunks)
    padded = []
    for c in chunks:
        if c.shape[1] < n:
            pad_shape = (c.shape[0], n - c.shape[1]) + tuple(c.shape[2:])
            c = torch.cat([c, torch.full(pad_shape, value, dtype=c.dtype, device=c.device)], dim=1)
        padded.append(c)
    return torch.cat(padded)
