"""``controlmm train`` and ``controlmm generate`` end to end; bad input is one line with exit code 2."""

from __future__ import annotations

import json
import shutil
import subprocess
import sys

import numpy as np
import pytest

from controlmm.cli.main import main
from controlmm.cli.train import TRAIN_SUBCOMMANDS

from .conftest import subprocess_env


def test_generate_writes_a_motion_and_a_plot(tiny_model_dir, tmp_path):
    out = tmp_path / "walk.npz"
    res = subprocess.run(
        [
            sys.executable,
            "-m",
            "controlmm",
            "generate",
            "--text",
            "a person squats slowly",
            "--seconds",
            "3",
            "--seed",
            "0",
            "--out",
            str(out),
            "--plot",
            str(tmp_path / "walk.png"),
            "--model",
            str(tiny_model_dir),
        ],
        capture_output=True,
        text=True,
        env=subprocess_env(),
        timeout=300,
    )
    assert res.returncode == 0, res.stderr
    assert "wrote" in res.stdout and (tmp_path / "walk.png").stat().st_size > 1000
    with np.load(out) as data:
        assert data["joints"].shape == (60, 22, 3) and data["features"].shape == (60, 263)
        assert float(data["fps"]) == 20.0 and str(data["text"]) == "a person squats slowly"
        meta = json.loads(str(data["metadata"]))
    assert meta["seed"] == 0 and meta["frames"] == 60


def test_generate_batch_numbers_outputs(tiny_model_dir, tmp_path, capsys):
    code = main(
        [
            "generate",
            "--text",
            "a person squats",
            "--text",
            "someone bends over",
            "--frames",
            "44",
            "--seed",
            "1",
            "--out",
            str(tmp_path / "m.npz"),
            "--model",
            str(tiny_model_dir),
        ]
    )
    assert code == 0
    assert (tmp_path / "m_0.npz").is_file() and (tmp_path / "m_1.npz").is_file()
    with np.load(tmp_path / "m_1.npz") as data:
        assert str(data["text"]) == "someone bends over" and data["joints"].shape == (44, 22, 3)


def _one_line_error(capsys, argv, needle):
    code = main(argv)
    err = capsys.readouterr().err
    assert code == 2, err
    assert err.count("\n") == 1 and needle in err, err


def test_generate_bad_input(tiny_model_dir, tmp_path, capsys):
    base = ["generate", "--out", str(tmp_path / "o.npz"), "--model", str(tiny_model_dir)]
    _one_line_error(capsys, base + ["--text", "  "], "text must not be empty")
    _one_line_error(capsys, base + ["--text", "a person squats", "--seconds", "20"], "out of range")
    _one_line_error(
        capsys, ["generate", "--text", "hi", "--out", str(tmp_path / "o.txt")], "unknown output format"
    )
    _one_line_error(
        capsys,
        ["generate", "--text", "hi", "--out", str(tmp_path / "o.npz"), "--model", str(tmp_path / "none")],
        "does not exist",
    )
    broken = tmp_path / "broken"
    shutil.copytree(tiny_model_dir, broken, ignore=shutil.ignore_patterns("checkpoints", "cache"))
    (broken / "tokenizer.pt").write_bytes(b"\x00" * 100)
    _one_line_error(
        capsys,
        ["generate", "--text", "hi", "--out", str(tmp_path / "o.npz"), "--model", str(broken)],
        "corrupt",
    )
    (broken / "tokenizer.pt").unlink()
    _one_line_error(
        capsys,
        ["generate", "--text", "hi", "--out", str(tmp_path / "o.npz"), "--model", str(broken)],
        "has no tokenizer.pt",
    )


def _files(root):
    """Every file under ``root`` with its bytes."""
    return {p.relative_to(root): p.read_bytes() for p in sorted(root.rglob("*")) if p.is_file()}


@pytest.mark.parametrize(
    ("extra", "needle"),
    [
        (["--batch-size", "1000"], "batch size 1000 is more than the 11 usable training items"),
        (["--batch-size", "0"], "batch size must be at least 1; got 0"),
        (["--iters", "0"], "iters must be at least 1; got 0"),
        (["--epochs", "-1"], "--epochs must be positive; got -1"),
        (["--lr", "0"], "learning rate must be positive; got 0"),
        (["--checkpoint-every", "0"], "checkpoint interval must be at least 1; got 0"),
        (["--workers", "-1"], "--workers must be >= 0; got -1"),
        (["--threads", "0"], "threads must be at least 1; got 0"),
        (["--preset", "huge"], "unknown preset 'huge'"),
    ],
)
def test_train_refuses_options_before_creating_anything(tiny_data, tmp_path, capsys, extra, needle):
    out = tmp_path / "new" / "model"
    argv = ["train", "tokenizer", "--data", str(tiny_data), "--out", str(out), "--preset", "tiny"]
    _one_line_error(capsys, argv + ["--no-progress", *extra], needle)
    assert not (tmp_path / "new").exists()


def test_train_control_refusal_leaves_the_model_directory_as_it_was(
    tiny_data, tiny_model_dir, tmp_path, capsys
):
    model = tmp_path / "model"
    shutil.copytree(tiny_model_dir, model, ignore=shutil.ignore_patterns("checkpoints"))
    before = _files(model)
    argv = ["train", "control", "--data", str(tiny_data), "--out", str(model), "--no-progress"]
    # --joints pelvis would be recorded in model.json: refused before that happens
    _one_line_error(capsys, argv + ["--joints", "pelvis", "--batch-size", "1000"], "batch size 1000")
    _one_line_error(capsys, argv + ["--alpha", "2"], "alpha must be in [0, 1]; got 2.0")
    assert _files(model) == before


def test_train_control_choices_match_the_stage():
    from controlmm.cli import train_control
    from controlmm.training import control

    assert train_control.ESTIMATORS == control.ESTIMATORS
    assert train_control.CONTROL_MODES == control.CONTROL_MODES
    assert train_control.DENSITIES == control.DENSITIES


def test_train_help_and_bad_input(tiny_data, tmp_path, capsys):
    assert TRAIN_SUBCOMMANDS == (
        "tokenizer",
        "transformer",
        "token_transformer",
        "residual",
        "control",
        "evaluator",
    )
    for stage in TRAIN_SUBCOMMANDS:
        with pytest.raises(SystemExit) as info:
            main(["train", stage.replace("_", "-"), "--help"])
        assert info.value.code == 0
        assert "--resume" in capsys.readouterr().out
    _one_line_error(capsys, ["train"], "choose a stage")
    _one_line_error(
        capsys,
        ["train", "tokenizer", "--data", str(tiny_data), "--out", str(tmp_path / "m"), "--preset", "huge"],
        "unknown preset 'huge'; allowed: paper, demo, tiny",
    )
    _one_line_error(
        capsys,
        ["train", "transformer", "--data", str(tiny_data), "--out", str(tmp_path / "m")],
        "train the tokenizer first",
    )
    _one_line_error(
        capsys,
        ["train", "tokenizer", "--data", str(tmp_path / "nodata"), "--out", str(tmp_path / "m")],
        "does not exist",
    )
    _one_line_error(
        capsys,
        [
            "train",
            "tokenizer",
            "--data",
            str(tiny_data),
            "--out",
            str(tmp_path / "m"),
            "--preset",
            "tiny",
            "--iters",
            "0",
        ],
        "iters must be at least 1",
    )
    with pytest.raises(SystemExit) as info:
        main(["train", "tokenizer", "--data", str(tiny_data)])  # argparse usage error: one line, exit 2
    assert info.value.code == 2 and capsys.readouterr().err.count("\n") == 1
