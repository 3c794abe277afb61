"""The official HumanML3D evaluator: strict loading of the official names and shapes, word vectors, errors.

The official files are not available here, so the test writes state dicts with exactly the official
parameter names and shapes (listed below from the released ``finest.tar``; random values), GloVe files
and the normalisation in the official folder layout, and loads them.
"""

from __future__ import annotations

import pickle

import numpy as np
import pytest
import torch

from controlmm.data.humanml3d import Caption
from controlmm.errors import InputFileError
from controlmm.eval.evaluator import OfficialEvaluator, WordVectorizer, load_evaluator

GRU = lambda h_in, h: {  # noqa: E731 - a table helper
    f"gru.{kind}_{part}_l0{rev}": shape
    for rev in ("", "_reverse")
    for kind, part, shape in (
        ("weight", "ih", (3 * h, h_in)),
        ("weight", "hh", (3 * h, h)),
        ("bias", "ih", (3 * h,)),
        ("bias", "hh", (3 * h,)),
    )
}
OFFICIAL = {
    "movement_encoder": {
        "main.0.weight": (512, 259, 4),
        "main.0.bias": (512,),
        "main.3.weight": (512, 512, 4),
        "main.3.bias": (512,),
        "out_net.weight": (512, 512),
        "out_net.bias": (512,),
    },
    "text_encoder": {
        "hidden": (2, 1, 512),
        "pos_emb.weight": (300, 15),
        "pos_emb.bias": (300,),
        "input_emb.weight": (512, 300),
        "input_emb.bias": (512,),
        **GRU(512, 512),
        "output_net.0.weight": (512, 1024),
        "output_net.0.bias": (512,),
        "output_net.1.weight": (512,),
        "output_net.1.bias": (512,),
        "output_net.3.weight": (512, 512),
        "output_net.3.bias": (512,),
    },
    "motion_encoder": {
        "hidden": (2, 1, 1024),
        "input_emb.weight": (1024, 512),
        "input_emb.bias": (1024,),
        **GRU(1024, 1024),
        "output_net.0.weight": (1024, 2048),
        "output_net.0.bias": (1024,),
        "output_net.1.weight": (1024,),
        "output_net.1.bias": (1024,),
        "output_net.3.weight": (512, 1024),
        "output_net.3.bias": (512,),
    },
}
WORDS = ["unk", "sos", "eos", "a", "person", "walk", "forward", "left", "hand", "wave"]


def _write_official(root, state=None, glove=True):
    """The official layout under ``root`` (a MoMask checkout); ``state="layout"`` writes an empty
    finest.tar."""
    t2m = root / "checkpoints" / "t2m"
    (t2m / "text_mot_match" / "model").mkdir(parents=True)
    g = torch.Generator().manual_seed(0)
    if state is None:
        state = {
            part: {k: torch.randn(shape, generator=g) * 0.05 for k, shape in names.items()}
            for part, names in OFFICIAL.items()
        }
    if state == "layout":
        (t2m / "text_mot_match" / "model" / "finest.tar").write_bytes(b"")
    else:
        torch.save({**state, "epoch": 42}, t2m / "text_mot_match" / "model" / "finest.tar")
    meta = t2m / "Comp_v6_KLD005" / "meta"
    meta.mkdir(parents=True)
    np.save(meta / "mean.npy", np.zeros(263, dtype=np.float32))
    np.save(meta / "std.npy", np.ones(263, dtype=np.float32))
    if glove:
        (root / "glove").mkdir()
        vectors = np.random.default_rng(0).normal(size=(len(WORDS), 300)).astype(np.float32)
        np.save(root / "glove" / "our_vab_data.npy", vectors)
        with open(root / "glove" / "our_vab_words.pkl", "wb") as fh:
            pickle.dump(WORDS, fh)
        with open(root / "glove" / "our_vab_idx.pkl", "wb") as fh:
            pickle.dump({w: i for i, w in enumerate(WORDS)}, fh)
    return state


def test_official_state_dicts_load_strictly_and_embed(tmp_path, sample_features):
    state = _write_official(tmp_path)
    evaluator = load_evaluator(tmp_path)
    assert isinstance(evaluator, OfficialEvaluator) and evaluator.dim == 512
    for part in OFFICIAL:  # every official tensor is in the module, with its value
        own = getattr(evaluator, part).state_dict()
        assert set(own) == set(OFFICIAL[part])
        assert all(torch.equal(own[k], state[part][k]) for k in own)
    caption = Caption(
        "a person walks forward", ("a/DET", "person/NOUN", "walk/VERB", "forward/ADV"), 0.0, 0.0
    )
    with pytest.warns(UserWarning, match="word/POS"):  # plain text has no POS tags: a warning, once
        texts = evaluator.embed_texts([caption, "a person waves the left hand"])
    motions = evaluator.embed_motions([sample_features[:120], sample_features[:80]])
    assert (
        texts.shape == (2, 512) == motions.shape
        and np.all(np.isfinite(texts))
        and np.all(np.isfinite(motions))
    )
    # The same checkout found from checkpoints/t2m and from checkpoints/ (GloVe beside the checkout root).
    assert np.allclose(
        load_evaluator(tmp_path / "checkpoints" / "t2m").embed_motions([sample_features[:80]]),
        motions[1:],
        atol=1e-5,
    )
    # A motion's embedding does not depend on the other motions of its batch (zero padding to 196 frames).
    assert np.allclose(evaluator.embed_motions([sample_features[:80]]), motions[1:], atol=1e-5)


def test_word_vectorizer_follows_the_official_rules(tmp_path):
    _write_official(tmp_path)
    words = WordVectorizer(tmp_path / "glove")
    vec, pos = words["walk/VERB"]
    assert np.array_equal(vec, words.word2vec["walk"]) and pos.argmax() == 12  # Act_VIP replaces VERB
    vec, pos = words["person/NOUN"]
    assert pos.argmax() == 1  # NOUN
    vec, pos = words["zebra/NOUN"]
    assert np.array_equal(vec, words.word2vec["unk"]) and pos.argmax() == 14  # unknown: unk, OTHER
    emb, onehot, length = words.sentence(["a/DET", "person/NOUN"])
    assert emb.shape == (22, 300) and onehot.shape == (22, 15) and length == 4
    assert np.array_equal(emb[0], words.word2vec["sos"]) and np.array_equal(emb[3], words.word2vec["eos"])
    assert np.array_equal(emb[4], words.word2vec["unk"])
    _, _, length = words.sentence(["a/DET"] * 25)
    assert length == 22


def test_official_layout_errors(tmp_path):
    with pytest.raises(InputFileError, match="neither an evaluator directory"):
        load_evaluator(tmp_path)
    no_glove = tmp_path / "a"
    _write_official(no_glove, state="layout", glove=False)
    with pytest.raises(InputFileError, match="our_vab_data.npy") as err:
        load_evaluator(no_glove)
    assert "\n" not in str(err.value)

    def state():
        return {
            part: {k: torch.zeros(shape) for k, shape in names.items()} for part, names in OFFICIAL.items()
        }

    for name, edit, needle in (
        (
            "shape",
            lambda s: s["motion_encoder"].update({"output_net.3.weight": torch.zeros(256, 1024)}),
            "motion_encoder' does not fit the configured model; wrong shape: output_net.3.weight",
        ),
        (
            "extra",
            lambda s: s["text_encoder"].update({"extra.weight": torch.zeros(3)}),
            "unexpected: extra.weight",
        ),
        ("missing", lambda s: s["movement_encoder"].pop("out_net.bias"), "missing: out_net.bias"),
        ("part", lambda s: s.pop("motion_encoder"), "has no 'motion_encoder' state dict"),
    ):
        broken = state()
        edit(broken)
        _write_official(tmp_path / name, state=broken)
        with pytest.raises(InputFileError, match=needle):
            load_evaluator(tmp_path / name)
    meta = tmp_path / "d"
    _write_official(meta, state="layout")
    (meta / "checkpoints" / "t2m" / "Comp_v6_KLD005" / "meta" / "std.npy").unlink()
    with pytest.raises(InputFileError, match="std.npy"):
        load_evaluator(meta)
    (meta / "checkpoints" / "t2m" / "Comp_v6_KLD005" / "meta" / "std.npy").write_bytes(b"")
    with pytest.raises(InputFileError, match="finest.tar' is corrupt"):
        load_evaluator(meta)


def test_imported_model_directory_carries_the_official_evaluator(tmp_path):
    """import-official --evaluator copies the files; eval quality/control find them beside the model."""
    from controlmm.eval.evaluator import OfficialEvaluator, load_evaluator, model_evaluator
    from controlmm.models.official.convert import _copy_evaluator

    _write_official(tmp_path / "momask")
    model_dir = tmp_path / "model"
    model_dir.mkdir()
    assert model_evaluator(str(model_dir)) is None
    _copy_evaluator(tmp_path / "momask", model_dir / "evaluator")
    assert model_evaluator([str(model_dir)]) == model_dir / "evaluator"
    assert model_evaluator([str(model_dir), str(tmp_path)]) is None  # several models: no implicit choice
    assert isinstance(load_evaluator(model_evaluator(str(model_dir))), OfficialEvaluator)
