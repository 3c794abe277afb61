"""The persistent prompt-embedding cache: where it lives, what a hit returns, and that a corrupt entry,
an entry of another model version or of another text is rebuilt, never trusted."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
import torch

from controlmm.text.embedding_cache import CACHE_ENV, EmbeddingCache, user_cache_dir
from controlmm.text.minilm import CACHED_BATCH, MiniLMTextEncoder

PROMPTS = ["a person walks forward", "someone waves with the right hand"]


def test_cache_location_follows_the_environment(monkeypatch, tmp_path):
    monkeypatch.setenv(CACHE_ENV, str(tmp_path / "mine"))
    assert user_cache_dir() == tmp_path / "mine"
    monkeypatch.setenv(CACHE_ENV, "")
    assert user_cache_dir() is None  # empty: no persistent cache
    monkeypatch.delenv(CACHE_ENV)
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    assert user_cache_dir() == tmp_path / "xdg" / "controlmm"
    monkeypatch.delenv("XDG_CACHE_HOME")
    monkeypatch.setenv("HOME", str(tmp_path / "home"))
    assert user_cache_dir() == tmp_path / "home" / ".cache" / "controlmm"


def _files(cache: EmbeddingCache) -> list:
    assert cache.directory is not None
    return sorted(cache.directory.glob("*.npz"))


def test_a_cached_prompt_gives_the_same_outputs_without_the_model(tmp_path):
    fresh = MiniLMTextEncoder(cache=False)
    expected = fresh.encode(PROMPTS)
    states = fresh.encode_tokens(PROMPTS, 64)
    first = MiniLMTextEncoder(cache=EmbeddingCache(fresh.identity, 384, tmp_path))
    assert torch.equal(first.encode(PROMPTS), expected)
    assert first.cache is not None and len(_files(first.cache)) == 2
    # a new encoder (a new process) reads the entries: identical vectors, token states and counts
    again = MiniLMTextEncoder(cache=EmbeddingCache(fresh.identity, 384, tmp_path))
    entry = again.cache.get(PROMPTS[0]) if again.cache else None
    assert entry is not None and entry.tokens == entry.states.shape[0] == 6  # [CLS] 4 words [SEP]
    assert torch.equal(again.encode(PROMPTS), expected)
    assert torch.equal(again.encode_tokens(PROMPTS, 64), states)
    vectors, both = again.encode_with_tokens(PROMPTS, 4)
    assert torch.equal(vectors, expected) and torch.equal(both, states[:, :4])


def test_a_corrupt_or_foreign_entry_is_rebuilt(tmp_path):
    encoder = MiniLMTextEncoder(cache=False)
    expected = encoder.encode(PROMPTS[:1])[0].numpy()
    cache = EmbeddingCache(encoder.identity, 384, tmp_path)
    MiniLMTextEncoder(cache=cache).encode(PROMPTS[:1])
    (path,) = _files(cache)

    def rebuilt() -> np.ndarray:
        vector = MiniLMTextEncoder(cache=EmbeddingCache(encoder.identity, 384, tmp_path)).encode(PROMPTS[:1])
        good = cache.get(PROMPTS[0])  # the entry was rewritten and is good again
        assert good is not None and np.array_equal(good.vector, expected)
        return vector[0].numpy()

    original = path.read_bytes()
    for damage in (
        lambda: path.write_bytes(b"garbage"),  # not an npz at all
        lambda: path.write_bytes(original[: len(original) // 2]),  # truncated
    ):
        damage()
        assert cache.get(PROMPTS[0]) is None
        np.testing.assert_array_equal(rebuilt(), expected)

    def rewrite(**changes) -> None:
        with np.load(path) as data:
            arrays = {k: data[k] for k in data.files}
        arrays.update(changes)
        np.savez(path, **arrays)

    wrong_vector = np.full(384, 0.5, np.float32)
    for bad in (
        {"vector": wrong_vector[:100]},  # wrong shape
        {"vector": np.full(384, np.nan, np.float32)},  # not finite
        {"meta": np.array(["1", "minilm:0.0.9:another-model", PROMPTS[0]])},  # another model version
        {"meta": np.array(["1", encoder.identity, "another text"]), "vector": wrong_vector},  # collision
        {"meta": np.array(["0", encoder.identity, PROMPTS[0]]), "vector": wrong_vector},  # old format
    ):
        rewrite(**bad)
        assert cache.get(PROMPTS[0]) is None
        np.testing.assert_array_equal(rebuilt(), expected)
    # another model version keys its own directory: nothing is shared
    other = EmbeddingCache("minilm:9.9:other", 384, tmp_path)
    assert other.directory != cache.directory and other.get(PROMPTS[0]) is None


def test_caption_sets_bypass_the_cache_and_a_read_only_cache_warns_once(tmp_path):
    encoder = MiniLMTextEncoder(cache=EmbeddingCache("minilm:test", 384, tmp_path / "c"))
    captions = [f"a person walks {k} steps" for k in range(CACHED_BATCH + 1)]
    encoder.encode(captions)
    assert not (tmp_path / "c").exists()  # training-sized requests write nothing
    blocked = tmp_path / "blocked"
    blocked.write_text("a file where the cache directory should be")
    stuck = MiniLMTextEncoder(cache=EmbeddingCache("minilm:test", 384, blocked))
    with pytest.warns(UserWarning, match="cannot write the text-embedding cache"):
        first = stuck.encode(PROMPTS[:1])
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert torch.equal(stuck.encode(PROMPTS[1:]), MiniLMTextEncoder(cache=False).encode(PROMPTS[1:]))
    assert first.shape == (1, 384)
