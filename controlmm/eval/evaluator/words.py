"""Words of a caption for the project's evaluator: tokenisation and the training vocabulary.

The evaluator's text side is deliberately independent of the generator's sentence encoder (MiniLM):
it reads lower-cased words of the raw caption, looks them up in a vocabulary built from the
training captions only, and learns its own word embeddings (as the HumanML3D evaluator reads
GloVe vectors of its own vocabulary). Words not in the vocabulary become ``<unk>``; captions are
wrapped in ``<sos>``/``<eos>`` and cut to ``max_words`` words, like the official evaluator's
22-token input (20 words + sos + eos).
"""

from __future__ import annotations

import re
from collections import Counter
from collections.abc import Iterable, Sequence
from dataclasses import dataclass

import torch

from controlmm.errors import ControlMMError

PAD, UNK, SOS, EOS = "<pad>", "<unk>", "<sos>", "<eos>"
SPECIALS = (PAD, UNK, SOS, EOS)
_WORD = re.compile(r"[a-z]+|[0-9]+")


def tokenize(text: str) -> list[str]:
    """Lower-cased words and digit runs of a caption: ``"Waves 3 times."`` -> ``["waves", "3", "times"]``."""
    return _WORD.findall(text.lower())


@dataclass(frozen=True)
class Vocabulary:
    """Words known to the evaluator (index 0..3 are ``<pad> <unk> <sos> <eos>``)."""

    words: tuple[str, ...]
    max_words: int = 20

    def __post_init__(self) -> None:
        if tuple(self.words[: len(SPECIALS)]) != SPECIALS:
            raise ControlMMError(f"a vocabulary must start with {', '.join(SPECIALS)}")
        if len(set(self.words)) != len(self.words):
            raise ControlMMError("the vocabulary lists a word twice")
        object.__setattr__(self, "_index", {w: i for i, w in enumerate(self.words)})

    @classmethod
    def build(cls, captions: Iterable[str], min_count: int = 1, max_words: int = 20) -> Vocabulary:
        """Every word used at least ``min_count`` times in ``captions``, most frequent first."""
        counts = Counter(w for c in captions for w in tokenize(c))
        ranked = sorted((w for w, n in counts.items() if n >= min_count), key=lambda w: (-counts[w], w))
        return cls(SPECIALS + tuple(ranked), max_words)

    def __len__(self) -> int:
        return len(self.words)

    def index(self, word: str) -> int:
        return self._index.get(word, 1)  # type: ignore[attr-defined]

    def unknown_share(self, captions: Sequence[str]) -> float:
        """Fraction of the words of ``captions`` that are not in the vocabulary (0..1)."""
        words = [w for c in captions for w in tokenize(c)]
        return sum(w not in self._index for w in words) / max(len(words), 1)  # type: ignore[attr-defined]

    def encode(self, captions: Sequence[str]) -> tuple[torch.Tensor, torch.Tensor]:
        """Captions -> token ids (B, max_words + 2) int64 (sos, words, eos, pad...) and lengths (B,)."""
        rows = []
        for caption in captions:
            words = tokenize(caption)[: self.max_words]
            rows.append([2] + [self.index(w) for w in words] + [3])
        ids = torch.zeros(len(rows), self.max_words + 2, dtype=torch.long)
        for i, row in enumerate(rows):
            ids[i, : len(row)] = torch.tensor(row)
        return ids, torch.tensor([len(r) for r in rows], dtype=torch.long)
