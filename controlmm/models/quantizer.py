"""Residual vector quantizer with EMA codebooks and dead-code reset (MoMask ``ResidualVQ``).

Each layer ``quantizer.layers.{i}`` owns a separate codebook buffer ``codebook`` (nb_code, code_dim).
Residual quantization of an encoder latent z: r_0 = z; c_i = nearest code of r_i; r_{i+1} = r_i - q_i;
the quantized latent is sum_i q_i (straight-through in z space).

Training-time behaviour (all as in MoMask):
- the code choice is ``argmax(-dist / temp + Gumbel)`` (temp 0.5), ``argmin(dist)`` in eval mode;
- codebooks are initialised from the first batch's latents and updated by EMA (decay ``mu``) of the
  assigned latents; codes whose EMA count falls below 1 are replaced by random latents of the current
  batch (dead-code reset);
- quantizer dropout: with probability ``quantize_dropout_prob`` per batch, a cut-off s ~ U{0..Q-1} is
  drawn and layers above s are skipped (their indices are -1).

Under ``torch.distributed`` the EMA statistics are summed over processes and the reset candidates and
first-batch initialisation come from rank 0, so every process keeps identical codebooks.
"""

from __future__ import annotations

from typing import cast

import torch
import torch.distributed as dist
import torch.nn.functional as F
from torch import nn

from controlmm.models.layers import gumbel_noise


def _distributed() -> bool:
    return dist.is_available() and dist.is_initialized() and dist.get_world_size() > 1


class QuantizeEMAReset(nn.Module):
    """One codebook with EMA updates and dead-code reset; works on (B, C, T) latents."""

    # Buffers (registered in __init__).
    codebook: torch.Tensor  # (nb_code, code_dim)
    code_sum: torch.Tensor  # (nb_code, code_dim) EMA of the assigned latents' sum
    code_count: torch.Tensor  # (nb_code,) EMA of the assignment counts
    initted: torch.Tensor  # () bool: the codebook was initialised from a batch

    def __init__(self, nb_code: int, code_dim: int, mu: float) -> None:
        super().__init__()
        self.nb_code, self.code_dim, self.mu = nb_code, code_dim, mu
        self.register_buffer("codebook", torch.zeros(nb_code, code_dim))
        # EMA state: not part of the official state_dict; training checkpoints save it explicitly.
        self.register_buffer("code_sum", torch.zeros(nb_code, code_dim), persistent=False)
        self.register_buffer("code_count", torch.zeros(nb_code), persistent=False)
        self.register_buffer("initted", torch.tensor(False), persistent=False)

    def _tile(self, x: torch.Tensor) -> torch.Tensor:
        """Repeat x (n, C) with small noise until it has at least nb_code rows."""
        n = x.shape[0]
        if n >= self.nb_code:
            return x
        repeats = (self.nb_code + n - 1) // n
        out = x.repeat(repeats, 1)
        return out + torch.randn_like(out) * (0.01 / self.code_dim**0.5)

    def _random_rows(self, x: torch.Tensor) -> torch.Tensor:
        """nb_code random rows of the tiled batch (identical on every process)."""
        out = self._tile(x)
        rows = out[torch.randperm(out.shape[0], device=out.device)[: self.nb_code]].contiguous()
        if _distributed():
            dist.broadcast(rows, src=0)
        return rows

    @torch.no_grad()
    def init_codebook(self, x: torch.Tensor) -> None:
        rows = self._tile(x)[: self.nb_code].contiguous()
        if _distributed():
            dist.broadcast(rows, src=0)
        self.codebook.copy_(rows)
        self.code_sum.copy_(rows)
        self.code_count.fill_(1.0)
        self.initted.fill_(True)

    def quantize(self, x: torch.Tensor, temperature: float = 0.0) -> torch.Tensor:
        """Code index of each row of x (n, C): nearest code (eval) or Gumbel choice (training)."""
        code = self.codebook
        distance = x.pow(2).sum(-1, keepdim=True) - 2.0 * x @ code.t() + code.pow(2).sum(-1)[None, :]
        logits = -distance
        if self.training and temperature > 0:
            logits = logits / temperature + gumbel_noise(logits)
        return logits.argmax(dim=-1)

    def dequantize(self, code_idx: torch.Tensor) -> torch.Tensor:
        return F.embedding(code_idx, self.codebook)

    @torch.no_grad()
    def update_codebook(self, x: torch.Tensor, code_idx: torch.Tensor) -> torch.Tensor:
        """EMA update plus dead-code reset from batch latents x (n, C); returns the perplexity."""
        onehot = F.one_hot(code_idx, self.nb_code).to(x.dtype)  # (n, K)
        code_sum = onehot.t() @ x  # (K, C)
        code_count = onehot.sum(0)  # (K,)
        if _distributed():
            dist.all_reduce(code_sum)
            dist.all_reduce(code_count)
        code_rand = self._random_rows(x)
        self.code_sum.mul_(self.mu).add_(code_sum, alpha=1.0 - self.mu)
        self.code_count.mul_(self.mu).add_(code_count, alpha=1.0 - self.mu)
        usage = (self.code_count >= 1.0).to(x.dtype)[:, None]
        code_update = self.code_sum / self.code_count.clamp(min=1e-12)[:, None]
        self.codebook.copy_(usage * code_update + (1.0 - usage) * code_rand)
        return _perplexity(code_count)

    def forward(
        self, x: torch.Tensor, temperature: float = 0.0
    ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]:
        """Quantize (B, C, T) -> (quantized (B, C, T), indices (B, T), commit loss, perplexity)."""
        b, c, t = x.shape
        flat = x.permute(0, 2, 1).reshape(b * t, c)
        if self.training and not bool(self.initted):
            self.init_codebook(flat)
        code_idx = self.quantize(flat, temperature)
        x_d = self.dequantize(code_idx)
        if self.training:
            perplexity = self.update_codebook(flat, code_idx)  # x_d keeps the pre-update codes
        else:
            perplexity = _perplexity(torch.bincount(code_idx, minlength=self.nb_code).to(flat.dtype))
        commit_loss = F.mse_loss(flat, x_d.detach())
        x_d = flat + (x_d - flat).detach()
        return x_d.view(b, t, c).permute(0, 2, 1), code_idx.view(b, t), commit_loss, perplexity


def _perplexity(code_count: torch.Tensor) -> torch.Tensor:
    prob = code_count / code_count.sum().clamp(min=1e-12)
    return torch.exp(-(prob * torch.log(prob + 1e-7)).sum())


class ResidualVQ(nn.Module):
    """``num_quantizers`` :class:`QuantizeEMAReset` layers applied to successive residuals."""

    def __init__(
        self, num_quantizers: int, nb_code: int, code_dim: int, mu: float, quantize_dropout_prob: float
    ) -> None:
        super().__init__()
        self.num_quantizers = num_quantizers
        self.quantize_dropout_prob = quantize_dropout_prob
        self.layers = nn.ModuleList(QuantizeEMAReset(nb_code, code_dim, mu) for _ in range(num_quantizers))

    @property
    def quantizers(self) -> list[QuantizeEMAReset]:
        """``layers`` with their type (a type checker sees the items of an ``nn.ModuleList`` as plain
        modules)."""
        return cast(list[QuantizeEMAReset], list(self.layers))

    @property
    def codebooks(self) -> torch.Tensor:
        """(Q, nb_code, code_dim) stacked codebooks."""
        return torch.stack([layer.codebook for layer in self.quantizers])

    def _draw_dropout_cut(self, device: torch.device) -> int:
        """Quantizer dropout: the last kept layer (Q = none dropped), the same on every process."""
        cut = torch.tensor([self.num_quantizers], device=device)
        if float(torch.rand(())) < self.quantize_dropout_prob:
            cut[0] = int(torch.randint(0, self.num_quantizers, ()))
        if _distributed():
            dist.broadcast(cut, src=0)
        return int(cut[0])

    def forward(
        self, x: torch.Tensor, temperature: float = 0.0, force_dropout_index: int = -1
    ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]:
        """Quantize (B, C, T).

        Returns:
            quantized (B, C, T) straight-through sum of the used layers, indices (B, T, Q) with -1 for
            skipped layers, mean commitment loss over used layers, mean perplexity over used layers.
        """
        with torch.autocast(x.device.type, enabled=False):  # nearest-code search needs float32
            return self._forward(x.float(), temperature, force_dropout_index)

    def _forward(
        self, x: torch.Tensor, temperature: float, force_dropout_index: int
    ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]:
        b, _, t = x.shape
        cut = self.num_quantizers
        if force_dropout_index >= 0:
            cut = force_dropout_index
        elif self.training and self.quantize_dropout_prob > 0:
            cut = self._draw_dropout_cut(x.device)
        residual = x
        quantized_out = torch.zeros_like(x)
        indices: list[torch.Tensor] = []
        losses: list[torch.Tensor] = []
        perplexities: list[torch.Tensor] = []
        for i, layer in enumerate(self.quantizers):
            if i > cut:
                indices.append(torch.full((b, t), -1, dtype=torch.long, device=x.device))
                continue
            quantized, idx, loss, perplexity = layer(residual, temperature)
            residual = residual - quantized.detach()
            quantized_out = quantized_out + quantized
            indices.append(idx)
            losses.append(loss)
            perplexities.append(perplexity)
        return (
            quantized_out,
            torch.stack(indices, dim=-1),
            torch.stack(losses).mean(),
            torch.stack(perplexities).mean(),
        )

    @torch.no_grad()
    def quantize(self, x: torch.Tensor) -> torch.Tensor:
        """Deterministic indices (B, T, Q) of (B, C, T) latents with all layers (eval behaviour)."""
        residual = x
        indices = []
        for layer in self.quantizers:
            b, c, t = residual.shape
            flat = residual.permute(0, 2, 1).reshape(b * t, c)
            code = layer.codebook
            distance = (
                flat.pow(2).sum(-1, keepdim=True) - 2.0 * flat @ code.t() + code.pow(2).sum(-1)[None, :]
            )
            idx = distance.argmin(dim=-1)
            residual = residual - layer.dequantize(idx).view(b, t, c).permute(0, 2, 1)
            indices.append(idx.view(b, t))
        return torch.stack(indices, dim=-1)

    def get_codes_from_indices(self, indices: torch.Tensor) -> torch.Tensor:
        """(B, N, q <= Q) indices (-1 = none) -> (Q, B, N, code_dim) code vectors (zeros for -1)."""
        b, n, q = indices.shape
        if q < self.num_quantizers:
            indices = F.pad(indices, (0, self.num_quantizers - q), value=-1)
        codes = []
        for i, layer in enumerate(self.quantizers):
            idx = indices[..., i]
            vec = layer.dequantize(idx.clamp(min=0))
            codes.append(vec * (idx >= 0)[..., None].to(vec.dtype))
        return torch.stack(codes)

    def ema_state(self) -> dict[str, torch.Tensor]:
        """EMA statistics of every layer (for training checkpoints)."""
        state = {}
        for i, layer in enumerate(self.quantizers):
            state[f"{i}.code_sum"] = layer.code_sum.detach().clone()
            state[f"{i}.code_count"] = layer.code_count.detach().clone()
            state[f"{i}.initted"] = layer.initted.detach().clone()
        return state

    def load_ema_state(self, state: dict[str, torch.Tensor]) -> None:
        for i, layer in enumerate(self.quantizers):
            layer.code_sum.copy_(state[f"{i}.code_sum"])
            layer.code_count.copy_(state[f"{i}.code_count"])
            layer.initted.copy_(state[f"{i}.initted"])
