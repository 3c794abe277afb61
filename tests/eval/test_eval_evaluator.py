"""The project's evaluator: words, training (retrieval improves), the directory format, resume, CLI errors."""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest
import torch

from controlmm.cli.main import main
from controlmm.errors import ControlMMError, InputFileError
from controlmm.eval.evaluator import (
    EVALUATOR_PRESETS,
    TextMotionEncoder,
    TextMotionEvaluator,
    Vocabulary,
    load_evaluator,
    tokenize,
)
from controlmm.eval.quality import EvalSet
from controlmm.training import TrainOptions, train
from controlmm.training.contrastive import contrastive_loss


def test_tokenize_and_vocabulary():
    assert tokenize("Someone waves 3 times, then WALKS.") == [
        "someone",
        "waves",
        "3",
        "times",
        "then",
        "walks",
    ]
    vocab = Vocabulary.build(["a man walks", "a man runs", "a woman walks"])
    assert vocab.words[:4] == ("<pad>", "<unk>", "<sos>", "<eos>") and vocab.words[4:6] == ("a", "man")
    ids, lengths = vocab.encode(["a man flies", "walks"])
    assert ids.shape == (2, 22) and lengths.tolist() == [5, 3]
    assert ids[0, :5].tolist() == [2, vocab.index("a"), vocab.index("man"), 1, 3] and ids[0, 5:].eq(0).all()
    assert vocab.unknown_share(["a man flies"]) == pytest.approx(1 / 3)
    long_ids, long_len = vocab.encode([" ".join(["a"] * 30)])
    assert long_len.item() == 22 and long_ids[0, -1].item() == 3
    with pytest.raises(ControlMMError):
        Vocabulary(("a", "b"))


def test_contrastive_loss_masks_repeated_captions():
    emb = (
        torch.eye(4, 8) * 5
    )  # four orthogonal embeddings on the sphere of radius 5 (random ones can be close)
    loss, acc = contrastive_loss(emb, emb, torch.tensor([0, 1, 2, 3]), scale=5.0)
    assert acc == 1.0 and loss < 0.1
    # Samples 0 and 1 share a caption: their cross pairs are not negatives, so swapping them costs nothing.
    swapped = emb[[1, 0, 2, 3]]
    same, _ = contrastive_loss(emb, swapped, torch.tensor([0, 0, 2, 3]), scale=5.0)
    differ, _ = contrastive_loss(emb, swapped, torch.tensor([0, 1, 2, 3]), scale=5.0)
    assert differ > same + 1.0


def _gt_retrieval(evaluator, corpus) -> float:  # R@3 of the ground truth
    evalset = EvalSet.load(corpus, "train")
    return float(np.mean([evalset.draw(s).matching(evaluator).r_precision[2] for s in range(3)]))


def test_training_improves_retrieval(tiny_evaluator_dir, small_corpus):
    trained = load_evaluator(tiny_evaluator_dir)
    assert isinstance(trained, TextMotionEvaluator)
    torch.manual_seed(0)
    untrained = TextMotionEvaluator(
        TextMotionEncoder(trained.module.cfg), trained.vocabulary, trained.normalizer
    )
    before, after = _gt_retrieval(untrained, small_corpus), _gt_retrieval(trained, small_corpus)
    # Four families in one group of 32: chance R@3 is 3/32; telling the families apart gives about 3/8.
    assert after > 0.25 and after > before + 0.12, (before, after)
    manifest = json.loads((tiny_evaluator_dir / "evaluator.json").read_text())
    assert manifest["format"] == "controlmm-evaluator" and manifest["training"]["iterations"] == 40
    assert manifest["part"]["dtype"] == "float16" and manifest["vocabulary"][:2] == ["<pad>", "<unk>"]
    assert manifest["training"]["history"] and "val_r3" in manifest["training"]["best"]
    assert set(manifest["retrieval"]) == {"val", "test"}


def test_embeddings_lie_on_the_sphere_and_match_the_module(tiny_evaluator_dir, small_corpus):
    evaluator = load_evaluator(tiny_evaluator_dir)
    evalset = EvalSet.load(small_corpus, "test")
    run = evalset.draw(0)
    motions = evaluator.embed_motions(run.motions)
    texts = evaluator.embed_texts(run.texts)
    scale = evaluator.module.cfg.scale
    assert motions.shape == (len(run.samples), evaluator.dim) == texts.shape
    assert np.allclose(np.linalg.norm(motions, axis=1), scale, atol=1e-4)
    # Padding does not change an embedding: one motion alone or in a batch of longer ones.
    alone = evaluator.embed_motions(run.motions[:1])
    assert np.allclose(alone, motions[:1], atol=1e-4)
    # Motion objects and raw features give the same embedding; too short motions are an error.
    from controlmm.motion import Motion

    assert np.allclose(evaluator.embed_motions([Motion.from_features(run.motions[0])]), alone, atol=1e-5)
    with pytest.raises(ControlMMError, match="at least 4"):
        evaluator.embed_motions([run.motions[0][:2]])


def test_resume_continues_exactly(small_corpus, tmp_path):
    def opts(out, iters, resume=False):
        return TrainOptions(
            data=small_corpus,
            out=out,
            preset="tiny",
            iters=iters,
            resume=resume,
            progress=False,
            device="cpu",
            checkpoint_every=5,
        )

    train("evaluator", opts(tmp_path / "a", 12))
    train("evaluator", opts(tmp_path / "b", 6))
    train("evaluator", opts(tmp_path / "b", 12, resume=True))
    a = torch.load(tmp_path / "a" / "checkpoints" / "evaluator.pt", weights_only=False)["model"]
    b = torch.load(tmp_path / "b" / "checkpoints" / "evaluator.pt", weights_only=False)["model"]
    assert all(torch.equal(a[k], b[k]) for k in a)
    with pytest.raises(ControlMMError, match="--resume"):
        train("evaluator", opts(tmp_path / "a", 12))


def test_loading_errors(tiny_evaluator_dir, tmp_path):
    import shutil

    with pytest.raises(InputFileError, match="neither an evaluator directory"):
        load_evaluator(tmp_path)
    broken = tmp_path / "broken"
    shutil.copytree(tiny_evaluator_dir, broken, ignore=shutil.ignore_patterns("checkpoints"))
    (broken / "evaluator.pt").write_bytes(b"\x00" * 64)
    with pytest.raises(InputFileError, match="corrupt"):
        load_evaluator(broken)
    manifest = json.loads((tiny_evaluator_dir / "evaluator.json").read_text())
    manifest["config"]["embed_dim"] += 1
    shutil.copy(tiny_evaluator_dir / "evaluator.pt", broken / "evaluator.pt")
    (broken / "evaluator.json").write_text(json.dumps(manifest))
    with pytest.raises(InputFileError, match="wrong shape"):
        load_evaluator(broken)


def test_shipped_evaluator_is_small_and_loads():
    from controlmm.eval.evaluator import default_evaluator_dir

    directory = default_evaluator_dir()
    size = sum(p.stat().st_size for p in directory.iterdir() if p.is_file())
    assert size <= 3 * 2**20, size
    evaluator = load_evaluator()
    assert evaluator.module.cfg == replace(EVALUATOR_PRESETS["default"], vocab_size=len(evaluator.vocabulary))
    assert evaluator.manifest["retrieval"]["test"]["r_precision_top1"] > 3 / 32


def _one_line_error(capsys, argv, needle):
    code = main(argv)
    err = capsys.readouterr().err
    assert code == 2, err
    assert err.count("\n") == 1 and needle in err, err


def test_train_evaluator_cli_errors(capsys, tmp_path, tiny_evaluator_dir, small_corpus):
    _one_line_error(
        capsys,
        ["train", "evaluator", "--data", str(tmp_path / "none"), "--out", str(tmp_path / "e")],
        "does not exist",
    )
    _one_line_error(
        capsys,
        ["train", "evaluator", "--data", str(small_corpus), "--out", str(tiny_evaluator_dir)],
        "already has evaluator training",
    )
    _one_line_error(
        capsys,
        ["train", "evaluator", "--data", str(small_corpus), "--out", str(tmp_path / "e"), "--preset", "huge"],
        "unknown evaluator preset 'huge'",
    )
    _one_line_error(
        capsys,
        ["train", "evaluator", "--data", str(small_corpus), "--out", str(tmp_path / "e"), "--resume"],
        "nothing to resume",
    )


@pytest.mark.parametrize(
    ("extra", "needle"),
    [
        (["--batch-size", "1"], "batch size must be at least 2 (contrastive pairs); got 1"),
        (["--batch-size", "1000"], "batch size 1000 is more than the"),
        (["--iters", "0"], "iters must be at least 1; got 0"),
        (["--lr", "-1"], "learning rate must be positive; got -1"),
    ],
)
def test_train_evaluator_refuses_options_before_creating_anything(
    capsys, tmp_path, small_corpus, extra, needle
):
    out = tmp_path / "new" / "eval"
    argv = ["train", "evaluator", "--data", str(small_corpus), "--out", str(out), "--preset", "tiny"]
    _one_line_error(capsys, argv + ["--no-progress", *extra], needle)
    assert not (tmp_path / "new").exists()


def test_evaluator_keeps_the_highest_score():
    from controlmm.training.evaluator import EvaluatorStage
    from controlmm.training.tokenizer import TokenizerStage

    assert EvaluatorStage.is_better({"val_score": 0.5}, {"val_score": 0.4})
    assert not EvaluatorStage.is_better({"val_score": 0.3}, {"val_score": 0.4})
    assert TokenizerStage.is_better({"val_mpjpe_mm": 30.0}, {"val_mpjpe_mm": 40.0})
    assert not TokenizerStage.is_better({"val_mpjpe_mm": 50.0}, {"val_mpjpe_mm": 40.0})
    assert EvaluatorStage.is_better({"val_score": 0.1}, None)
