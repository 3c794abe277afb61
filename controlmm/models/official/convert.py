"""Import the official MoMask / MaskControl checkpoints into a model directory (``paper`` preset).

``import_official(momask, control, evaluator, out)``:

1. find the folders (:mod:`controlmm.models.official.folders`) and read each ``.tar`` safely
   (``torch.load(weights_only=True)``) and each ``opt.txt``;
2. derive the configs from the tensor shapes (sizes) and ``opt.txt`` (heads, dropout, EMA decay:
   values that shapes cannot tell), and check the options the ``paper`` modules do not implement
   (ReLU VQ without normalisation, separate codebooks, shared residual weights);
3. map the official names onto the parts (:mod:`controlmm.models.official.names`) and load every part
   strictly (every official tensor consumed, every one of ours filled, shapes equal; otherwise one
   error line listing the mismatches);
4. write the model directory atomically: ``model.json``, the VQ folder's ``meta/mean.npy`` and
   ``meta/std.npy`` as they are (they already carry the official Std/25 quirk on dims 0-3 and 259-262),
   ``tokenizer.pt``, ``transformer.pt``, ``residual.pt``, ``control.pt`` in float32, and optionally
   the HumanML3D evaluator's files under ``evaluator/``.

With a control checkpoint, the tokenizer and the base transformer come from **inside** it
(``vq_model.*`` and the frozen base), as the official control scripts do when they load
``ct2m_transformer`` over the separately loaded models; the differences to the MoMask folders' copies
are recorded in ``model.json`` (``official.notes``).
"""

from __future__ import annotations

import re
import shutil
from collections.abc import Callable
from dataclasses import asdict, replace
from pathlib import Path
from typing import Any, TypedDict

import numpy as np
import torch

from controlmm.atomic import atomic_dir, check_output_dir
from controlmm.errors import ControlMMError, InputFileError
from controlmm.files import load_torch
from controlmm.models.config import (
    ControlConfig,
    ModelConfig,
    ResidualConfig,
    TokenizerConfig,
    TransformerConfig,
    preset_config,
)
from controlmm.models.model_dir import (
    PARTS,
    load_state_strict,
    new_manifest,
    save_part,
    write_manifest,
    write_statistics,
)
from controlmm.models.official.folders import OfficialFolder, find_control, find_momask
from controlmm.models.official.names import CHECKPOINT_KEYS, State, map_official_state
from controlmm.motion.normalization import Normalizer
from controlmm.motion.skeleton import FEATURE_DIM
from controlmm.text.config import CLIP_MODEL_ID, TextEncoderConfig

CONTROL_CHANNELS = {6: "pelvis", 36: "all"}
"""Input channels of ``encoder_control`` -> control joint set (MaskControl ``trajectory`` / ``cross``)."""


# -- reading ----------------------------------------------------------------------------------------
def load_official_checkpoint(path: Path, kind: str) -> tuple[State, dict[str, Any]]:
    """The state_dict of an official ``.tar`` (entry per :data:`CHECKPOINT_KEYS`) and its scalar extras."""
    data = load_torch(path, "official checkpoint")
    if not isinstance(data, dict):
        raise InputFileError(f"'{path}' is not an official checkpoint (a dict); got {type(data).__name__}")
    key = next((k for k in CHECKPOINT_KEYS[kind] if k in data), None)
    if key is None:
        raise InputFileError(
            f"'{path}' has no '{CHECKPOINT_KEYS[kind][0]}' entry (keys: "
            f"{', '.join(map(str, data)) or 'none'}); is it the {kind} checkpoint?"
        )
    state = data[key]
    if not isinstance(state, dict) or not all(isinstance(v, torch.Tensor) for v in state.values()):
        raise InputFileError(f"'{path}' entry '{key}' is not a state_dict of tensors")
    extras = {k: v for k, v in data.items() if isinstance(v, (int, float, str)) and not isinstance(v, bool)}
    return {str(k): v for k, v in state.items()}, {"entry": key, **extras}


def _indices(state: State, pattern: str) -> list[int]:
    """Sorted distinct integers captured by ``pattern`` (one group) over the keys."""
    rx = re.compile(pattern)
    return sorted({int(m.group(1)) for k in state if (m := rx.fullmatch(k))})


def _need(state: State, key: str, where: str) -> torch.Tensor:
    if key not in state:
        raise InputFileError(f"{where}: missing tensor '{key}' (not an official checkpoint of this kind?)")
    return state[key]


def _opt(folder: OfficialFolder, key: str, default: Any, notes: list[str]) -> Any:
    if key in folder.opt:
        return folder.opt[key]
    notes.append(f"{folder.folder.name}: opt.txt has no '{key}'; used {default!r} (the released value)")
    return default


# -- configs from shapes and opt.txt ----------------------------------------------------------------
def tokenizer_config(state: State, folder: OfficialFolder, notes: list[str]) -> TokenizerConfig:
    where = str(folder.checkpoint)
    first = _need(state, "encoder.model.0.weight", where)
    down = _indices(state, r"encoder\.model\.(\d+)\.0\.weight")
    depth = _indices(state, r"encoder\.model\.\d+\.1\.model\.(\d+)\.conv1\.weight")
    layers = _indices(state, r"quantizer\.layers\.(\d+)\.codebook")
    if not down or not depth or not layers:
        raise InputFileError(
            f"{where}: not an RVQ-VAE state_dict (no strided convs, residual blocks or codebooks)"
        )
    codebook = state["quantizer.layers.0.codebook"]
    opt = folder.opt
    for key, allowed in (("vq_act", "relu"), ("vq_norm", None), ("shared_codebook", False)):
        if key in opt and opt[key] != allowed:
            raise InputFileError(
                f"{folder.folder / 'opt.txt'}: {key} = {opt[key]!r} is not supported "
                f"(the paper modules implement {key} = {allowed!r})"
            )
    if first.shape[1] != FEATURE_DIM:
        raise InputFileError(
            f"{where}: motion features are {first.shape[1]}-d; only HumanML3D ({FEATURE_DIM}-d) "
            "models can be imported (KIT-ML models are not supported)"
        )
    growth = int(_opt(folder, "dilation_growth_rate", 3, notes))
    return TokenizerConfig(
        input_dim=int(first.shape[1]),
        width=int(first.shape[0]),
        code_dim=int(codebook.shape[1]),
        nb_code=int(codebook.shape[0]),
        num_quantizers=len(layers),
        down_t=len(down),
        stride_t=int(state[f"encoder.model.{down[0]}.0.weight"].shape[-1]) // 2,
        depth=len(depth),
        dilation_growth_rate=growth,
        mu=float(_opt(folder, "mu", 0.99, notes)),
        quantize_dropout_prob=float(_opt(folder, "quantize_dropout_prob", 0.2, notes)),
    )


class _TrunkSizes(TypedDict):
    """Sizes of a transformer trunk read from its state_dict (shared by both transformer configs)."""

    num_layers: int
    ff_size: int
    latent_dim: int
    text_dim: int
    max_len: int


def _trunk_sizes(state: State, where: str) -> _TrunkSizes:
    layers = _indices(state, r"seqTransEncoder\.layers\.(\d+)\.linear1\.weight")
    if not layers:
        raise InputFileError(f"{where}: no seqTransEncoder layers")
    return _TrunkSizes(
        num_layers=len(layers),
        ff_size=int(state["seqTransEncoder.layers.0.linear1.weight"].shape[0]),
        latent_dim=int(_need(state, "cond_emb.weight", where).shape[0]),
        text_dim=int(state["cond_emb.weight"].shape[1]),
        max_len=int(_need(state, "position_enc.pe", where).shape[0]),
    )


def transformer_config(state: State, folder: OfficialFolder, notes: list[str]) -> TransformerConfig:
    where = str(folder.checkpoint)
    token_emb = _need(state, "token_emb.weight", where)
    return TransformerConfig(
        nb_code=int(token_emb.shape[0]) - 2,
        code_dim=int(token_emb.shape[1]),
        num_heads=int(_opt(folder, "n_heads", 6, notes)),
        dropout=float(_opt(folder, "dropout", 0.2, notes)),
        cond_drop_prob=float(_opt(folder, "cond_drop_prob", 0.1, notes)),
        **_trunk_sizes(state, where),
    )


def residual_config(state: State, folder: OfficialFolder, notes: list[str]) -> ResidualConfig:
    where = str(folder.checkpoint)
    if folder.opt.get("share_weight") is False or "embed_proj_shared_weight" not in state:
        raise InputFileError(
            f"{where}: only residual transformers trained with share_weight (the released "
            "'..._sw' model: embed_proj_shared_weight, token_embed_weight_, output_proj_weight_) "
            "can be imported"
        )
    token = _need(state, "token_embed_weight_", where)
    return ResidualConfig(
        nb_code=int(token.shape[1]) - 1,
        code_dim=int(token.shape[2]),
        num_quantizers=int(_need(state, "quant_emb.weight", where).shape[1]),
        num_heads=int(_opt(folder, "n_heads", 6, notes)),
        dropout=float(_opt(folder, "dropout", 0.2, notes)),
        cond_drop_prob=float(_opt(folder, "cond_drop_prob", 0.2, notes)),
        **_trunk_sizes(state, where),
    )


def control_config(state: State, tokenizer: TokenizerConfig, where: str) -> ControlConfig:
    first = _need(state, "encoder_control.model.0.weight", where)
    channels = int(first.shape[1])
    if channels not in CONTROL_CHANNELS:
        raise InputFileError(
            f"{where}: encoder_control takes {channels} channels; supported: 6 (pelvis, MaskControl "
            "control 'trajectory') or 36 (joints 0, 10, 11, 15, 20, 21)"
        )
    if int(first.shape[0]) != tokenizer.width:
        raise InputFileError(
            f"{where}: encoder_control is {first.shape[0]} wide but the RVQ-VAE is {tokenizer.width} "
            "wide; the paper modules use the tokenizer's width for both"
        )
    return ControlConfig(joints=CONTROL_CHANNELS[channels])


def paper_differences(config: ModelConfig) -> list[str]:
    """Architecture fields where ``config`` differs from the ``paper`` preset (empty for the released
    models)."""
    paper = preset_config("paper")
    out = []
    for part in ("tokenizer", "transformer", "residual"):
        ours, ref = asdict(getattr(config, part)), asdict(getattr(paper, part))
        out += [f"{part}.{k}: paper {ref[k]} -> {ours[k]}" for k in ref if ours[k] != ref[k]]
    return out


def _max_difference(a: State, b: State) -> float | None:
    """Largest absolute difference between two state_dicts with equal names and shapes (None otherwise)."""
    if set(a) != set(b) or any(a[k].shape != b[k].shape for k in a):
        return None
    return max((float((a[k].float() - b[k].float()).abs().max()) for k in a if a[k].numel()), default=0.0)


# -- the import -------------------------------------------------------------------------------------
def official_model(
    momask: str | Path,
    control: str | Path | None = None,
    clip_weights: str | None = None,
    clip_precision: str = "float16",
) -> tuple[ModelConfig, dict[str, torch.nn.Module], dict[str, Any]]:
    """Read the official folders and build the loaded modules.

    Returns (config, {part: module with the official weights}, record for ``model.json``).
    """
    notes: list[str] = []
    folders = find_momask(momask)
    states: dict[str, State] = {}
    origin: dict[str, Path] = {}  # part -> the file its tensors come from
    sources: dict[str, Any] = {}
    for kind, folder in folders.items():
        raw, extras = load_official_checkpoint(folder.checkpoint, kind)
        states.update(map_official_state(kind, raw))
        origin[kind] = folder.checkpoint
        sources[kind] = {
            "folder": str(folder.folder.resolve()),
            "checkpoint": folder.checkpoint.name,
            "opt_txt": folder.has_opt,
            **extras,
        }
    if control is not None:
        ctrl_folder = find_control(control)
        raw, extras = load_official_checkpoint(ctrl_folder.checkpoint, "control")
        split = map_official_state("control", raw)
        for part in ("tokenizer", "transformer"):
            diff = _max_difference(states[part], split[part])
            what = (
                "different names/shapes"
                if diff is None
                else "identical"
                if diff == 0.0
                else f"max |diff| {diff:.3g}"
            )
            notes.append(
                f"{part}: taken from the control checkpoint (as the official control scripts do); "
                f"the MoMask folder's copy is {what}"
            )
            sources[part]["weights_from"] = str(ctrl_folder.checkpoint.resolve())
        states.update(split)
        origin.update({part: ctrl_folder.checkpoint for part in split})
        sources["control"] = {
            "folder": str(ctrl_folder.folder.resolve()),
            "checkpoint": ctrl_folder.checkpoint.name,
            "opt_txt": ctrl_folder.has_opt,
            "control": ctrl_folder.opt.get("control"),
            **extras,
        }
        folders["control"] = ctrl_folder
    tok = tokenizer_config(states["tokenizer"], folders["tokenizer"], notes)
    tr = transformer_config(states["transformer"], folders["transformer"], notes)
    res = residual_config(states["residual"], folders["residual"], notes)
    if tr.text_dim != res.text_dim:
        raise InputFileError(
            f"the masked transformer takes {tr.text_dim}-d text vectors but the residual transformer "
            f"{res.text_dim}-d; they must come from the same text encoder"
        )
    text = TextEncoderConfig(
        name="clip",
        weights=clip_weights or CLIP_MODEL_ID,
        precision=clip_precision,
        size=None if tr.text_dim == 512 else tr.text_dim,
    )
    paper = preset_config("paper")
    ctrl = (
        control_config(states["control"], tok, str(folders["control"].checkpoint))
        if "control" in states
        else paper.control
    )
    try:
        config = replace(
            paper,
            tokenizer=tok,
            transformer=tr,
            residual=res,
            text_encoder=text,
            control=ctrl,
            storage_dtype="float32",
        )
    except ControlMMError as exc:
        raise InputFileError(f"the official checkpoints do not fit together: {exc}") from None
    modules: dict[str, torch.nn.Module] = {}
    for part, state in states.items():
        module = PARTS[part].build(config)
        where = f"{origin[part]} ({part})"
        load_state_strict(
            module, {k: v.float() if v.is_floating_point() else v for k, v in state.items()}, where
        )
        modules[part] = module.eval()
    record = {"sources": sources, "differs_from_paper_preset": paper_differences(config), "notes": notes}
    return config, modules, record


def _copy_evaluator(root: str | Path, dest: Path) -> dict[str, Any]:
    """Copy the HumanML3D evaluator's files (MoMask layout) under ``dest``; return their record."""
    root = Path(root).expanduser()
    t2m = next(
        (
            d
            for d in (root, root / "t2m", root / "checkpoints" / "t2m")
            if (d / "text_mot_match" / "model" / "finest.tar").is_file()
        ),
        None,
    )
    if t2m is None:
        raise InputFileError(
            f"--evaluator '{root}': no text_mot_match/model/finest.tar under it (looked in "
            f"{root}, {root / 't2m'}, {root / 'checkpoints' / 't2m'})"
        )
    finest = t2m / "text_mot_match" / "model" / "finest.tar"
    data = load_torch(finest, "evaluator checkpoint")
    missing = [
        k
        for k in ("movement_encoder", "text_encoder", "motion_encoder")
        if not isinstance(data, dict) or not isinstance(data.get(k), dict)
    ]
    if missing:
        raise InputFileError(f"'{finest}' is not the HumanML3D evaluator: no {', '.join(missing)} state_dict")
    glove = next(
        (
            d
            for d in (root / "glove", t2m / "glove", t2m.parent / "glove", t2m.parent.parent / "glove")
            if (d / "our_vab_data.npy").is_file()
        ),
        None,
    )
    files = {finest: Path("text_mot_match/model/finest.tar")}
    for name in ("mean.npy", "std.npy"):
        src = t2m / "Comp_v6_KLD005" / "meta" / name
        if not src.is_file():
            raise InputFileError(f"--evaluator: '{src}' is missing (the evaluator's normalisation)")
        files[src] = Path("Comp_v6_KLD005/meta") / name
    if (t2m / "Comp_v6_KLD005" / "opt.txt").is_file():
        files[t2m / "Comp_v6_KLD005" / "opt.txt"] = Path("Comp_v6_KLD005/opt.txt")
    if glove is None:
        raise InputFileError(
            f"--evaluator '{root}': no glove/our_vab_data.npy beside it (the GloVe files of "
            "MoMask's prepare/download_glove.sh)"
        )
    for name in ("our_vab_data.npy", "our_vab_words.pkl", "our_vab_idx.pkl"):
        if not (glove / name).is_file():
            raise InputFileError(f"--evaluator: '{glove / name}' is missing")
        files[glove / name] = Path("glove") / name
    for src, rel in files.items():
        (dest / rel).parent.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(src, dest / rel)
    return {
        "format": "official-humanml3d-evaluator",
        "path": dest.name,
        "source": str(t2m.resolve()),
        "files": sorted(str(p) for p in files.values()),
        "note": "the official Guo et al. 2022 evaluator in MoMask's checkpoints/t2m layout; load it with "
        "controlmm.eval.evaluator.official.load_official_evaluator(MODEL_DIR / 'evaluator')",
    }


def _compare_statistics(normalizer: Normalizer, meta: Path) -> str:
    """A note comparing the VQ statistics with the evaluator's (MaskControl denormalises its decoded motion
    with the evaluator loader's mean/std while the data were normalised with the VQ's; the released files
    are expected to agree)."""
    other = Normalizer.load(meta / "mean.npy", meta / "std.npy")
    mean_gap = float(np.abs(other.mean - normalizer.mean).max())
    std_gap = float(np.abs(other.std / normalizer.std - 1.0).max())
    return (
        f"evaluator Comp_v6_KLD005/meta vs the VQ meta: max |mean diff| {mean_gap:.3g}, max |std ratio - 1| "
        f"{std_gap:.3g} (the model directory uses the VQ meta)"
    )


def import_official(
    momask: str | Path,
    out: str | Path,
    control: str | Path | None = None,
    evaluator: str | Path | None = None,
    clip_weights: str | None = None,
    clip_precision: str = "float16",
    force: bool = False,
    log: Callable[[str], None] | None = None,
) -> Path:
    """Convert the official checkpoint folders into the model directory ``out`` (see the module docstring)."""
    out = Path(out).expanduser()
    check_output_dir(out, kind=None, force=force)
    if clip_precision not in ("float16", "float32"):
        raise ControlMMError(f"--clip-precision must be float16 or float32; got {clip_precision}")
    log = log or (lambda message: None)
    config, modules, record = official_model(momask, control, clip_weights, clip_precision)
    meta = Path(record["sources"]["tokenizer"]["folder"]) / "meta"
    normalizer = Normalizer.load(meta / "mean.npy", meta / "std.npy")
    normalization = {
        "source": str(meta),
        "description": "the official RVQ-VAE folder's meta/mean.npy and meta/std.npy, unchanged (their std "
        "of dims 0-3 and 259-262 is HumanML3D's Std/25: MoMask's feat_bias 5 applied twice)",
        "feat_bias": config.feat_bias,
        "feat_bias_times": config.feat_bias_times,
    }
    manifest = new_manifest(config, normalization)
    order = [p for p in ("tokenizer", "transformer", "residual", "control") if p in modules]
    requires = {
        "transformer": ("tokenizer",),
        "residual": ("tokenizer",),
        "control": ("tokenizer", "transformer"),
    }
    with atomic_dir(out, kind=None, force=force) as tmp:
        write_statistics(tmp, normalizer)
        for name in order:
            entry = save_part(tmp, name, modules[name], config.storage_dtype)
            entry["trained_on"] = {
                dep: manifest["parts"][dep]["sha256"]
                for dep in requires.get(name, ())
                if dep in manifest["parts"]
            }
            entry["source"] = "official"
            manifest["parts"][name] = entry
            manifest["training"][name] = {"source": "official", **record["sources"][name]}
            log(f"{name}: {entry['parameters']:,} parameters from {record['sources'][name]['folder']}")
        if evaluator is not None:
            record["evaluator"] = _copy_evaluator(evaluator, tmp / "evaluator")
            record["notes"].append(
                _compare_statistics(normalizer, tmp / "evaluator" / "Comp_v6_KLD005" / "meta")
            )
            log(f"evaluator: copied to {out / 'evaluator'}")
        manifest["official"] = record
        write_manifest(tmp, manifest)
    for note in record["notes"]:
        log(f"note: {note}")
    return out
