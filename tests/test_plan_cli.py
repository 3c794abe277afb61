"""``controlmm plan`` input handling: one-line errors (exit 2) before any model is loaded, no output left."""

from __future__ import annotations

import json

import pytest

from controlmm.cli.main import main
from controlmm.control.spec import ControlSpec
from controlmm.pipeline.inputs import constraint_warnings, plan_seconds, start_pose_error
from scenes import load_scene
from tests.cli_helpers import run_cli

BLOCKED_START = """<mujoco model="blocked">
  <custom>
    <text name="controlmm.prompt" data="a person walks forward."/>
    <numeric name="controlmm.start" data="0 0 0"/>
  </custom>
  <worldbody>
    <light pos="0 0 3" dir="0 0 -1" directional="true"/>
    <geom name="floor" type="plane" size="0 0 0.05"/>
    <geom name="crate" type="box" size="0.3 0.3 0.5" pos="0.05 0 0.5"/>
  </worldbody>
</mujoco>
"""


@pytest.mark.parametrize(
    "args, needle",
    [
        (["--scene", "volcano"], "volcano"),
        (["--robot", "r2d2"], "r2d2"),
        (["--control", "missing_spec.json"], "missing_spec.json"),
        (["--rounds", "-1"], "rounds"),
        (["--seconds", "30"], "seconds"),
        (["--text", "  "], "text"),
        (["--fps", "5"], "fps"),
        (["--preset", "turbo"], "turbo"),
        (["--threads", "0"], "threads"),
    ],
)
def test_bad_input_is_one_line_exit_2(tmp_path, capsys, args, needle):
    out = tmp_path / "plan"
    assert run_cli(["plan", "--out", str(out), "--no-render", "--no-progress", *args]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and needle in err and "Traceback" not in err
    assert not out.exists()


def test_bad_spec_names_the_joint(tmp_path, capsys):
    spec = tmp_path / "spec.json"
    spec.write_text(
        json.dumps({"coords": "world", "constraints": [{"joint": "tail", "frame": 3, "position": [0, 0, 1]}]})
    )
    assert main(["plan", "--out", str(tmp_path / "p"), "--control", str(spec), "--no-progress"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "tail" in err and "pelvis" in err


def test_start_pose_inside_an_obstacle_is_an_error(tmp_path, capsys):
    xml = tmp_path / "blocked.xml"
    xml.write_text(BLOCKED_START)
    assert "crate" in start_pose_error(load_scene(xml, robot="g1"))
    assert start_pose_error(load_scene("table", robot="g1")) is None
    assert main(["plan", "--out", str(tmp_path / "p"), "--scene", str(xml), "--no-progress"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "crate" in err and "start" in err
    assert not (tmp_path / "p").exists()


def test_unreachable_and_buried_targets_warn_with_the_distance():
    scene = load_scene("table", robot=None)
    transform = scene.human_to_world(0.75)
    spec = ControlSpec.from_dict(
        {
            "coords": "world",
            "constraints": [
                {"joint": "pelvis", "frame": 40, "position": [20.0, 0.0, 0.74]},  # 21 m in 2 s
                {"joint": "right_wrist", "frame": 80, "position": [1.2, 0.0, 0.555]},  # inside the table top
                {"joint": "head", "frame": 100, "position": [0.0, 0.0, 3.0]},  # far above any head
                {"joint": "left_wrist", "frame": 120, "position": [-1.5, 0.3, 0.9]},  # fine
            ],
        }
    )
    warnings = constraint_warnings(spec, transform, scene.sdf())
    assert len(warnings) == 3
    far, buried, high = warnings
    assert "pelvis at frame 40" in far and "beyond" in far and "m" in far
    assert float(far.split(" is ")[1].split(" m")[0]) > 10
    assert "right_wrist" in buried and "inside an obstacle" in buried
    assert "head" in high and "above" in high
    assert constraint_warnings(ControlSpec.from_dict(scene.suggested_control), transform, scene.sdf()) == []


def _spec(*frames: int) -> ControlSpec:
    return ControlSpec.from_dict(
        {
            "coords": "world",
            "constraints": [{"joint": "pelvis", "frame": f, "position": [0.5, 0.0, 0.74]} for f in frames],
        }
    )


def test_a_plan_ends_half_a_second_after_its_last_constraint():
    assert plan_seconds(None, _spec(20, 80)) == pytest.approx(91 / 20)  # frames 0..90
    assert plan_seconds(None, _spec(5)) == pytest.approx(40 / 20)  # never shorter than 2 s
    assert plan_seconds(None, _spec(115)) == pytest.approx(120 / 20)  # never longer than the 6 s default
    assert plan_seconds(None, _spec(150)) == pytest.approx(151 / 20)  # ... unless a constraint is later
    assert plan_seconds(None, None) is None and plan_seconds(3.0, _spec(80)) == 3.0
    assert plan_seconds(None, _spec(196)) is None  # the generator names the out-of-range frame
    # the bundled example: a reach at frame 80
    assert plan_seconds(None, ControlSpec.from_dict(load_scene("table").suggested_control)) == pytest.approx(
        4.55
    )


def test_plan_help_explains_outputs(capsys):
    with pytest.raises(SystemExit) as exc:
        main(["plan", "--help"])
    assert exc.value.code == 0
    text = capsys.readouterr().out
    for word in ("report.json", "robot.csv", "render.mp4", "--rounds", "table", "Exit status"):
        assert word in text
