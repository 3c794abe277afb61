"""The model directory: what training writes and what generation loads (contract 5).

Layout::

    MODEL_DIR/model.json       format name and version, preset, configs of every part, text encoder,
                               normalisation, parts (file, dtype, parameter count, sha256), and a
                               training record per stage (data, iterations, wall time, metrics)
    MODEL_DIR/mean.npy         (263,) feature mean used by every part
    MODEL_DIR/std.npy          (263,) feature std (with the feat_bias quirk already applied)
    MODEL_DIR/tokenizer.pt     RVQ-VAE weights
    MODEL_DIR/transformer.pt   masked transformer weights
    MODEL_DIR/residual.pt      residual transformer weights
    MODEL_DIR/token_transformer.pt  optional masked transformer on MiniLM token states (config.token_view)
    (control.pt, evaluator.pt  added by the control and evaluation stages)
    MODEL_DIR/checkpoints/     training checkpoints (optimizer, RNG, step); not needed to generate
    MODEL_DIR/cache/           cached caption embeddings; not needed to generate

A part file is ``torch.save({"format": "controlmm-part", "part": name, "state_dict": ...})`` with
floating tensors in the model's ``storage_dtype`` (float16 for the demo preset); loading casts them back
to float32 and checks names and shapes strictly. Parts are registered by name (:func:`register_part`)
so later stages add their own without changing this module.
"""

from __future__ import annotations

import hashlib
import json
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, cast

import numpy as np
import torch
from torch import nn

from controlmm.assets import default_model_dir
from controlmm.atomic import atomic_path, write_text
from controlmm.errors import ControlMMError, InputFileError
from controlmm.files import load_torch
from controlmm.models.config import ModelConfig, TokenViewConfig
from controlmm.models.mask_transformer import MaskTransformer
from controlmm.models.residual_transformer import ResidualTransformer
from controlmm.models.rvqvae import RVQVAE
from controlmm.motion.normalization import Normalizer
from controlmm.text import TextEncoder, load_text_encoder

FORMAT = "controlmm-model"
FORMAT_VERSION = 1
PART_FORMAT = "controlmm-part"


@dataclass(frozen=True)
class PartSpec:
    """How to build the module of a part from a :class:`ModelConfig`."""

    name: str
    build: Callable[[ModelConfig], nn.Module]
    requires: tuple[str, ...] = ()  # parts it was trained on top of


PARTS: dict[str, PartSpec] = {}
"""Registered parts by name (``tokenizer``, ``transformer``, ``residual``, ...)."""


def train_command(part: str) -> str:
    """The ``controlmm train`` subcommand that trains ``part`` (``token_transformer`` ->
    ``token-transformer``)."""
    return part.replace("_", "-")


def register_part(
    name: str, build: Callable[[ModelConfig], nn.Module], requires: tuple[str, ...] = ()
) -> None:
    """Make a part loadable from model directories (``<name>.pt``)."""
    PARTS[name] = PartSpec(name, build, requires)


def _build_tokenizer(cfg: ModelConfig) -> nn.Module:
    return RVQVAE(cfg.tokenizer)


def _build_transformer(cfg: ModelConfig) -> nn.Module:
    return MaskTransformer(cfg.transformer)


def _build_token_transformer(cfg: ModelConfig) -> nn.Module:
    if cfg.token_view is None:
        raise ControlMMError(
            "the model configuration has no token_view (the token-state transformer's config)"
        )
    return MaskTransformer(cfg.token_view.transformer)


def _build_residual(cfg: ModelConfig) -> nn.Module:
    return ResidualTransformer(cfg.residual)


register_part("tokenizer", _build_tokenizer)
register_part("transformer", _build_transformer, requires=("tokenizer",))
register_part("residual", _build_residual, requires=("tokenizer",))
register_part("token_transformer", _build_token_transformer, requires=("tokenizer",))


# -- model.json -----------------------------------------------------------------------------------
def read_manifest(model_dir: str | Path) -> dict[str, Any]:
    """The parsed ``model.json`` of a model directory (checked format and version)."""
    model_dir = Path(model_dir)
    if not model_dir.is_dir():
        raise InputFileError(f"model directory '{model_dir}' does not exist")
    path = model_dir / "model.json"
    if not path.is_file():
        raise InputFileError(f"'{model_dir}' is not a model directory: model.json is missing")
    try:
        manifest = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, json.JSONDecodeError) as exc:
        raise InputFileError(f"'{path}' is not valid JSON: {exc}") from exc
    if not isinstance(manifest, dict) or manifest.get("format") != FORMAT:
        raise InputFileError(f"'{path}' is not a controlmm model description (format '{FORMAT}')")
    if manifest.get("format_version") != FORMAT_VERSION:
        raise InputFileError(
            f"'{path}' has format version {manifest.get('format_version')}; "
            f"this controlmm reads version {FORMAT_VERSION}"
        )
    return manifest


def write_manifest(model_dir: Path, manifest: dict[str, Any]) -> None:
    write_text(model_dir / "model.json", json.dumps(manifest, indent=2, sort_keys=False) + "\n")


def new_manifest(config: ModelConfig, normalization: dict[str, Any]) -> dict[str, Any]:
    return {
        "format": FORMAT,
        "format_version": FORMAT_VERSION,
        "preset": config.preset,
        "config": config.to_dict(),
        "text_encoder": {
            "name": config.text_encoder.name,
            "dim": config.text_encoder.dim,
            "weights": config.text_encoder.weights,
        },
        "normalization": normalization,
        "parts": {},
        "training": {},
    }


def write_statistics(model_dir: Path, normalizer: Normalizer) -> None:
    for name, arr in (("mean.npy", normalizer.mean), ("std.npy", normalizer.std)):
        with atomic_path(model_dir / name) as tmp:
            np.save(tmp, arr.astype(np.float32))


def read_statistics(model_dir: Path) -> Normalizer:
    for name in ("mean.npy", "std.npy"):
        if not (model_dir / name).is_file():
            raise InputFileError(f"model directory '{model_dir}' has no {name}")
    return Normalizer.load(model_dir / "mean.npy", model_dir / "std.npy")


# -- part files -----------------------------------------------------------------------------------
def sha256_file(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for chunk in iter(lambda: fh.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


def save_part(
    model_dir: Path,
    name: str,
    module: nn.Module,
    dtype: str,
    state_dict: dict[str, torch.Tensor] | None = None,
) -> dict[str, Any]:
    """Write ``<name>.pt`` atomically; return its manifest entry (file, dtype, params, sha256)."""
    state = module.state_dict() if state_dict is None else state_dict
    target = torch.float16 if dtype == "float16" else torch.float32
    state = {
        k: (v.detach().to("cpu", target) if v.is_floating_point() else v.detach().cpu()).contiguous()
        for k, v in state.items()
    }
    path = model_dir / f"{name}.pt"
    with atomic_path(path) as tmp:
        torch.save({"format": PART_FORMAT, "part": name, "dtype": dtype, "state_dict": state}, tmp)
    return {
        "file": path.name,
        "dtype": dtype,
        "parameters": int(sum(p.numel() for p in module.parameters())),
        "bytes": path.stat().st_size,
        "sha256": sha256_file(path),
        "saved": time.strftime("%Y-%m-%dT%H:%M:%S"),
    }


def load_part_state(
    model_dir: Path, name: str, entry: dict[str, Any] | None = None
) -> dict[str, torch.Tensor]:
    """The float32 state dict of ``<name>.pt``; one-line errors for missing or corrupt files."""
    path = model_dir / f"{name}.pt"
    if not path.is_file():
        raise InputFileError(
            f"model directory '{model_dir}' has no {name}.pt "
            f"(train it with: controlmm train {train_command(name)} --out {model_dir})"
        )
    if entry and entry.get("sha256") and sha256_file(path) != entry["sha256"]:
        raise InputFileError(
            f"checkpoint '{path}' is corrupt: its checksum differs from model.json "
            f"(train it again with: controlmm train {train_command(name)} --out {model_dir} --force)"
        )
    data = load_torch(
        path, "checkpoint", hint=f"train it again with: controlmm train {train_command(name)} --force"
    )
    if not isinstance(data, dict) or data.get("format") != PART_FORMAT or "state_dict" not in data:
        raise InputFileError(f"checkpoint '{path}' is not a controlmm part file")
    return {k: (v.float() if v.is_floating_point() else v) for k, v in data["state_dict"].items()}


def load_state_strict(module: nn.Module, state: dict[str, torch.Tensor], where: str) -> None:
    """``load_state_dict`` with every name and shape checked; a one-line error listing mismatches."""
    own = module.state_dict()
    missing = sorted(set(own) - set(state))
    unexpected = sorted(set(state) - set(own))
    wrong = sorted(k for k in set(own) & set(state) if tuple(own[k].shape) != tuple(state[k].shape))
    if missing or unexpected or wrong:
        parts = []
        for label, names in (("missing", missing), ("unexpected", unexpected), ("wrong shape", wrong)):
            if names:
                shown = ", ".join(names[:5]) + (f" (+{len(names) - 5} more)" if len(names) > 5 else "")
                parts.append(f"{label}: {shown}")
        raise InputFileError(f"checkpoint '{where}' does not fit the configured model; " + "; ".join(parts))
    module.load_state_dict(state, strict=True)


# -- the loaded model -----------------------------------------------------------------------------
@dataclass
class MotionModel:
    """A loaded model directory: configs, normaliser, parts (eval mode) and the text encoder."""

    config: ModelConfig
    normalizer: Normalizer
    parts: dict[str, nn.Module]
    manifest: dict[str, Any]
    directory: Path | None = None
    device: torch.device = field(default_factory=lambda: torch.device("cpu"))
    clip_weights: str | None = None
    _text_encoder: TextEncoder | None = None

    @property
    def tokenizer(self):
        return self.require("tokenizer")

    @property
    def transformer(self) -> MaskTransformer:
        return cast(MaskTransformer, self.require("transformer"))  # built by _build_transformer

    @property
    def residual(self) -> ResidualTransformer | None:
        return cast(ResidualTransformer | None, self.parts.get("residual"))  # built by _build_residual

    @property
    def token_transformer(self) -> MaskTransformer | None:
        """The token-state masked transformer of ``config.token_view``, or None (not trained)."""
        return cast(MaskTransformer | None, self.parts.get("token_transformer"))

    def require(self, name: str) -> nn.Module:
        if name not in self.parts:
            where = self.directory or "this model"
            raise ControlMMError(
                f"model directory '{where}' has no trained {name} "
                f"(train it with: controlmm train {train_command(name)} --out {where})"
            )
        return self.parts[name]

    @property
    def text_encoder(self):
        """The sentence encoder the transformers were trained with (loaded on first use)."""
        if self._text_encoder is None:
            self._text_encoder = load_text_encoder(
                self.config.text_encoder, device=self.device, weights=self.clip_weights
            )
        return self._text_encoder

    def encode_text(self, texts: list[str]) -> torch.Tensor:
        """(B,) texts -> (B, text_dim) condition vectors on the model's device; (B, L, text_dim) token
        states when the model was trained on them (``config.text_encoder.tokens``)."""
        tokens = self.config.text_encoder.tokens
        self.text_encoder.warn_truncated(texts, tokens or None)
        vectors = (
            self.text_encoder.encode_tokens(texts, tokens) if tokens else self.text_encoder.encode(texts)
        )
        return self._checked_condition(vectors)

    def _checked_condition(self, vectors: torch.Tensor) -> torch.Tensor:
        expected = self.config.transformer.text_dim
        if vectors.shape[-1] != expected:
            raise ControlMMError(
                f"text encoder '{self.config.text_encoder.name}' gives {vectors.shape[-1]}-d vectors; "
                f"the model expects {expected}-d (wrong CLIP weights?)"
            )
        return vectors.to(self.device)

    def encode_token_states(self, texts: list[str]) -> torch.Tensor:
        """(B,) texts -> (B, L, 384) MiniLM token states for the token-state transformer
        (``config.token_view``)."""
        view = self._token_view()
        self.text_encoder.warn_truncated(texts, view.tokens)
        return self.text_encoder.encode_tokens(texts, view.tokens).to(self.device)

    def _token_view(self) -> TokenViewConfig:
        """``config.token_view``, or a clear error for a model without one."""
        if self.config.token_view is None:
            raise ControlMMError(f"model '{self.directory or 'this model'}' has no token_view configuration")
        return self.config.token_view

    def encode_text_views(self, texts: list[str]) -> tuple[torch.Tensor, torch.Tensor | None]:
        """:meth:`encode_text` and, when the model has a token-state transformer, :meth:`encode_token_states`
        of the same texts; one MiniLM pass gives both where the encoder can (the same values)."""
        if self.token_transformer is None:
            return self.encode_text(texts), None
        both = getattr(self.text_encoder, "encode_with_tokens", None)
        if both is None or self.config.text_encoder.tokens:
            return self.encode_text(texts), self.encode_token_states(texts)
        view = self._token_view()
        self.text_encoder.warn_truncated(texts, view.tokens)
        vectors, states = both(texts, view.tokens)
        return self._checked_condition(vectors), states.to(self.device)

    def to(self, device: str | torch.device) -> MotionModel:
        self.device = torch.device(device)
        for module in self.parts.values():
            module.to(self.device)
        return self


def resolve_device(device: str | torch.device | None) -> torch.device:
    """``None``/"auto" -> CUDA when available, else CPU; "cuda" without a GPU is an error."""
    if device is None or str(device) == "auto":
        return torch.device("cuda" if torch.cuda.is_available() else "cpu")
    device = torch.device(device)
    if device.type == "cuda" and not torch.cuda.is_available():
        raise ControlMMError("device 'cuda' requested but no CUDA GPU is available; use --device cpu")
    if device.type not in ("cpu", "cuda"):
        raise ControlMMError(f"unknown device '{device}'; allowed: cpu, cuda")
    return device


def load_model(
    model_dir: str | Path | None = None,
    device: str | torch.device | None = "cpu",
    parts: tuple[str, ...] | None = None,
    clip_weights: str | None = None,
    skip: tuple[str, ...] = (),
) -> MotionModel:
    """Load a model directory (``None``: the embedded default, ``controlmm.assets.default_model_dir()``).

    Args:
        model_dir: the directory written by ``controlmm train`` (or ``import-official``).
        device: "cpu", "cuda" or None/"auto".
        parts: parts to load; default every part listed in model.json.
        skip: parts not to load even if listed (e.g. ``("control",)`` for generation without control).
        clip_weights: for CLIP-conditioned models, where the CLIP weights are (overrides model.json).
    """
    if model_dir is None:
        model_dir = default_model_dir()
        if not (Path(model_dir) / "model.json").is_file():
            raise InputFileError(
                f"no embedded default model at '{model_dir}'; train one with "
                "'controlmm train tokenizer|transformer|residual --out DIR' and pass --model DIR"
            )
    model_dir = Path(model_dir)
    manifest = read_manifest(model_dir)
    config = ModelConfig.from_dict(manifest["config"])
    normalizer = read_statistics(model_dir)
    listed = manifest.get("parts", {})
    wanted = tuple(p for p in (tuple(listed) if parts is None else parts) if p not in skip)
    loaded: dict[str, nn.Module] = {}
    for name in wanted:
        if name not in PARTS:
            raise InputFileError(f"model.json lists unknown part '{name}'; known: {', '.join(PARTS)}")
        entry = listed.get(name)
        if entry is None:
            raise InputFileError(f"model directory '{model_dir}' has no trained {name}")
        module = PARTS[name].build(config)
        load_state_strict(module, load_part_state(model_dir, name, entry), str(model_dir / f"{name}.pt"))
        for dep in PARTS[name].requires:
            trained_on = entry.get("trained_on", {}).get(dep)
            current = listed.get(dep, {}).get("sha256")
            if trained_on and current and trained_on != current:
                raise InputFileError(
                    f"'{model_dir / (name + '.pt')}' was trained on a different {dep}.pt; "
                    f"retrain it (controlmm train {name} --out {model_dir} --force)"
                )
        loaded[name] = module.eval().requires_grad_(False)  # inference: gradients only reach inputs
    model = MotionModel(
        config=config,
        normalizer=normalizer,
        parts=loaded,
        manifest=manifest,
        directory=model_dir,
        clip_weights=clip_weights,
    )
    return model.to(resolve_device(device))
