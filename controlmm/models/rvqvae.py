"""RVQ-VAE motion tokenizer (MoMask ``RVQVAE``), module for module and name for name.

Shapes (paper preset): normalised features (B, T, 263) -> encoder (B, 512, T/4) -> residual quantizer
(6 layers x 512 codes x 512 dims) -> decoder -> (B, T, 263). Convolutions run over time,
channels-first. State-dict names match the official checkpoint:

    encoder.model.0                 Conv1d(263 -> width, k3)           (1 = ReLU)
    encoder.model.{2,3}.0           Conv1d(width -> width, k4, s2)     downsampling
    encoder.model.{2,3}.1.model.{j} ResConv1DBlock (conv1 k3 dilated, conv2 k1), dilations 9, 3, 1
    encoder.model.4                 Conv1d(width -> code_dim, k3)
    decoder.model.0                 Conv1d(code_dim -> width, k3)      (1 = ReLU)
    decoder.model.{2,3}.0.model.{j} ResConv1DBlock, dilations 9, 3, 1 (2.1 = nearest Upsample x2)
    decoder.model.{2,3}.2           Conv1d(width -> width, k3)
    decoder.model.4                 Conv1d(width -> width, k3)         (5 = ReLU)
    decoder.model.6                 Conv1d(width -> 263, k3)
    quantizer.layers.{i}.codebook   (nb_code, code_dim) buffers
"""

from __future__ import annotations

from typing import TypedDict

import torch
import torch.nn.functional as F
from torch import nn

from controlmm.models.config import TokenizerConfig
from controlmm.models.quantizer import ResidualVQ


class ResConv1DBlock(nn.Module):
    """x + Dropout(conv2(ReLU(conv1(ReLU(x))))), conv1 dilated k3, conv2 k1; no normalisation."""

    def __init__(self, width: int, dilation: int, dropout: float) -> None:
        super().__init__()
        self.conv1 = nn.Conv1d(width, width, 3, 1, padding=dilation, dilation=dilation)
        self.conv2 = nn.Conv1d(width, width, 1, 1, 0)
        self.dropout = nn.Dropout(dropout)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        h = self.conv2(F.relu(self.conv1(F.relu(x))))
        return x + self.dropout(h)


class Resnet1D(nn.Module):
    """``depth`` residual blocks with dilations growth**d, **reversed** (9, 3, 1 for depth 3)."""

    def __init__(self, width: int, depth: int, growth: int, dropout: float) -> None:
        super().__init__()
        blocks = [ResConv1DBlock(width, growth**d, dropout) for d in range(depth)][::-1]
        self.model = nn.Sequential(*blocks)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.model(x)


class Encoder(nn.Module):
    """(B, C_in, T) -> (B, C_out, T / stride**down_t); also the control branch's encoder (C_in 6/36)."""

    def __init__(
        self,
        input_dim: int,
        output_dim: int,
        width: int,
        down_t: int = 2,
        stride_t: int = 2,
        depth: int = 3,
        growth: int = 3,
        dropout: float = 0.2,
    ) -> None:
        super().__init__()
        blocks: list[nn.Module] = [nn.Conv1d(input_dim, width, 3, 1, 1), nn.ReLU()]
        for _ in range(down_t):
            blocks.append(
                nn.Sequential(
                    nn.Conv1d(width, width, stride_t * 2, stride_t, stride_t // 2),
                    Resnet1D(width, depth, growth, dropout),
                )
            )
        blocks.append(nn.Conv1d(width, output_dim, 3, 1, 1))
        self.model = nn.Sequential(*blocks)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.model(x)


class Decoder(nn.Module):
    """(B, code_dim, N) latents -> (B, N * stride**down_t, output_dim) features (time-major output)."""

    def __init__(
        self,
        output_dim: int,
        code_dim: int,
        width: int,
        down_t: int = 2,
        stride_t: int = 2,
        depth: int = 3,
        growth: int = 3,
        dropout: float = 0.2,
    ) -> None:
        super().__init__()
        blocks: list[nn.Module] = [nn.Conv1d(code_dim, width, 3, 1, 1), nn.ReLU()]
        for _ in range(down_t):
            blocks.append(
                nn.Sequential(
                    Resnet1D(width, depth, growth, dropout),
                    nn.Upsample(scale_factor=stride_t, mode="nearest"),
                    nn.Conv1d(width, width, 3, 1, 1),
                )
            )
        blocks += [nn.Conv1d(width, width, 3, 1, 1), nn.ReLU(), nn.Conv1d(width, output_dim, 3, 1, 1)]
        self.model = nn.Sequential(*blocks)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.model(x).permute(0, 2, 1)


class _ConvOptions(TypedDict):
    """The options the encoder and the decoder share."""

    width: int
    down_t: int
    stride_t: int
    depth: int
    growth: int
    dropout: float


class RVQVAE(nn.Module):
    """The motion tokenizer: encoder, residual quantizer, decoder."""

    def __init__(self, cfg: TokenizerConfig) -> None:
        super().__init__()
        self.cfg = cfg
        conv = _ConvOptions(
            width=cfg.width,
            down_t=cfg.down_t,
            stride_t=cfg.stride_t,
            depth=cfg.depth,
            growth=cfg.dilation_growth_rate,
            dropout=cfg.resnet_dropout,
        )
        self.encoder = Encoder(cfg.input_dim, cfg.code_dim, **conv)
        self.decoder = Decoder(cfg.input_dim, cfg.code_dim, **conv)
        self.quantizer = ResidualVQ(
            cfg.num_quantizers, cfg.nb_code, cfg.code_dim, cfg.mu, cfg.quantize_dropout_prob
        )

    def forward(self, x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]:
        """Training pass on normalised features (B, T, 263), T a multiple of 4.

        Returns (reconstruction (B, T, 263), commitment loss, perplexity, indices (B, T/4, Q)).
        """
        latent = self.encoder(x.permute(0, 2, 1))
        quantized, indices, commit, perplexity = self.quantizer(latent, self.cfg.sample_codebook_temp)
        return self.decoder(quantized), commit, perplexity, indices

    @torch.no_grad()
    def encode(self, x: torch.Tensor) -> torch.Tensor:
        """Normalised features (B, T, 263) -> deterministic token ids (B, T/4, Q) (eval behaviour)."""
        return self.quantizer.quantize(self.encoder(x.permute(0, 2, 1)))

    def ids_to_latent(self, ids: torch.Tensor) -> torch.Tensor:
        """Token ids (B, N, q <= Q) (-1 = no code) -> decoder input latent (B, N, code_dim)."""
        return self.quantizer.get_codes_from_indices(ids).sum(0)

    def decode_latent(self, latent: torch.Tensor) -> torch.Tensor:
        """Latent (B, N, code_dim) -> normalised features (B, 4N, 263); differentiable."""
        return self.decoder(latent.permute(0, 2, 1))

    def decode(self, ids: torch.Tensor) -> torch.Tensor:
        """Token ids (B, N, q) -> normalised features (B, 4N, 263) (MoMask ``forward_decoder``)."""
        return self.decode_latent(self.ids_to_latent(ids))

    @property
    def codebooks(self) -> torch.Tensor:
        """(Q, nb_code, code_dim) codebooks; ``codebooks[0]`` is the base layer's C_0."""
        return self.quantizer.codebooks
