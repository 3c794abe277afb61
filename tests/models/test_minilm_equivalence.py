"""The plain-transformers MiniLM (controlmm.text.minilm) against the packaged sentence-transformers
pipeline it replaces: the same sentence vectors and token states, prompts short and truncated."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from controlmm.text.minilm import MiniLMTextEncoder

PROMPTS = [
    "a person walks forward",
    "a person walks forward, turns around and sits down on the chair",
    "someone waves with the right hand while stepping to the left",
    "jump",
    "a person crouches under a low beam, then stands up and walks to the table",
    "the man runs in a circle " * 60,  # > 256 word pieces: truncated by both
]


@pytest.fixture(scope="module")
def reference():
    sentence_transformers = pytest.importorskip("sentence_transformers")
    encoder = MiniLMTextEncoder(cache=False)
    return encoder, sentence_transformers.SentenceTransformer(str(encoder.path), device="cpu")


def test_sentence_vectors_match_sentence_transformers(reference):
    encoder, st = reference
    ours = encoder.encode(PROMPTS).numpy()
    theirs = st.encode(PROMPTS, convert_to_numpy=True, normalize_embeddings=False)
    assert ours.shape == theirs.shape == (len(PROMPTS), 384)
    np.testing.assert_allclose(ours, theirs, atol=2e-6, rtol=0)
    np.testing.assert_allclose(np.linalg.norm(ours, axis=1), 1.0, atol=1e-6)


def test_token_states_match_sentence_transformers(reference):
    encoder, st = reference
    states = encoder.encode_tokens(PROMPTS[:3], 64)
    theirs = st.encode(PROMPTS[:3], output_value="token_embeddings", convert_to_tensor=False)
    for i, expected in enumerate(theirs):
        n = len(expected)
        torch.testing.assert_close(states[i, :n], expected.float().cpu(), atol=2e-5, rtol=0)
        assert bool((states[i, n:] == 0).all())  # zero rows pad the shorter prompts
