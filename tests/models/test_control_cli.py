"""``generate --control``, ``train control``, ``eval control`` and the evaluation metrics on hand-made
inputs."""

from __future__ import annotations

import json

import numpy as np
import pytest

from controlmm.cli.main import main
from controlmm.eval.control import (
    CROSS_COMBINATIONS,
    build_cases,
    case_metrics,
    keyframe_errors,
    summarize,
)
from controlmm.generate import generate, load_model


@pytest.fixture(scope="module")
def spec_path(tiny_control_dir, tmp_path_factory):
    joints = generate(load_model(tiny_control_dir), "a person squats", frames=60, seed=0).motion.joints
    path = tmp_path_factory.mktemp("spec") / "spec.json"
    path.write_text(
        json.dumps(
            {
                "coords": "human",
                "constraints": [
                    {"joint": "pelvis", "frame": 20, "position": joints[20, 0].tolist()},
                    {"joint": "left_wrist", "frame_range": [40, 41], "positions": joints[40:42, 20].tolist()},
                ],
            }
        )
    )
    return path


def test_generate_with_control_prints_and_stores_every_error(tiny_control_dir, spec_path, tmp_path, capsys):
    out = tmp_path / "m.npz"
    code = main(
        [
            "generate",
            "--text",
            "a person squats",
            "--frames",
            "60",
            "--seed",
            "0",
            "--control",
            str(spec_path),
            "--preset",
            "fast",
            "--out",
            str(out),
            "--model",
            str(tiny_control_dir),
        ]
    )
    printed = capsys.readouterr().out
    assert code == 0, printed
    lines = [line for line in printed.splitlines() if " error " in line]
    assert len(lines) == 3 and "pelvis" in lines[0] and "frame  41" in lines[2] and lines[0].endswith("cm")
    assert "codebook editing" in printed and "control model" in printed
    with np.load(out) as data:
        meta = json.loads(str(data["metadata"]))
        errors = data["control_errors"]
        assert data["control_mask"].shape == (60, 22) and data["control_mask"].sum() == 3
    control = meta["control"]
    assert control["spec"]["constraints"][1]["frame_range"] == [40, 41] and control["preset"] == "fast"
    shown = [float(line.split("error")[1].split("cm")[0]) for line in lines]
    np.testing.assert_allclose(shown, 100 * errors, atol=0.006)
    np.testing.assert_allclose([c["error_cm"] for c in control["constraints"]], 100 * errors, atol=1e-3)
    assert control["editing"]["codebook_steps"] <= 100


def _one_line_error(capsys, argv, needle):
    try:
        code = main(argv)
    except SystemExit as exc:  # argparse usage errors
        code = exc.code
    err = capsys.readouterr().err
    assert code == 2, err
    assert err.count("\n") == 1 and needle in err, err


@pytest.mark.parametrize(
    "spec, needle",
    [
        (
            {"constraints": [{"joint": "left_hand", "frame": 3, "position": [0, 1, 0]}]},
            "unknown joint 'left_hand'",
        ),
        (
            {"constraints": [{"joint": "pelvis", "frame": 70, "position": [0, 1, 0]}]},
            "frame 70 is outside the motion",
        ),
        ({"constraints": [{"joint": "pelvis", "frame": 3, "position": [0, "nan", 0]}]}, "NaN"),
        (
            {"constraints": [{"joint": "pelvis", "frame": 3, "position": [0, 1]}]},
            "position must be 3 numbers",
        ),
        (
            {
                "constraints": [
                    {"joint": 0, "frame": 3, "position": [0, 1, 0]},
                    {"joint": "pelvis", "frame": 3, "position": [0, 1, 0]},
                ]
            },
            "duplicate constraint",
        ),
        ({"constraints": []}, "has no constraints"),
        ({"coords": "robot", "constraints": []}, "coords must be one of human, world"),
    ],
)
def test_bad_specs_are_one_line(tiny_control_dir, tmp_path, capsys, spec, needle):
    path = tmp_path / "bad.json"
    path.write_text(json.dumps(spec).replace('"nan"', "NaN"))
    _one_line_error(
        capsys,
        [
            "generate",
            "--text",
            "a person squats",
            "--frames",
            "60",
            "--control",
            str(path),
            "--out",
            str(tmp_path / "x.npz"),
            "--model",
            str(tiny_control_dir),
        ],
        needle,
    )
    assert not (tmp_path / "x.npz").exists()


def test_control_flags_need_a_spec_and_sane_values(tiny_control_dir, spec_path, tmp_path, capsys):
    base = [
        "generate",
        "--text",
        "a person squats",
        "--out",
        str(tmp_path / "x.npz"),
        "--model",
        str(tiny_control_dir),
    ]
    _one_line_error(capsys, base + ["--preset", "fast"], "--preset needs --control SPEC.json")
    _one_line_error(
        capsys,
        base + ["--control", str(spec_path), "--tolerance", "0"],
        "--tolerance: must be greater than 0",
    )
    _one_line_error(capsys, base + ["--contact-steps", "50"], "--contact-steps needs --control SPEC.json")
    _one_line_error(
        capsys,
        base + ["--control", str(spec_path), "--contact-steps", "-1"],
        "contact_steps must be a whole number >= 0; got -1",
    )
    _one_line_error(capsys, base + ["--control", str(tmp_path / "none.json")], "does not exist")
    _one_line_error(
        capsys, base + ["--control", str(spec_path), "--preset", "slow"], "invalid choice: 'slow'"
    )
    _one_line_error(
        capsys,
        ["train", "control", "--data", "x", "--out", "y", "--joints", "hands"],
        "invalid choice: 'hands'",
    )


# -- evaluation protocol ----------------------------------------------------------------------------
def test_keyframe_metrics_on_hand_made_motion():
    targets = np.zeros((10, 22, 3))
    joints = np.zeros((10, 22, 3))
    mask = np.zeros((10, 22), dtype=bool)
    mask[2, [0, 15]] = True  # frame 2: pelvis 0.2 m off, head exact -> e = 0.1
    mask[5, 0] = True  # frame 5: pelvis 0.8 m off -> e = 0.8 > 0.5
    mask[7, 21] = True  # frame 7: exact
    joints[2, 0] = [0.2, 0.0, 0.0]
    joints[5, 0] = [0.0, 0.8, 0.0]
    joints[3, 0] = [9.0, 9.0, 9.0]  # uncontrolled frames do not count
    np.testing.assert_allclose(keyframe_errors(joints, targets, mask), [0.1, 0.8, 0.0])
    m = case_metrics(joints, targets, mask)
    assert m["traj"] == 1.0 and m["loc"] == pytest.approx(1 / 3)
    assert m["avg"] == pytest.approx(0.3) and m["max"] == pytest.approx(0.8)
    good = case_metrics(targets, targets, mask)
    assert good == {"traj": 0.0, "loc": 0.0, "avg": 0.0, "max": 0.0}
    s = summarize([m, good])
    assert s["traj"] == 0.5 and s["loc"] == pytest.approx(1 / 6) and s["avg"] == pytest.approx(0.15)
    assert s["max"] == pytest.approx(0.8) and s["cases"] == 2


def test_cross_combinations_and_cases(tiny_data):
    assert len(CROSS_COMBINATIONS) == 63 and len(set(CROSS_COMBINATIONS)) == 63
    sizes = [len(c) for c in CROSS_COMBINATIONS]
    assert sizes == sorted(sizes) and [sizes.count(k) for k in range(1, 7)] == [6, 15, 20, 15, 6, 1]
    assert CROSS_COMBINATIONS[0] == (0,) and CROSS_COMBINATIONS[-1] == (0, 10, 11, 15, 20, 21)
    cases = build_cases(tiny_data, "cross", samples=10, seed=0)
    for i, c in enumerate(cases):
        assert (
            c.frames % 4 == 0 and c.targets.shape == (c.frames, 22, 3) and c.joints == CROSS_COMBINATIONS[i]
        )
        frames = np.flatnonzero(c.mask.any(-1))
        expected = c.density if c.density <= 5 else int(c.frames * c.density / 196)
        assert len(frames) == expected and c.density == (1, 2, 5, 49, 196)[i % 5]
        assert set(np.flatnonzero(c.mask.any(0))) == set(c.joints)
        np.testing.assert_allclose(c.targets[0, 0, [0, 2]], 0.0, atol=1e-6)  # starts at the origin
    wrist = build_cases(tiny_data, "left_wrist", densities=(196,), samples=2)
    assert all(c.mask[:, 20].all() and c.mask.sum() == c.frames for c in wrist)


def test_eval_control_prints_the_table(tiny_control_dir, tiny_data, tmp_path, capsys):
    report = tmp_path / "eval.json"
    code = main(
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
            "pelvis,cross",
            "--samples",
            "2",
            "--density",
            "1,196",
            "--quiet",
            "--json",
            str(report),
        ]
    )
    printed = capsys.readouterr().out
    assert code == 0, printed
    assert printed.count("Traj.err") == 2 and "joints cross" in printed
    data = json.loads(report.read_text())
    assert [d["joints"] for d in data] == ["pelvis", "cross"]
    summary = data[0]["summary"]
    assert set(summary) == {"1", "196", "all"} and np.isfinite(summary["all"]["avg"])
    assert 0 <= summary["all"]["traj"] <= 1 and summary["all"]["cases"] == 2
    assert len(data[1]["cases"]) == 2 and data[1]["cases"][1]["joints"] == ["left_foot"]
    _one_line_error(
        capsys,
        ["eval", "control", "--model", str(tiny_control_dir), "--data", str(tiny_data), "--joints", "elbow"],
        "unknown --joints 'elbow'",
    )
    _one_line_error(
        capsys,
        ["eval", "control", "--model", str(tiny_control_dir), "--data", str(tiny_data), "--density", "7"],
        "unknown --density '7'",
    )
