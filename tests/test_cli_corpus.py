"""``controlmm corpus`` and ``controlmm eval probes``: outputs and exit codes."""

from __future__ import annotations

import json

from controlmm.corpus import family_names, get_family
from tests.cli_helpers import run_cli

ROBOT_TASK_GROUPS = ("postures", "actions", "terrain", "sequences")


def test_corpus_then_probes_end_to_end(tmp_path, capsys):
    out = tmp_path / "c"
    assert (
        run_cli(["corpus", "--out", str(out), "--clips", "6", "--seed", "3", "--workers", "1", "--quiet"])
        == 0
    )
    assert "wrote" in capsys.readouterr().out
    assert len((out / "all.txt").read_text().split()) == 6
    report = tmp_path / "probes.json"
    assert (
        run_cli(["eval", "probes", "--data", str(out), "--split", "all", "--quiet", "--json", str(report)])
        == 0
    )
    text = capsys.readouterr().out
    assert "100.0%" in text.splitlines()[-2] or "100.0%" in text
    assert json.loads(report.read_text())["rate"] == 1.0
    # A corpus directory may be regenerated in place; anything else is never replaced.
    assert (
        run_cli(
            [
                "corpus",
                "--out",
                str(out),
                "--clips",
                "2",
                "--workers",
                "1",
                "--quiet",
                "--families",
                "clap,squat",
            ]
        )
        == 0
    )
    assert sorted(json.loads((out / "corpus.json").read_text())["families"]) == ["clap", "squat"]


def test_probes_through_the_shipped_tokenizer(tmp_path, capsys):
    """--tokenizer-only probes the ground truth after an encode/decode round trip of the model's
    tokenizer: the shipped one reproduces walks (their probes pass), and the report says what it ran."""
    out = tmp_path / "c"
    assert (
        run_cli(
            [
                "corpus",
                "--out",
                str(out),
                "--clips",
                "4",
                "--seed",
                "5",
                "--workers",
                "1",
                "--quiet",
                "--families",
                "walk,sidestep_left",
            ]
        )
        == 0
    )
    capsys.readouterr()
    report = tmp_path / "tok.json"
    assert (
        run_cli(
            [
                "eval",
                "probes",
                "--data",
                str(out),
                "--split",
                "all",
                "--model",
                "default",
                "--tokenizer-only",
                "--quiet",
                "--json",
                str(report),
            ]
        )
        == 0
    )
    data = json.loads(report.read_text())
    assert "through the tokenizer" in data["source"] and "all layer" in data["source"]
    assert data["families"]["walk"]["passed"] == data["families"]["walk"]["total"] > 0
    assert (
        run_cli(
            [
                "eval",
                "probes",
                "--data",
                str(out),
                "--split",
                "all",
                "--model",
                "default",
                "--tokenizer-only",
                "--layers",
                "1",
                "--quiet",
            ]
        )
        == 0
    )
    assert "1 layer(s)" in capsys.readouterr().out
    for argv in (
        ["--layers", "1"],
        ["--tokenizer-only"],
        ["--model", "default", "--tokenizer-only", "--layers", "9"],
        ["--model", "default", "--layers", "2"],
    ):
        assert run_cli(["eval", "probes", "--data", str(out), "--quiet", *argv]) == 2, argv
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and "error" in err, (argv, err)


def test_bad_input_exits_2_with_one_line(tmp_path, capsys):
    blocker = tmp_path / "file.txt"
    blocker.write_text("x")
    other = tmp_path / "mine"
    other.mkdir()
    (other / "thesis.tex").write_text("precious")
    bad = [
        ["corpus", "--out", str(tmp_path / "o"), "--clips", "0"],
        ["corpus", "--out", str(blocker / "o"), "--clips", "2"],
        ["corpus", "--out", str(tmp_path / "o"), "--clips", "2", "--families", "walk,moonwalk"],
        ["corpus", "--out", str(other), "--clips", "2", "--families", "moonwalk"],  # names before paths
        ["corpus", "--out", str(tmp_path / "o"), "--clips", "2", "--families", " , "],
        ["corpus", "--out", str(other), "--clips", "2", "--workers", "1"],
        ["corpus", "--clips", "2"],
        ["eval", "probes", "--data", str(tmp_path / "missing")],
        ["eval", "probes", "--data", str(tmp_path)],
    ]
    for argv in bad:
        assert run_cli(argv) == 2, argv
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and "error" in err, (argv, err)
        if "moonwalk" in argv[-1] or argv[-1] == " , ":
            assert "'moonwalk'" in err or "names no family" in err, err
            assert all(name in err for name in family_names())  # the known families, new ones included
    assert (other / "thesis.tex").read_text() == "precious"
    assert not (tmp_path / "o").exists()
    assert run_cli(["eval"]) == 2


def test_probes_of_the_robot_task_families_through_the_cli(tmp_path, capsys):
    """One clip of each robot-task family (postures, actions, terrain, sequences): `controlmm eval
    probes` checks every caption with its family's probe, and every one passes on the ground truth;
    test-split captions are held-out phrasings."""
    new = [name for name in family_names() if get_family(name).group in ROBOT_TASK_GROUPS]
    assert len(new) == 17
    out = tmp_path / "c"
    argv = ["corpus", "--out", str(out), "--clips", "17", "--seed", "4", "--workers", "1", "--quiet"]
    assert run_cli([*argv, "--families", ",".join(new)]) == 0
    report = tmp_path / "probes.json"
    argv = ["eval", "probes", "--data", str(out), "--split", "all", "--quiet", "--json", str(report)]
    assert run_cli(argv) == 0
    table = capsys.readouterr().out
    data = json.loads(report.read_text())
    assert set(data["families"]) == set(new) and all(f in table for f in new)
    assert all(c == {"passed": 3, "total": 3} for c in data["families"].values()), data["families"]
    test_ids = (out / "test.txt").read_text().split()
    assert test_ids
    for clip_id in test_ids:
        meta = json.loads((out / "meta" / f"{clip_id}.json").read_text())
        assert meta["held_out"] and all(c["held_out"] for c in meta["captions"])
    assert run_cli(["eval", "probes", "--data", str(out), "--split", "test", "--quiet"]) == 0
    assert "100.0%" in capsys.readouterr().out
