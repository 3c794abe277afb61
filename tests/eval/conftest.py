"""Fixtures of the evaluation tests: corpora, a tiny evaluator and a tiny model.

The corpora are written by the project's corpus generator (HumanML3D layout with meta/), so probes and
quality passes read it like the default corpus. The evaluator and the model use the ``tiny`` presets for
a few dozen iterations: enough to exercise every code path and to learn the training clips apart.
"""

from __future__ import annotations

from pathlib import Path

import pytest
from torch_threads import one_thread

FAMILIES = ("walk", "jump_in_place", "wave_left", "turn_right")


@pytest.fixture(autouse=True, scope="module")
def _one_torch_thread():
    with one_thread():
        yield


@pytest.fixture(scope="session")
def eval_corpus(tmp_path_factory) -> Path:
    """64 clips, two of each of the first 32 families (51 train, 3 val, 10 test), 3 captions each; not
    in the default corpus."""
    from controlmm.corpus import CorpusConfig, family_names, write_corpus

    out = tmp_path_factory.mktemp("evalcorpus") / "corpus"
    write_corpus(out, CorpusConfig(clips=64, seed=7, families=family_names()[:32]), workers=1, progress=False)
    return out


@pytest.fixture(scope="session")
def small_corpus(tmp_path_factory) -> Path:
    """40 clips of four families (32 train, 2 val, 6 test): what a tiny evaluator learns in seconds."""
    from controlmm.corpus import CorpusConfig, write_corpus

    out = tmp_path_factory.mktemp("smallcorpus") / "corpus"
    write_corpus(out, CorpusConfig(clips=40, seed=5, families=FAMILIES), workers=1, progress=False)
    return out


@pytest.fixture(scope="session")
def tiny_evaluator_dir(tmp_path_factory, small_corpus) -> Path:
    from controlmm.training import TrainOptions, train

    out = tmp_path_factory.mktemp("evaluator") / "tiny"
    with one_thread():
        train(
            "evaluator", TrainOptions(data=small_corpus, out=out, preset="tiny", progress=False, device="cpu")
        )
    return out


@pytest.fixture(scope="session")
def tiny_model_dir(tmp_path_factory, eval_corpus) -> Path:
    """A tiny generative model (tokenizer + masked transformer) trained briefly on the corpus."""
    from controlmm.training import TrainOptions, train

    out = tmp_path_factory.mktemp("model") / "tiny"
    with one_thread():
        for stage, iters in (("tokenizer", 20), ("transformer", 10)):
            train(
                stage,
                TrainOptions(
                    data=eval_corpus, out=out, preset="tiny", iters=iters, progress=False, device="cpu"
                ),
            )
    return out
