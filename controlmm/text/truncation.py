"""A prompt longer than what a text encoder reads is cut; say so instead of cutting silently."""

from __future__ import annotations

import warnings
from collections.abc import Sequence


class TextTruncatedWarning(UserWarning):
    """A prompt had more tokens than the text encoder (or the token-state view) reads."""


def warn_truncated(texts: Sequence[str], counts: Sequence[int], limit: int, reader: str) -> None:
    """Warn once per text whose token count (special tokens included) exceeds ``limit``."""
    for text, count in zip(texts, counts, strict=True):
        if count > limit:
            shown = text if len(text) <= 60 else text[:57] + "..."
            warnings.warn(
                f"the prompt '{shown}' has {count} tokens; {reader} reads only the first {limit}, "
                "the rest is ignored (shorten the prompt)",
                TextTruncatedWarning,
                stacklevel=3,
            )
