"""Text-motion quality columns of the control evaluation: scoring, the Table 1 rows, ``eval control``."""

from __future__ import annotations

import json

import numpy as np
import pytest

from controlmm.eval.control import build_cases
from controlmm.eval.control_table import UNCONTROLLED, TableRow, evaluate_control_table, recropped
from controlmm.eval.evaluator import load_evaluator
from controlmm.eval.scoring import MotionSet, score_motions
from controlmm.generate import load_model
from controlmm.motion.skeleton import CONTROL_JOINTS
from tests.cli_helpers import run_cli


@pytest.fixture(scope="module")
def evaluator():
    return load_evaluator()


def test_score_motions_over_runs(tiny_data, evaluator):
    """Ground truth against itself: FID 0; damaged motions: FID and R-precision worse; CI over the runs."""
    runs, damaged = [], []
    rng = np.random.default_rng(0)
    for seed in (0, 1, 2):
        cases = build_cases(tiny_data, "pelvis", samples=8, seed=seed, split="train")
        truth, texts = [c.features for c in cases], [c.text for c in cases]
        runs.append(MotionSet(truth, texts, truth))
        damaged.append(
            MotionSet(
                [
                    f[rng.permutation(len(f))]
                    + rng.normal(size=f.shape).astype(np.float32) * 2 * evaluator.normalizer.std
                    for f in truth
                ],
                texts,
                truth,
            )
        )
    real, bad = score_motions(evaluator, runs), score_motions(evaluator, damaged)
    assert real.runs == 3 and set(real.values) == {
        "r_precision_top1",
        "r_precision_top2",
        "r_precision_top3",
        "fid",
        "mm_dist",
        "diversity",
    }
    assert max(real.values["fid"]) < 1e-6 and min(bad.values["fid"]) > 1.0
    assert np.mean(bad.values["mm_dist"]) > np.mean(real.values["mm_dist"])
    mean, ci = bad.summary()["fid"]
    v = np.array(bad.values["fid"])
    assert mean == pytest.approx(v.mean()) and ci == pytest.approx(1.96 * v.std() / np.sqrt(3))
    assert json.loads(json.dumps(bad.to_json()))["fid"]["values"] == bad.values["fid"]
    single = score_motions(evaluator, runs[0], seed=5)  # one set: one run, CI 0
    assert single.runs == 1 and single.summary()["diversity"][1] == 0.0


def test_each_mode_cycles_the_six_joints(tiny_data):
    cases = build_cases(tiny_data, "each", densities=(5,), samples=8, seed=0)
    assert [c.joints for c in cases] == [(CONTROL_JOINTS[i % 6],) for i in range(8)]
    pelvis = build_cases(tiny_data, "pelvis", densities=(5,), samples=8, seed=0)
    assert [c.text for c in cases] == [c.text for c in pelvis]  # same clips, captions, crops, keyframes
    assert all(np.array_equal(a.mask.any(-1), b.mask.any(-1)) for a, b in zip(cases, pelvis, strict=True))


def test_real_reference_recrops_the_same_clips(tiny_data):
    cases = build_cases(tiny_data, "pelvis", samples=12, seed=3)
    crops = recropped(tiny_data, cases, seed=3)
    assert len(crops) == 12 and crops[0].dtype == np.float32
    for case, crop in zip(cases, crops, strict=True):
        clip = np.load(tiny_data / "new_joint_vecs" / f"{case.motion_id}.npy")
        m = len(crop)
        assert m % 4 == 0 and m > len(clip) - 8 - 1, (m, len(clip))
        assert any(np.array_equal(clip[i : i + m], crop) for i in range(len(clip) - m + 1))
    assert any(
        len(c.features) != len(r) or not np.array_equal(c.features, r)
        for c, r in zip(cases, crops, strict=True)
    )
    assert all(np.array_equal(a, b) for a, b in zip(crops, recropped(tiny_data, cases, seed=3), strict=True))


def test_control_table_rows(tiny_control_dir, tiny_data, evaluator):
    model = load_model(tiny_control_dir)
    rows = [
        TableRow("uncontrolled", "pelvis", UNCONTROLLED),
        TableRow("pelvis", "pelvis", "fast"),
        TableRow("all joints", "each", "fast"),
    ]
    table = evaluate_control_table(
        model, tiny_data, rows, evaluator=evaluator, densities=(2, 196), samples=4, repeats=2, batch_size=4
    )
    summary = table.summary()
    assert list(summary) == ["Real", "uncontrolled", "pelvis", "all joints"]
    for scores in table.rows.values():
        assert scores.runs == 2 and {"fid", "r_precision_top3", "diversity", "traj", "avg", "skate"} <= set(
            scores.values
        )
    assert summary["Real"]["avg"] == (0.0, 0.0) and summary["Real"]["traj"] == (0.0, 0.0)
    assert summary["pelvis"]["avg"][0] < 0.5 * summary["uncontrolled"]["avg"][0]  # editing meets the targets
    # the quality columns are exactly score_motions of the generated motions against the cases' ground truth
    results = table.evaluations["pelvis"]
    again = score_motions(
        evaluator,
        [MotionSet(r.generated, [c.text for c in r.cases], [c.features for c in r.cases]) for r in results],
    )
    assert again.values["fid"] == table.rows["pelvis"].values["fid"]
    assert [c.joints for c in table.evaluations["all joints"][0].cases][:3] == [(0,), (10,), (11,)]
    assert (
        results[0].cases[0].text != results[1].cases[0].text
        or results[0].cases[0].frames != results[1].cases[0].frames
    )
    text = table.table()
    assert text.count("\n") == 5 and "FID" in text and "Avg. err cm" in text and "±" in text
    assert set(json.loads(json.dumps(table.to_json()))["rows"]) == set(summary)


def test_eval_control_quality_cli(tiny_control_dir, tiny_data, tmp_path, capsys):
    out = tmp_path / "table.json"
    code = run_cli(
        [
            "eval",
            "control",
            "--model",
            str(tiny_control_dir),
            "--data",
            str(tiny_data),
            "--preset",
            "fast",
            "--joints",
            "pelvis",
            "--density",
            "5",
            "--samples",
            "3",
            "--repeats",
            "2",
            "--batch-size",
            "3",
            "--real",
            "--uncontrolled",
            "--quiet",
            "--json",
            str(out),
        ]
    )
    printed = capsys.readouterr().out
    assert code == 0, printed
    assert "R@1" in printed and "Real " in printed and "uncontrolled " in printed and "2 repeat(s)" in printed
    data = json.loads(out.read_text())
    assert [d["joints"] for d in data] == ["pelvis", "Real", "uncontrolled"]
    assert len(data[0]["table_row"]["fid"]["values"]) == 2 and len(data[0]["repeats"]) == 2
    assert data[1]["table_row"]["traj"]["mean"] == 0.0
    for argv, needle in (
        (["--repeats", "0"], "--repeats: must be at least 1"),
        (["--samples", "1"], "--samples 2 or more"),
    ):
        assert (
            run_cli(["eval", "control", "--model", str(tiny_control_dir), "--data", str(tiny_data)] + argv)
            == 2
        )
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and needle in err, err
