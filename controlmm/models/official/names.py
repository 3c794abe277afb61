"""The name mapping from the official MoMask / MaskControl state_dicts to this project's parts.

The ``paper`` preset's modules use the official module names, so the mapping is a split by prefix,
not a renaming. Official checkpoint (dict key) -> part file of the model directory::

    rvq_.../model/net_best_fid.tar   ["vq_model"]          every key            -> tokenizer.pt  (same name)
    t2m_.../model/latest.tar         ["t2m_transformer"]   every key            -> transformer.pt (same name)
                                     (older files: ["trans"])
    tres_.../model/net_best_fid.tar  ["res_transformer"]   every key            -> residual.pt   (same name)
    <control run>/model/latest.tar   ["ct2m_transformer"]
        vq_model.<k>                                                            -> tokenizer.pt   <k>
        seqTransEncoder_control.*, encoder_control.*, first_zero_linear.*,
        mid_zero_linear.*                                                       -> control.pt     (same name)
        every other key (token_emb, input_process, position_enc, seqTransEncoder, cond_emb,
        output_process: the frozen base the control branch was trained on)     -> transformer.pt (same name)

Keys starting with ``clip_model.`` (the frozen CLIP, stripped by the official savers but present in some
files) are dropped: CLIP is loaded separately (``controlmm.text.clip``). Nothing else is dropped; a key
that fits no module is reported by the strict load (``load_state_strict``) as "unexpected".

Tensors the official modules compute rather than store (``mask_emb_vq`` = mean of the base codebook,
the residual's assembled ``token_embed_weight`` / ``output_proj_weight``) are computed the same way
here from the stored tensors.
"""

from __future__ import annotations

import torch

from controlmm.errors import InputFileError

CLIP_PREFIX = "clip_model."
VQ_PREFIX = "vq_model."
CONTROL_PREFIXES: tuple[str, ...] = (
    "seqTransEncoder_control.",
    "encoder_control.",
    "first_zero_linear.",
    "mid_zero_linear.",
)
"""Prefixes of the motion control model's tensors inside ``ct2m_transformer`` (-> ``control.pt``)."""

CHECKPOINT_KEYS: dict[str, tuple[str, ...]] = {
    "tokenizer": ("vq_model", "net"),
    "transformer": ("t2m_transformer", "trans"),
    "residual": ("res_transformer",),
    "control": ("ct2m_transformer",),
}
"""Which entry of the official ``.tar`` dict holds the state_dict, per kind (first found wins).
A VQ checkpoint saved as ``{'net': state_dict}`` is accepted as the official loaders accept it."""

State = dict[str, torch.Tensor]


def without_clip(state: State) -> State:
    """The state_dict without the frozen CLIP's tensors."""
    return {k: v for k, v in state.items() if not k.startswith(CLIP_PREFIX)}


def split_control_state(state: State) -> dict[str, State]:
    """Split an official ``ct2m_transformer`` state_dict into this project's parts.

    Returns ``{"tokenizer": ..., "transformer": ..., "control": ...}`` (see the module docstring);
    every non-CLIP key lands in exactly one part.
    """
    parts: dict[str, State] = {"tokenizer": {}, "transformer": {}, "control": {}}
    for key, value in without_clip(state).items():
        if key.startswith(VQ_PREFIX):
            parts["tokenizer"][key[len(VQ_PREFIX) :]] = value
        elif key.startswith(CONTROL_PREFIXES):
            parts["control"][key] = value
        else:
            parts["transformer"][key] = value
    if not parts["control"]:
        raise InputFileError(
            "the control checkpoint holds no motion control model tensors "
            f"({', '.join(p.rstrip('.') for p in CONTROL_PREFIXES)}); is it a MaskControl "
            "ct2m_transformer?"
        )
    return parts


def map_official_state(kind: str, state: State) -> dict[str, State]:
    """Official state_dict of one checkpoint kind -> ``{part name: state_dict}`` with our names.

    ``kind``: ``"tokenizer"`` (RVQVAE), ``"transformer"`` (MaskTransformer), ``"residual"``
    (ResidualTransformer) or ``"control"`` (ControlTransformer, split into three parts).
    """
    if kind == "control":
        return split_control_state(state)
    if kind not in CHECKPOINT_KEYS:
        raise ValueError(f"unknown official checkpoint kind '{kind}'")
    return {kind: without_clip(state)}
