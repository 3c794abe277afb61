"""The project's text-motion evaluator: a motion encoder and a text encoder into one embedding space.

It follows the layout of the HumanML3D evaluator (Guo et al. 2022, "Generating Diverse and Natural 3D
Human Motions from Text", CVPR), scaled down to train on a CPU:

- motion: normalised features without the 4 foot contacts (259-d) -> movement encoder (two stride-2
  convolutions, one step per 4 frames, + a linear layer) -> bidirectional GRU over the valid steps
  -> Linear, LayerNorm, LeakyReLU, Linear -> embedding;
- text: word ids -> learned word embeddings (vocabulary of the training captions; HumanML3D uses
  GloVe plus a POS one-hot) -> Linear -> bidirectional GRU -> the same head -> embedding.

Embeddings are L2-normalised and scaled to a sphere of radius ``scale``: retrieval by Euclidean
distance (how R-precision ranks) is then retrieval by cosine similarity, which is what the
contrastive (InfoNCE) training optimises; with the default radius 5 two unrelated motions lie about
7 apart, the order of the official evaluator's distances (Diversity about 9.5 on HumanML3D).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, fields
from typing import Any

import torch
import torch.nn.functional as F
from torch import nn
from torch.nn.utils.rnn import pack_padded_sequence

from controlmm.errors import ControlMMError

MOTION_DIM = 259  # 263-d features without the 4 foot-contact flags, as the official evaluator
UNIT = 4  # frames per movement step (two stride-2 convolutions)


@dataclass(frozen=True)
class EvaluatorConfig:
    """Sizes of the evaluator (``default``: the shipped one; ``tiny``: tests)."""

    vocab_size: int = 4
    word_dim: int = 96
    text_hidden: int = 128
    movement_hidden: int = 192
    motion_hidden: int = 192
    embed_dim: int = 128
    dropout: float = 0.2
    scale: float = 5.0
    max_words: int = 20

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> EvaluatorConfig:
        known = {f.name for f in fields(cls)}
        unknown = sorted(set(data) - known)
        if unknown:
            raise ControlMMError(f"unknown evaluator config field(s): {', '.join(unknown)}")
        return cls(**data)


EVALUATOR_PRESETS: dict[str, EvaluatorConfig] = {
    "default": EvaluatorConfig(),
    "tiny": EvaluatorConfig(word_dim=16, text_hidden=24, movement_hidden=32, motion_hidden=24, embed_dim=16),
}


def _head(hidden: int, out: int) -> nn.Sequential:
    return nn.Sequential(
        nn.Linear(2 * hidden, hidden), nn.LayerNorm(hidden), nn.LeakyReLU(0.2), nn.Linear(hidden, out)
    )


def _bigru_last(gru: nn.GRU, h0: nn.Parameter, x: torch.Tensor, lengths: torch.Tensor) -> torch.Tensor:
    """Final hidden states of both directions of a packed bidirectional GRU: (B, 2H)."""
    packed = pack_padded_sequence(x, lengths.cpu().clamp(min=1), batch_first=True, enforce_sorted=False)
    _, last = gru(packed, h0.expand(-1, x.shape[0], -1).contiguous())
    return torch.cat([last[0], last[1]], dim=-1)


class MovementEncoder(nn.Module):
    """(B, T, 259) normalised features -> (B, T // 4, H) movement features."""

    def __init__(self, hidden: int, dropout: float) -> None:
        super().__init__()
        self.main = nn.Sequential(
            nn.Conv1d(MOTION_DIM, hidden, 4, 2, 1),
            nn.Dropout(dropout),
            nn.LeakyReLU(0.2),
            nn.Conv1d(hidden, hidden, 4, 2, 1),
            nn.Dropout(dropout),
            nn.LeakyReLU(0.2),
        )
        self.out = nn.Linear(hidden, hidden)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.out(self.main(x.transpose(1, 2)).transpose(1, 2))


class MotionEncoder(nn.Module):
    """Movement features (B, N, H_m) and step counts (B,) -> embeddings (B, D) before normalisation."""

    def __init__(self, cfg: EvaluatorConfig) -> None:
        super().__init__()
        self.input = nn.Linear(cfg.movement_hidden, cfg.motion_hidden)
        self.gru = nn.GRU(cfg.motion_hidden, cfg.motion_hidden, batch_first=True, bidirectional=True)
        self.h0 = nn.Parameter(torch.zeros(2, 1, cfg.motion_hidden))
        self.head = _head(cfg.motion_hidden, cfg.embed_dim)

    def forward(self, movements: torch.Tensor, steps: torch.Tensor) -> torch.Tensor:
        return self.head(_bigru_last(self.gru, self.h0, self.input(movements), steps))


class TextEncoder(nn.Module):
    """Token ids (B, L) and lengths (B,) -> embeddings (B, D) before normalisation."""

    def __init__(self, cfg: EvaluatorConfig) -> None:
        super().__init__()
        self.words = nn.Embedding(cfg.vocab_size, cfg.word_dim, padding_idx=0)
        self.input = nn.Linear(cfg.word_dim, cfg.text_hidden)
        self.gru = nn.GRU(cfg.text_hidden, cfg.text_hidden, batch_first=True, bidirectional=True)
        self.h0 = nn.Parameter(torch.zeros(2, 1, cfg.text_hidden))
        self.dropout = nn.Dropout(cfg.dropout)
        self.head = _head(cfg.text_hidden, cfg.embed_dim)

    def forward(self, ids: torch.Tensor, lengths: torch.Tensor) -> torch.Tensor:
        x = self.input(self.dropout(self.words(ids)))
        return self.head(_bigru_last(self.gru, self.h0, x, lengths))


class TextMotionEncoder(nn.Module):
    """Both branches; ``encode_*`` return embeddings on the sphere of radius ``cfg.scale``."""

    def __init__(self, cfg: EvaluatorConfig) -> None:
        super().__init__()
        self.cfg = cfg
        self.movement = MovementEncoder(cfg.movement_hidden, cfg.dropout)
        self.motion = MotionEncoder(cfg)
        self.text = TextEncoder(cfg)

    def encode_motion(self, features: torch.Tensor, lengths: torch.Tensor) -> torch.Tensor:
        """Normalised features (B, T, 263 or 259), T a multiple of 4, valid frames (B,) -> (B, D)."""
        x = features[..., :MOTION_DIM]
        if x.shape[1] % UNIT:
            raise ControlMMError(
                f"motion batches must be padded to a multiple of {UNIT} frames; got {x.shape[1]}"
            )
        steps = torch.div(lengths, UNIT, rounding_mode="floor").clamp(1, x.shape[1] // UNIT)
        return F.normalize(self.motion(self.movement(x), steps), dim=-1) * self.cfg.scale

    def encode_text(self, ids: torch.Tensor, lengths: torch.Tensor) -> torch.Tensor:
        """Token ids (B, L) and lengths (B,) -> (B, D)."""
        return F.normalize(self.text(ids, lengths), dim=-1) * self.cfg.scale
