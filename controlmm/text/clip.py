"""CLIP ViT-B/32 text features as the official MoMask/ControlMM code computes them.

Official: ``clip_model.encode_text(clip.tokenize(texts, truncate=True)).float()``, i.e. the final
layer-normed hidden state at the (first) end-of-text token, times ``text_projection``; 77 tokens,
truncated; **not** L2-normalised. The official code converts CLIP to float16 (``clip.model.
convert_weights``: linear/attention weights and the text projection) while its LayerNorms compute in
float32 and cast back; ``precision="float16"`` reproduces that (the LayerNorms stay float32, see
:class:`_Float32LayerNorm`); float32 is the default here. Text is cleaned as the official tokenizer does
(HTML entities unescaped twice, whitespace collapsed, lower case; the ``ftfy`` repair step is skipped:
it changes only mis-encoded text). The pooled token is the first end-of-text token, which is where the
official ``argmax`` over token ids lands (end-of-text has the largest id).

The weights come from disk only: a folder written by ``transformers`` (``CLIPModel.save_pretrained``,
with its tokenizer) or a model id already present in the local Hugging Face cache.
"""

from __future__ import annotations

import html
import re
from collections.abc import Sequence
from pathlib import Path

import torch

from controlmm.errors import ControlMMError
from controlmm.text.base import check_texts, offline, quiet_transformers
from controlmm.text.config import CLIP_MODEL_ID
from controlmm.text.truncation import warn_truncated

CONTEXT_LENGTH = 77


def _missing(where: str) -> ControlMMError:
    return ControlMMError(
        f"CLIP ViT-B/32 weights not found ({where}); pass --clip-weights DIR (a folder saved by "
        f"transformers' CLIPModel.save_pretrained with its tokenizer) or put '{CLIP_MODEL_ID}' in the local "
        "Hugging Face cache; nothing is downloaded (or use --text-encoder minilm)"
    )


class _Float32LayerNorm(torch.nn.Module):
    """A LayerNorm kept in float32 inside a float16 model: input cast up, output cast back (official)."""

    def __init__(self, norm: torch.nn.LayerNorm) -> None:
        super().__init__()
        self.norm = norm.float()

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.norm(x.float()).to(x.dtype)


def _keep_layernorms_float32(module: torch.nn.Module) -> None:
    for name, child in list(module.named_children()):
        if isinstance(child, torch.nn.LayerNorm):
            setattr(module, name, _Float32LayerNorm(child))
        else:
            _keep_layernorms_float32(child)


def clean_text(text: str) -> str:
    """The official CLIP tokenizer's cleaning without ftfy: unescape HTML twice, collapse whitespace."""
    return re.sub(r"\s+", " ", html.unescape(html.unescape(text))).strip()


class CLIPTextEncoder:
    name = "clip"

    def __init__(
        self, weights: str | None = None, device: str | torch.device = "cpu", precision: str = "float32"
    ) -> None:
        offline()
        source = weights or CLIP_MODEL_ID
        path = Path(source).expanduser()
        if path.exists() and not (path / "config.json").is_file():
            raise _missing(f"'{path}' has no config.json")
        if not path.exists() and ("/" not in source or source.startswith((".", "/", "~"))):
            raise _missing(f"'{source}' does not exist")
        try:
            from transformers import AutoTokenizer, CLIPModel  # heavy: only when CLIP is used

            quiet_transformers()
            model = CLIPModel.from_pretrained(str(path) if path.exists() else source, local_files_only=True)
            self.tokenizer = AutoTokenizer.from_pretrained(
                str(path) if path.exists() else source, local_files_only=True
            )
        except ControlMMError:
            raise
        except Exception as exc:  # noqa: BLE001 - any loading failure means: not usable from disk
            raise _missing(f"'{source}': {type(exc).__name__}") from exc
        self.device = torch.device(device)
        dtype = torch.float16 if precision == "float16" else torch.float32
        self.text_model = model.text_model.to(self.device, dtype).eval()
        if dtype == torch.float16:
            _keep_layernorms_float32(self.text_model)
        self.text_projection = model.text_projection.to(self.device, dtype).eval()
        self.dim = int(self.text_projection.out_features)
        self.eos_token_id = int(self.tokenizer.eos_token_id)
        self.identity = f"clip:{source}:{precision}:cleaned"

    def warn_truncated(self, texts: Sequence[str], max_tokens: int | None = None) -> None:
        """Warn (:class:`TextTruncatedWarning`) about prompts longer than CLIP reads (77 tokens)."""
        texts = [clean_text(t) for t in check_texts(texts)]
        counts = [len(ids) for ids in self.tokenizer(texts)["input_ids"]]
        warn_truncated(texts, counts, CONTEXT_LENGTH, "the CLIP text encoder")

    @torch.no_grad()
    def encode(self, texts: Sequence[str]) -> torch.Tensor:
        texts = [clean_text(t) for t in check_texts(texts)]
        enc = self.tokenizer(
            texts, padding="max_length", max_length=CONTEXT_LENGTH, truncation=True, return_tensors="pt"
        )
        ids = enc["input_ids"].to(self.device)
        hidden = self.text_model(input_ids=ids).last_hidden_state  # final layer norm applied
        eot = (ids == self.eos_token_id).int().argmax(dim=-1)
        pooled = hidden[torch.arange(ids.shape[0], device=ids.device), eot]
        return self.text_projection(pooled).float().cpu()
