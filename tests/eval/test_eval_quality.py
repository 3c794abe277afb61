"""Evaluation passes, the quality columns and table, sanity of the shipped evaluator, the CLI commands."""

from __future__ import annotations

import json
import shutil

import numpy as np
import pytest

from controlmm.cli.main import main
from controlmm.errors import ControlMMError
from controlmm.eval.evaluator import load_evaluator
from controlmm.eval.quality import EvalSet, columns_from_embeddings, evaluate_quality, quality_columns


def test_eval_pass_follows_the_official_loader(eval_corpus):
    evalset = EvalSet.load(eval_corpus, "train")
    assert len(evalset) == 51
    run = evalset.draw(3)
    assert len(run.samples) == 32  # whole groups of 32 only
    again, other = evalset.draw(3), evalset.draw(4)
    assert [s.name for s in run.samples] == [s.name for s in again.samples]
    assert [s.name for s in run.samples] != [s.name for s in other.samples]
    by_name = dict(zip(evalset.names, evalset.motions, strict=True))
    for s in run.samples:
        full = by_name[s.name]
        assert s.frames % 4 == 0 and full.shape[0] - 8 < s.frames <= full.shape[0]
        assert any(
            np.array_equal(full[i : i + s.frames], s.features) for i in range(full.shape[0] - s.frames + 1)
        )
        assert s.caption.tokens and "/" in s.caption.tokens[0]
    assert len(evalset.draw(0, limit=10).samples) == 10 and len(evalset.draw(0, limit=40).samples) == 32


def test_shipped_evaluator_sanity(eval_corpus):
    """Unseen clips: ground truth retrieves far above chance; FID 0 against itself, clearly worse when
    damaged."""
    evaluator = load_evaluator()
    evalset = EvalSet.load(eval_corpus, "train")
    run = evalset.draw(0)
    texts = evaluator.embed_texts(run.captions)
    gt = evaluator.embed_motions(run.motions)
    real = columns_from_embeddings(texts, gt, gt)
    assert real["r_precision_top1"] > 0.4 and real["r_precision_top3"] > 0.7  # chance: 1/32, 3/32
    assert real["fid"] == pytest.approx(0.0, abs=1e-6)
    full = dict(zip(evalset.names, evalset.motions, strict=True))
    recropped = quality_columns(
        evaluator, [full[s.name][: s.frames] for s in run.samples], run.captions, run.motions
    )
    rng = np.random.default_rng(0)
    noised = [
        m + rng.normal(size=m.shape).astype(np.float32) * 2.0 * evaluator.normalizer.std for m in run.motions
    ]
    shuffled = [m[rng.permutation(len(m))] for m in run.motions]  # frames in random order
    for damaged, worse in ((noised, 3 * recropped["fid"]), (shuffled, 1.0)):
        cols = quality_columns(evaluator, damaged, run.captions, run.motions)
        assert cols["fid"] > worse and cols["r_precision_top1"] < real["r_precision_top1"], cols
    swapped = run.motions[1:] + run.motions[:1]  # every caption paired with another clip
    cols = quality_columns(evaluator, swapped, run.captions, run.motions)
    assert cols["fid"] < 1e-6 and cols["r_precision_top1"] < 0.2  # the same motions, the wrong captions


def test_evaluate_quality_rows_and_table(eval_corpus):
    evaluator = load_evaluator()
    evalset = EvalSet.load(eval_corpus, "train")

    def noisy(samples, seed):  # a generator that returns damaged ground truth: frames shuffled, noise added
        rng = np.random.default_rng(seed)
        return [
            s.features[rng.permutation(s.frames)]
            + rng.normal(size=s.features.shape).astype(np.float32) * 0.2 * evaluator.normalizer.std
            for s in samples
        ]

    report = evaluate_quality(
        evaluator, evalset, {"noisy": noisy}, repeats=2, mm_texts=3, mm_repeats=4, mm_times=3
    )
    summary = report.summary()
    assert list(summary) == ["Real", "noisy"] and report.samples == 32
    assert len(report.rows["Real"]["fid"]) == 2 and "multimodality" not in summary["Real"]
    assert summary["noisy"]["fid"][0] > summary["Real"]["fid"][0]
    assert summary["noisy"]["multimodality"][0] > 0
    table = report.table()
    assert "R@3" in table and "MModality" in table and table.count("\n") == 3 and "±" in table
    assert json.loads(json.dumps(report.to_json()))["rows"]["noisy"]["fid"]["values"]
    with pytest.raises(ControlMMError, match="mm-repeats"):
        evaluate_quality(
            evaluator, evalset, {"noisy": noisy}, repeats=1, mm_texts=2, mm_repeats=3, mm_times=3
        )


def _one_line_error(capsys, argv, needle):
    try:
        code = main(argv)
    except SystemExit as exc:  # argument types fail in argparse: the same one line, exit 2
        code = exc.code
    err = capsys.readouterr().err
    assert code == 2, err
    assert err.count("\n") == 1 and needle in err, err


def test_eval_quality_cli(eval_corpus, tiny_evaluator_dir, tiny_model_dir, tmp_path, capsys):
    out = tmp_path / "q.json"
    code = main(
        [
            "eval",
            "quality",
            "--model",
            str(tiny_model_dir),
            "--data",
            str(eval_corpus),
            "--split",
            "train",
            "--repeats",
            "2",
            "--limit",
            "32",
            "--mm-texts",
            "2",
            "--mm-repeats",
            "3",
            "--mm-pairs",
            "2",
            "--evaluator",
            str(tiny_evaluator_dir),
            "--json",
            str(out),
            "--quiet",
        ]
    )
    text = capsys.readouterr().out
    assert code == 0, text
    assert "Real " in text and "tiny " in text and "FID" in text
    data = json.loads(out.read_text())
    assert data["repeats"] == 2 and set(data["rows"]) == {"Real", "tiny"}
    assert len(data["rows"]["tiny"]["r_precision_top3"]["values"]) == 2
    _one_line_error(capsys, ["eval", "quality", "--data", str(eval_corpus), "--repeats", "0"], "--repeats")
    _one_line_error(
        capsys, ["eval", "quality", "--data", str(tmp_path / "none"), "--real-only"], "does not exist"
    )
    _one_line_error(
        capsys,
        ["eval", "quality", "--data", str(eval_corpus), "--real-only", "--evaluator", str(tmp_path)],
        "neither an evaluator directory",
    )
    with pytest.raises(SystemExit) as exc:  # argparse: one usage line, exit 2
        main(["eval", "quality", "--data", str(eval_corpus), "--split", "bogus"])
    err = capsys.readouterr().err
    assert exc.value.code == 2 and err.count("\n") == 1 and "invalid choice" in err


def test_eval_probes_model_mode(eval_corpus, tiny_model_dir, tmp_path, capsys):
    out = tmp_path / "p.json"
    code = main(
        [
            "eval",
            "probes",
            "--data",
            str(eval_corpus),
            "--split",
            "all",
            "--model",
            str(tiny_model_dir),
            "--samples",
            "2",
            "--families",
            "walk,wave_left,clap",
            "--json",
            str(out),
            "--quiet",
        ]
    )
    text = capsys.readouterr().out
    assert code == 0, text
    assert "model" in text and "all " in text
    data = json.loads(out.read_text())
    assert data["total"] == 6 and set(data["families"]) == {"walk", "wave_left", "clap"}
    assert data["source"].startswith("model")
    _one_line_error(
        capsys,
        ["eval", "probes", "--data", str(eval_corpus), "--model", str(tiny_model_dir), "--families", "fly"],
        "unknown family fly",
    )
    _one_line_error(
        capsys,
        ["eval", "probes", "--data", str(eval_corpus), "--model", str(tiny_model_dir), "--families", "walk"],
        "no captions of walk in this split",
    )
    _one_line_error(capsys, ["eval", "probes", "--data", str(eval_corpus), "--samples", "0"], "at least 1")


def test_eval_probes_do_not_load_the_control_model(eval_corpus, tiny_model_dir, tmp_path, capsys):
    """Probes generate without control, so a listed but absent control.pt does not stop them."""
    model_dir = tmp_path / "no-control"
    shutil.copytree(tiny_model_dir, model_dir)
    manifest = json.loads((model_dir / "model.json").read_text())
    manifest["parts"]["control"] = {**manifest["parts"]["transformer"], "sha256": "0" * 64}
    (model_dir / "model.json").write_text(json.dumps(manifest))
    assert not (model_dir / "control.pt").exists()
    code = main(
        [
            "eval",
            "probes",
            "--data",
            str(eval_corpus),
            "--split",
            "all",
            "--model",
            str(model_dir),
            "--samples",
            "1",
            "--families",
            "walk",
            "--quiet",
        ]
    )
    assert code == 0, capsys.readouterr().err
