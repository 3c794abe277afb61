"""Text encoders: the packaged MiniLM (default) and CLIP from weights on disk, and the caption cache."""

from __future__ import annotations

import pytest
import torch

from controlmm.errors import ControlMMError
from controlmm.text import embed_captions, load_text_encoder
from controlmm.text.config import TextEncoderConfig


@pytest.fixture(scope="module")
def minilm():
    return load_text_encoder("minilm")


def test_minilm_sentence_vectors(minilm):
    vectors = minilm.encode(["a person walks forward", "a person walks backwards", "someone jumps twice"])
    assert vectors.shape == (3, 384) and vectors.dtype == torch.float32
    assert torch.allclose(vectors.norm(dim=-1), torch.ones(3), atol=1e-4)
    sims = vectors @ vectors.t()
    assert sims[0, 1] > sims[0, 2]  # the two walking sentences are closer than walking vs jumping
    assert torch.equal(minilm.encode(["a person walks forward"])[0], vectors[0])


def test_empty_text_is_rejected(minilm):
    with pytest.raises(ControlMMError, match="text must not be empty"):
        minilm.encode(["  "])


def test_clip_features_are_the_projected_end_of_text_token(tiny_clip_dir):
    from transformers import AutoTokenizer, CLIPModel

    encoder = load_text_encoder(TextEncoderConfig(name="clip"), weights=str(tiny_clip_dir))
    texts = ["a person walks forward", "someone waves the right hand twice"]
    ours = encoder.encode(texts)
    assert ours.shape == (2, 24) and encoder.dim == 24
    # Independent computation with the library's own CLIP text feature path.
    model = CLIPModel.from_pretrained(tiny_clip_dir, local_files_only=True).eval()
    tok = AutoTokenizer.from_pretrained(tiny_clip_dir, local_files_only=True)
    enc = tok(texts, padding="max_length", max_length=77, truncation=True, return_tensors="pt")
    with torch.no_grad():
        ref = model.get_text_features(input_ids=enc["input_ids"])
    ref = getattr(ref, "pooler_output", ref)
    assert torch.allclose(ours, ref, atol=1e-5)
    assert not torch.allclose(ours.norm(dim=-1), torch.ones(2), atol=1e-2)  # not L2-normalised
    # Tokens after the end-of-text token do not change the feature (causal attention, EOT pooling).
    long = encoder.encode(["a person walks forward " * 30])
    assert long.shape == (1, 24) and torch.isfinite(long).all()


def test_clip_without_weights_is_a_clear_error(tmp_path):
    with pytest.raises(ControlMMError, match="CLIP ViT-B/32 weights not found") as info:
        load_text_encoder(TextEncoderConfig(name="clip"), weights=str(tmp_path / "nowhere"))
    assert "--clip-weights" in str(info.value) and "\n" not in str(info.value)
    (tmp_path / "empty").mkdir()
    with pytest.raises(ControlMMError, match="no config.json"):
        load_text_encoder(TextEncoderConfig(name="clip"), weights=str(tmp_path / "empty"))
    with pytest.raises(ControlMMError, match="unknown text encoder 'bert'"):
        load_text_encoder("bert")


def test_caption_cache_is_one_file_per_caption_set_and_encoder(minilm, tmp_path):
    captions = ["a person walks", "a person runs", "a person walks"]
    first = embed_captions(minilm, captions, cache_dir=tmp_path, progress=False)
    assert first.captions == ("a person walks", "a person runs") and first.vectors.shape == (2, 384)
    files = list(tmp_path.glob("text-minilm-*.pt"))
    assert len(files) == 1
    stamp = files[0].stat().st_mtime_ns
    again = embed_captions(minilm, captions, cache_dir=tmp_path, progress=False)
    assert torch.equal(again.vectors, first.vectors) and files[0].stat().st_mtime_ns == stamp
    files[0].write_bytes(b"garbage")  # a corrupt cache is recomputed, not trusted
    fixed = embed_captions(minilm, captions, cache_dir=tmp_path, progress=False)
    assert torch.allclose(fixed.vectors, first.vectors)
    embed_captions(minilm, ["another set"], cache_dir=tmp_path, progress=False)
    assert len(list(tmp_path.glob("text-minilm-*.pt"))) == 2


def test_minilm_token_states_pool_to_the_sentence_vector(minilm, tmp_path):
    from controlmm.models.layers import pool_text_tokens, text_token_padding

    texts = ["a person walks forward 4 meters and stops.", "someone claps 3 times"]
    states = minilm.encode_tokens(texts, max_tokens=64)
    lengths = (~text_token_padding(states)).sum(dim=1)
    # [CLS] + word pieces + [SEP]; the shorter text is zero-padded to the longer one.
    assert states.shape == (2, int(lengths.max()), 384) and int(lengths[1]) < int(lengths[0])
    assert torch.allclose(pool_text_tokens(states), minilm.encode(texts), atol=1e-5)
    assert torch.equal(minilm.encode_tokens(texts, max_tokens=4), states[:, :4])  # truncation keeps the first
    cached = embed_captions(minilm, texts, cache_dir=tmp_path, progress=False, tokens=64)
    assert cached.vectors.shape == states.shape and len(list(tmp_path.glob("text-minilm-tok64-*.pt"))) == 1
    assert torch.allclose(cached.vectors, states, atol=2e-3 * float(states.abs().max()))  # float16 on disk
    assert torch.equal(
        embed_captions(minilm, texts, cache_dir=tmp_path, progress=False, tokens=64).vectors, cached.vectors
    )


def test_a_prompt_longer_than_minilm_reads_warns_that_it_was_cut():
    from controlmm.text.minilm import MiniLMTextEncoder
    from controlmm.text.truncation import TextTruncatedWarning

    encoder = MiniLMTextEncoder()
    long = "a person walks forward and then turns left " * 40  # about 330 word pieces
    with pytest.warns(TextTruncatedWarning, match="reads only the first 256"):
        encoder.warn_truncated([long])
    with pytest.warns(TextTruncatedWarning, match="token-state text view reads only the first 8"):
        encoder.warn_truncated(["a person walks forward, stops, waves with the left hand and sits"], 8)
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("error", TextTruncatedWarning)
        encoder.warn_truncated(["a person walks forward"], 32)  # short prompts: no warning
        encoder.encode([long])  # encoding alone (training's captions) never warns
