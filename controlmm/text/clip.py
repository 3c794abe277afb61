"""CLIP ViT-B/32 text features as the official MoMask/ControlMM code computes them.

Official: ``clip_model.encode_text(clip.tokenize(texts, truncate=True)).float()``, i.e. the final
layer-normed hidden state at the (first) end-of-text token, times ``text_projection``; 77 tokens,
truncated; **not** L2-normalised. The official code runs CLIP in float16 on GPU (``precision=
"float16"`` reproduces that); float32 is the default here.

The weights come from disk only: a folder written by ``transformers`` (``CLIPModel.save_pretrained``,
with its tokenizer) or a model id already present in the local Hugging Face cache.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import torch

from controlmm.errors import ControlMMError
from controlmm.models.config import CLIP_MODEL_ID

CONTEXT_LENGTH = 77


def _missing(where: str) -> ControlMMError:
    return ControlMMError(
        f"CLIP ViT-B/32 weights not found ({where}); pass --clip-weights DIR (a folder saved by "
        f"transformers' CLIPModel.save_pretrained with its tokenizer) or put '{CLIP_MODEL_ID}' in the local "
        "Hugging Face cache; nothing is downloaded (or use --text-encoder minilm)")


class CLIPTextEncoder:
    name = "clip"

    def __init__(self, weights: str | None = None, device: str | torch.device = "cpu",
                 precision: str = "float32") -> None:
        from controlmm.text.minilm import offline

        offline()
        source = weights or CLIP_MODEL_ID
        path = Path(source).expanduser()
        if path.exists() and not (path / "config.json").is_file():
            raise _missing(f"'{path}' has no config.json")
        if not path.exists() and ("/" not in source or source.startswith((".", "/", "~"))):
            raise _missing(f"'{source}' does not exist")
        try:
            from transformers import AutoTokenizer, CLIPModel

            model = CLIPModel.from_pretrained(str(path) if path.exists() else source, local_files_only=True)
            self.tokenizer = AutoTokenizer.from_pretrained(str(path) if path.exists() else source,
                                                           local_files_only=True)
        except ControlMMError:
            raise
        except Exception as exc:  # noqa: BLE001 - any loading failure means: not usable from disk
            raise _missing(f"'{source}': {type(exc).__name__}") from exc
        self.device = torch.device(device)
        dtype = torch.float16 if precision == "float16" else torch.float32
        self.text_model = model.text_model.to(self.device, dtype).eval()
        self.text_projection = model.text_projection.to(self.device, dtype).eval()
        self.dim = int(self.text_projection.out_features)
        self.eos_token_id = int(self.tokenizer.eos_token_id)
        self.identity = f"clip:{source}:{precision}"

    @torch.no_grad()
    def encode(self, texts: Sequence[str]) -> torch.Tensor:
        from controlmm.text.base import check_texts

        texts = check_texts(texts)
        enc = self.tokenizer(texts, padding="max_length", max_length=CONTEXT_LENGTH, truncation=True,
                             return_tensors="pt")
        ids = enc["input_ids"].to(self.device)
        hidden = self.text_model(input_ids=ids).last_hidden_state  # final layer norm applied
        eot = (ids == self.eos_token_id).int().argmax(dim=-1)
        pooled = hidden[torch.arange(ids.shape[0], device=ids.device), eot]
        return self.text_projection(pooled).float().cpu()
