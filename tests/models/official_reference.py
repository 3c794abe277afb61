"""Test helpers for the official-checkpoint import, independent of ``controlmm.models``.

1. State_dicts with exactly the official names and shapes (as in the released MoMask /
   MaskControl `.tar` checkpoints), random values, written out in the official folder layout
   (``checkpoints/t2m/<name>/model/*.tar``, ``opt.txt``, ``meta/{mean,std}.npy``).
2. A re-implementation of the official forward passes written straight from the official module
   definitions with plain tensor ops on those raw state_dicts (no ``nn.Module`` of this project, no
   ``nn.TransformerEncoderLayer``): RVQ-VAE decoding from token ids, masked-transformer logits,
   residual-transformer logits, the MaskControl control branch and its control input.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch
import torch.nn.functional as F

CONTROL_JOINTS = [0, 10, 11, 15, 20, 21]  # MaskControl utils/metrics.py control_joint_ids


@dataclass(frozen=True)
class Dims:
    """Sizes of an official model family; ``paper()`` is the released one."""

    input_dim: int = 263
    width: int = 32
    code_dim: int = 16
    nb_code: int = 32
    num_q: int = 4
    down_t: int = 2
    depth: int = 3
    growth: int = 3
    latent: int = 32
    ff: int = 64
    layers: int = 2
    heads: int = 2
    text_dim: int = 24
    max_len: int = 64

    @classmethod
    def paper(cls) -> Dims:
        return cls(
            width=512,
            code_dim=512,
            nb_code=512,
            num_q=6,
            latent=384,
            ff=1024,
            layers=8,
            heads=6,
            text_dim=512,
            max_len=5000,
        )


class _Filler:
    def __init__(self, seed: int, empty: bool) -> None:
        self.gen = torch.Generator().manual_seed(seed)
        self.empty = empty

    def __call__(self, *shape: int, scale: float = 0.1, offset: float = 0.0) -> torch.Tensor:
        if self.empty:
            return torch.zeros(*shape)
        return torch.randn(*shape, generator=self.gen) * scale + offset


def _conv(sd, fill, name, c_out, c_in, k):
    sd[f"{name}.weight"] = fill(c_out, c_in, k, scale=1.0 / math.sqrt(c_in * k))
    sd[f"{name}.bias"] = fill(c_out, scale=0.05)


def _linear(sd, fill, name, d_out, d_in, bias=True):
    sd[f"{name}.weight"] = fill(d_out, d_in, scale=1.0 / math.sqrt(d_in))
    if bias:
        sd[f"{name}.bias"] = fill(d_out, scale=0.05)


def _resnet(sd, fill, prefix, width, depth):
    for j in range(depth):
        _conv(sd, fill, f"{prefix}.{j}.conv1", width, width, 3)
        _conv(sd, fill, f"{prefix}.{j}.conv2", width, width, 1)


def _conv_encoder(sd, fill, prefix, c_in, c_out, d: Dims):
    _conv(sd, fill, f"{prefix}.model.0", d.width, c_in, 3)
    for i in range(d.down_t):
        _conv(sd, fill, f"{prefix}.model.{2 + i}.0", d.width, d.width, 4)
        _resnet(sd, fill, f"{prefix}.model.{2 + i}.1.model", d.width, d.depth)
    _conv(sd, fill, f"{prefix}.model.{2 + d.down_t}", c_out, d.width, 3)


def official_vq_state(d: Dims, seed: int = 0, empty: bool = False) -> dict[str, torch.Tensor]:
    """MoMask ``RVQVAE`` state_dict (72 tensors for the released sizes)."""
    fill, sd = _Filler(seed, empty), {}
    _conv_encoder(sd, fill, "encoder", d.input_dim, d.code_dim, d)
    _conv(sd, fill, "decoder.model.0", d.width, d.code_dim, 3)
    for i in range(d.down_t):
        _resnet(sd, fill, f"decoder.model.{2 + i}.0.model", d.width, d.depth)
        _conv(sd, fill, f"decoder.model.{2 + i}.2", d.width, d.width, 3)
    _conv(sd, fill, f"decoder.model.{2 + d.down_t}", d.width, d.width, 3)
    _conv(sd, fill, f"decoder.model.{4 + d.down_t}", d.input_dim, d.width, 3)
    for q in range(d.num_q):
        sd[f"quantizer.layers.{q}.codebook"] = fill(d.nb_code, d.code_dim, scale=0.5)
    return sd


def _trunk(sd, fill, prefix, d: Dims):
    for i in range(d.layers):
        p = f"{prefix}.layers.{i}"
        _linear(sd, fill, f"{p}.self_attn.in_proj", 3 * d.latent, d.latent)
        sd[f"{p}.self_attn.in_proj_weight"] = sd.pop(f"{p}.self_attn.in_proj.weight")
        sd[f"{p}.self_attn.in_proj_bias"] = sd.pop(f"{p}.self_attn.in_proj.bias")
        _linear(sd, fill, f"{p}.self_attn.out_proj", d.latent, d.latent)
        _linear(sd, fill, f"{p}.linear1", d.ff, d.latent)
        _linear(sd, fill, f"{p}.linear2", d.latent, d.ff)
        for n in ("norm1", "norm2"):
            sd[f"{p}.{n}.weight"] = fill(d.latent, scale=0.1, offset=1.0)
            sd[f"{p}.{n}.bias"] = fill(d.latent, scale=0.05)


def _head(sd, fill, d: Dims, out: int):
    _linear(sd, fill, "output_process.dense", d.latent, d.latent)
    sd["output_process.LayerNorm.weight"] = fill(d.latent, scale=0.1, offset=1.0)
    sd["output_process.LayerNorm.bias"] = fill(d.latent, scale=0.05)
    _linear(sd, fill, "output_process.poseFinal", out, d.latent)


def official_mask_state(d: Dims, seed: int = 1, empty: bool = False) -> dict[str, torch.Tensor]:
    """MoMask ``MaskTransformer`` state_dict without CLIP (108 tensors for the released sizes)."""
    fill, sd = _Filler(seed, empty), {}
    sd["token_emb.weight"] = fill(d.nb_code + 2, d.code_dim, scale=0.5)
    _linear(sd, fill, "input_process.poseEmbedding", d.latent, d.code_dim)
    sd["position_enc.pe"] = fill(d.max_len, 1, d.latent, scale=0.5)
    _trunk(sd, fill, "seqTransEncoder", d)
    _linear(sd, fill, "cond_emb", d.latent, d.text_dim)
    _head(sd, fill, d, d.nb_code)
    return sd


def official_residual_state(d: Dims, seed: int = 2, empty: bool = False) -> dict[str, torch.Tensor]:
    """MoMask ``ResidualTransformer`` (share_weight) state_dict without CLIP (112 tensors released)."""
    fill, sd = _Filler(seed, empty), {}
    sd["embed_proj_shared_weight"] = fill(d.num_q - 2, d.nb_code + 1, d.code_dim, scale=0.5)
    sd["token_embed_weight_"] = fill(1, d.nb_code + 1, d.code_dim, scale=0.5)
    sd["output_proj_weight_"] = fill(1, d.nb_code + 1, d.code_dim, scale=0.5)
    _linear(sd, fill, "input_process.poseEmbedding", d.latent, d.code_dim)
    sd["position_enc.pe"] = fill(d.max_len, 1, d.latent, scale=0.5)
    _trunk(sd, fill, "seqTransEncoder", d)
    _linear(sd, fill, "quant_emb", d.latent, d.num_q)
    _linear(sd, fill, "cond_emb", d.latent, d.text_dim)
    _head(sd, fill, d, d.code_dim)
    return sd


def official_control_state(
    d: Dims,
    channels: int,
    seed: int = 3,
    empty: bool = False,
    base: dict | None = None,
    vq: dict | None = None,
) -> dict[str, torch.Tensor]:
    """MaskControl ``ControlTransformer`` state_dict (``ct2m_transformer``; 326 tensors released)."""
    fill = _Filler(seed, empty)
    sd = dict(base if base is not None else official_mask_state(d, seed + 10, empty))
    _trunk(sd, fill, "seqTransEncoder_control", d)
    _conv_encoder(sd, fill, "encoder_control", channels, d.latent, d)
    _linear(sd, fill, "first_zero_linear", d.latent, d.latent)
    for i in range(d.layers):
        _linear(sd, fill, f"mid_zero_linear.{i}", d.latent, d.latent)
    for k, v in (vq if vq is not None else official_vq_state(d, seed + 20, empty)).items():
        sd[f"vq_model.{k}"] = v
    return sd


# -- the official folder layout -------------------------------------------------------------------
def write_opt(path: Path, options: dict) -> None:
    lines = ["------------ Options -------------"] + [f"{k}: {options[k]}" for k in sorted(options)]
    path.write_text("\n".join(lines + ["-------------- End ----------------"]) + "\n")


def write_official_checkpoints(
    root: Path, d: Dims, control_channels: int | None = 36, control_vq_same: bool = True
) -> dict:
    """Write ``root/checkpoints/t2m/...`` as the official download scripts leave it; return the
    state_dicts."""
    t2m = root / "checkpoints" / "t2m"
    vq, base, res = official_vq_state(d), official_mask_state(d), official_residual_state(d)
    common = dict(dataset_name="t2m", checkpoints_dir="./checkpoints", gpu_id=0, milestones=[50000])
    folders = {
        "rvq_nq6_dc512_nc512_noshare_qdp0.2": (
            "net_best_fid.tar",
            {"vq_model": vq, "ep": 49},
            dict(
                nb_code=d.nb_code,
                code_dim=d.code_dim,
                output_emb_width=d.code_dim,
                down_t=d.down_t,
                stride_t=2,
                width=d.width,
                depth=d.depth,
                dilation_growth_rate=d.growth,
                vq_act="relu",
                vq_norm=None,
                num_quantizers=d.num_q,
                shared_codebook=False,
                quantize_dropout_prob=0.2,
                mu=0.99,
            ),
        ),
        "t2m_nlayer8_nhead6_ld384_ff1024_cdp0.1_rvq6ns": (
            "latest.tar",
            {"t2m_transformer": base, "ep": 499},
            dict(
                latent_dim=d.latent,
                n_heads=d.heads,
                n_layers=d.layers,
                ff_size=d.ff,
                dropout=0.2,
                cond_drop_prob=0.1,
                share_weight=False,
                vq_name="rvq_nq6_dc512_nc512_noshare_qdp0.2",
            ),
        ),
        "tres_nlayer8_ld384_ff1024_rvq6ns_cdp0.2_sw": (
            "net_best_fid.tar",
            {"res_transformer": res, "ep": 480},
            dict(
                latent_dim=d.latent,
                n_heads=d.heads,
                n_layers=d.layers,
                ff_size=d.ff,
                dropout=0.2,
                cond_drop_prob=0.2,
                share_weight=True,
                vq_name="rvq_nq6_dc512_nc512_noshare_qdp0.2",
            ),
        ),
    }
    out = {"vq": vq, "base": base, "res": res}
    if control_channels is not None:
        ctrl_vq = vq if control_vq_same else official_vq_state(d, seed=7)
        ctrl = official_control_state(d, control_channels, base=base, vq=ctrl_vq)
        name = (
            "z2024-08-27-21-07-55_CtrlNet_randCond1-196_l1.5XEnt.5TTT__cross"
            if control_channels == 36
            else "z2024-08-23-01-27-51_CtrlNet_randCond1-196_l1.1XEnt.9TTT__fixRandCond"
        )
        folders[name] = (
            "latest.tar",
            {"ct2m_transformer": ctrl, "ep": 55, "total_it": 100000},
            dict(
                latent_dim=d.latent,
                n_heads=d.heads,
                n_layers=d.layers,
                ff_size=d.ff,
                dropout=0.2,
                control="cross" if control_channels == 36 else "trajectory",
            ),
        )
        out["ctrl"], out["control_dir"] = ctrl, t2m / name
    for name, (file, payload, options) in folders.items():
        (t2m / name / "model").mkdir(parents=True)
        torch.save(payload, t2m / name / "model" / file)
        write_opt(t2m / name / "opt.txt", {**common, "name": name, **options})
    meta = t2m / "rvq_nq6_dc512_nc512_noshare_qdp0.2" / "meta"
    meta.mkdir()
    rng = np.random.default_rng(0)
    out["mean"] = rng.normal(size=d.input_dim).astype(np.float32)
    out["std"] = rng.uniform(0.05, 1.0, size=d.input_dim).astype(np.float32)
    np.save(meta / "mean.npy", out["mean"])
    np.save(meta / "std.npy", out["std"])
    out["t2m"] = t2m
    return out


# -- the official forward passes, re-implemented on raw state_dicts -----------------------------------
def _c(x, sd, name, stride=1, padding=1, dilation=1):
    return F.conv1d(
        x, sd[f"{name}.weight"], sd[f"{name}.bias"], stride=stride, padding=padding, dilation=dilation
    )


def _res_blocks(x, sd, prefix, d: Dims):
    for j in range(d.depth):
        dil = d.growth ** (d.depth - 1 - j)  # reverse_dilation: 9, 3, 1
        h = _c(F.relu(x), sd, f"{prefix}.{j}.conv1", padding=dil, dilation=dil)
        x = x + _c(F.relu(h), sd, f"{prefix}.{j}.conv2", padding=0)
    return x


def ref_conv_encoder(x, sd, prefix, d: Dims):
    """Official ``Encoder``: (B, C, T) -> (B, C_out, T / 4)."""
    x = F.relu(_c(x, sd, f"{prefix}.model.0"))
    for i in range(d.down_t):
        x = _c(x, sd, f"{prefix}.model.{2 + i}.0", stride=2, padding=1)
        x = _res_blocks(x, sd, f"{prefix}.model.{2 + i}.1.model", d)
    return _c(x, sd, f"{prefix}.model.{2 + d.down_t}")


def ref_vq_decode(sd, ids, d: Dims):
    """Official ``RVQVAE.forward_decoder``: ids (B, N, q<=Q), -1 = no code -> features (B, 4N, 263)."""
    ids = F.pad(ids, (0, d.num_q - ids.shape[-1]), value=-1)
    latent = 0
    for q in range(d.num_q):
        book = sd[f"quantizer.layers.{q}.codebook"]
        idx = ids[..., q]
        latent = latent + torch.where((idx >= 0)[..., None], book[idx.clamp(min=0)], torch.zeros(()))
    x = F.relu(_c(latent.permute(0, 2, 1), sd, "decoder.model.0"))
    for i in range(d.down_t):
        x = _res_blocks(x, sd, f"decoder.model.{2 + i}.0.model", d)
        x = _c(x.repeat_interleave(2, dim=-1), sd, f"decoder.model.{2 + i}.2")
    x = F.relu(_c(x, sd, f"decoder.model.{2 + d.down_t}"))
    return _c(x, sd, f"decoder.model.{4 + d.down_t}").permute(0, 2, 1)


def _lin(x, sd, name):
    return x @ sd[f"{name}.weight"].T + sd[f"{name}.bias"]


def _ln(x, sd, name, eps):
    mu = x.mean(-1, keepdim=True)
    var = ((x - mu) ** 2).mean(-1, keepdim=True)
    return (x - mu) / torch.sqrt(var + eps) * sd[f"{name}.weight"] + sd[f"{name}.bias"]


def ref_encoder_layer(x, sd, p, heads, pad):
    """Post-LN ``TransformerEncoderLayer`` (GELU, eps 1e-5) on (S, B, D); ``pad`` (B, S) True = padded key."""
    s, b, dim = x.shape
    hd = dim // heads
    qkv = x @ sd[f"{p}.self_attn.in_proj_weight"].T + sd[f"{p}.self_attn.in_proj_bias"]
    q, k, v = (t.reshape(s, b, heads, hd).permute(1, 2, 0, 3) for t in qkv.split(dim, dim=-1))
    scores = (q @ k.transpose(-1, -2)) / math.sqrt(hd)
    scores = scores.masked_fill(pad[:, None, None, :], float("-inf"))
    attn = (scores.softmax(-1) @ v).permute(2, 0, 1, 3).reshape(s, b, dim)
    x = _ln(x + _lin(attn, sd, f"{p}.self_attn.out_proj"), sd, f"{p}.norm1", 1e-5)
    ff = _lin(F.gelu(_lin(x, sd, f"{p}.linear1")), sd, f"{p}.linear2")
    return _ln(x + ff, sd, f"{p}.norm2", 1e-5)


def _ref_head(sd, h):
    h = _ln(F.gelu(_lin(h, sd, "output_process.dense")), sd, "output_process.LayerNorm", 1e-12)
    return _lin(h, sd, "output_process.poseFinal").permute(1, 0, 2)


def _ref_xseq(sd, tokens, cond, pad):
    e = sd["token_emb.weight"][tokens] if tokens.dtype == torch.long else tokens
    x = _lin(e, sd, "input_process.poseEmbedding").permute(1, 0, 2)
    x = x + sd["position_enc.pe"][: x.shape[0]]
    c = _lin(cond, sd, "cond_emb")[None]
    return torch.cat([c, x]), torch.cat([torch.zeros_like(pad[:, :1]), pad], dim=1)


def ref_mask_logits(sd, tokens, cond, pad, d: Dims):
    """Official ``MaskTransformer.trans_forward``: logits (B, N, nb_code)."""
    h, mask = _ref_xseq(sd, tokens, cond, pad)
    for i in range(d.layers):
        h = ref_encoder_layer(h, sd, f"seqTransEncoder.layers.{i}", d.heads, mask)
    return _ref_head(sd, h[1:])


def ref_residual_logits(sd, ids, q: int, cond, pad, d: Dims):
    """Official ``ResidualTransformer`` logits (B, N, nb_code + 1) of layer ``q`` given ids (B, N, >= q)."""
    emb = torch.cat([sd["token_embed_weight_"], sd["embed_proj_shared_weight"]])
    proj = torch.cat([sd["embed_proj_shared_weight"], sd["output_proj_weight_"]])
    history = sum(emb[j][ids[..., j]] for j in range(q))
    x = (
        _lin(history, sd, "input_process.poseEmbedding").permute(1, 0, 2)
        + sd["position_enc.pe"][: ids.shape[1]]
    )
    onehot = F.one_hot(torch.full((ids.shape[0],), q), d.num_q).to(cond.dtype)
    h = torch.cat([_lin(cond, sd, "cond_emb")[None], _lin(onehot, sd, "quant_emb")[None], x])
    mask = torch.cat([torch.zeros_like(pad[:, :2]), pad], dim=1)
    for i in range(d.layers):
        h = ref_encoder_layer(h, sd, f"seqTransEncoder.layers.{i}", d.heads, mask)
    out = _ref_head(sd, h[2:])  # (B, N, code_dim)
    return torch.einsum("kc,bnc->bnk", proj[q - 1], out)


def ref_control_input(targets, mask, current, trajectory: bool):
    """MaskControl ``ctrlNet_cond``: [(S - G) sigma, S sigma] of the control joints, channels-first."""
    rel = (targets - current) * mask[..., None]
    absolute = targets * mask[..., None]
    if trajectory:
        rel, absolute = rel[:, :, 0], absolute[:, :, 0]
    else:
        rel = rel[:, :, CONTROL_JOINTS].reshape(*rel.shape[:2], -1)
        absolute = absolute[:, :, CONTROL_JOINTS].reshape(*absolute.shape[:2], -1)
    return torch.cat([rel, absolute], dim=-1).permute(0, 2, 1)


def ref_control_logits(sd, tokens, cond, pad, ctrl, d: Dims):
    """Official ``ControlTransformer.trans_forward`` with the control net on: logits (B, N, nb_code)."""
    xseq, mask = _ref_xseq(sd, tokens, cond, pad)
    c = _lin(ref_conv_encoder(ctrl, sd, "encoder_control", d).permute(2, 0, 1), sd, "first_zero_linear")
    h0 = xseq + torch.cat([torch.zeros_like(xseq[:1]), c])
    g, residuals = h0, []
    for i in range(d.layers):
        g = ref_encoder_layer(g, sd, f"seqTransEncoder_control.layers.{i}", d.heads, mask)
        residuals.append(_lin(g, sd, f"mid_zero_linear.{i}"))
    h = h0
    for i in range(d.layers):
        h = ref_encoder_layer(h, sd, f"seqTransEncoder.layers.{i}", d.heads, mask) + residuals[i]
    return _ref_head(sd, h[1:])
