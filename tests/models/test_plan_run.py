"""``plan`` end to end on a tiny trained model: rounds, feedback terms, every output file, reproducibility."""

from __future__ import annotations

import json

import numpy as np
import pytest

from controlmm.errors import ControlMMError
from controlmm.motion.io import load_motion
from controlmm.pipeline import PlanConfig, plan, write_plan
from controlmm.pipeline.outputs import draw_in_child
from sim import CheckConfig

# Any real motion needs some non-physical root force averaged over 0.5 s; a limit of 0 makes every
# plan fail its first round, so the feedback path always runs.
STRICT = CheckConfig(max_sustained_residual_force_ratio=0.0)


@pytest.fixture(scope="module")
def strict_plan(tiny_model_dir):
    config = PlanConfig(
        scene="table",
        rounds=1,
        preset="fast",
        model=str(tiny_model_dir),
        seed=3,
        check=STRICT,
        render_fps=4.0,
        render_size=(96, 72),
    )
    return plan(config, progress=False)


def test_failures_become_feedback_terms_and_every_round_is_recorded(strict_plan):
    r0, r1 = strict_plan.rounds
    assert not r0.passed and any(f.kind == "residual_force" for f in r0.report.failures)
    assert "floor" in r0.terms and any(t.startswith("body_obstacle:table") for t in r0.terms)
    assert not any(t.startswith("feedback") for t in r0.terms)
    feedback = [t for t in r1.terms if t.startswith("feedback1:residual_force")]
    assert feedback and r1.terms[: len(r0.terms)] == r0.terms
    assert r1.editing["codebook_steps"] > 0  # the feedback round edited the codebook latent
    assert len(strict_plan.final.constraint_errors_m) == 1  # the table's right-hand target
    assert strict_plan.best in (0, 1)


def test_the_bundled_example_ends_half_a_second_after_the_reach(strict_plan):
    assert strict_plan.spec.last_frame == 80
    assert all(r.motion.num_frames == 91 for r in strict_plan.rounds)


def test_outputs_are_complete_and_consistent(strict_plan, tmp_path):
    out = tmp_path / "nested" / "plan"
    backend = write_plan(strict_plan, out, progress=False)
    names = {p.relative_to(out).as_posix() for p in out.rglob("*") if p.is_file()}
    assert {
        "motion.npz",
        "robot.csv",
        "robot.npz",
        "robot.json",
        "report.json",
        "plan.json",
        "render.mp4",
        "plots/top_view.png",
        "plots/clearance.png",
        "plots/report.png",
        "plots/motion.png",
    } <= names
    assert backend in ("mujoco", "stick")
    report = json.loads((out / "report.json").read_text())
    for key in (
        "passed",
        "max_penetration_m",
        "floor_penetration_m",
        "self_collision_frames",
        "joint_limit_violations",
        "foot_sliding_m",
        "residual_force",
        "failures",
        "rounds",
        "plan",
    ):
        assert key in report
    assert report["passed"] is False and report["plan"]["rounds_run"] == 2 == len(report["rounds"])
    assert report["plan"]["chosen_round"] == strict_plan.best
    csv = np.loadtxt(out / "robot.csv", delimiter=",")
    npz = np.load(out / "robot.npz")
    assert csv.shape == (report["num_frames"], 7 + 29) == (npz["qpos"].shape[0], npz["qpos"].shape[1])
    np.testing.assert_allclose(csv[:, 7:], npz["qpos"][:, 7:])
    motion = load_motion(out / "motion.npz")
    assert motion.num_frames == strict_plan.motion.num_frames
    np.testing.assert_allclose(motion.joints, strict_plan.motion.joints, atol=1e-6)
    assert not [p for p in out.parent.iterdir() if p.name.startswith(".")]  # no temporary directory left


def test_stage_timing_adds_up_in_the_report(strict_plan, tmp_path):
    """``report.json``'s ``timing``: every stage that ran, in order, summing to the total with ``other``."""
    write_plan(strict_plan, tmp_path / "plan", render=False, progress=False)
    timing = json.loads((tmp_path / "plan" / "report.json").read_text())["timing"]
    stages = timing["stages_s"]
    ran = [
        "startup",
        "text",
        "decoding",
        "codebook_editing",
        "retarget",
        "checks",
        "feedback_rounds",
        "outputs",
    ]
    assert [s for s in stages if s in ran] == ran  # the fast preset: no logits editing
    assert all(v >= 0 for v in stages.values()) and stages["decoding"] > 0 and stages["checks"] > 0
    assert sum(stages.values()) == pytest.approx(timing["total_s"], abs=0.01)
    assert timing["total_s"] >= strict_plan.seconds  # the plan, then writing its files
    r1 = strict_plan.rounds[1].seconds
    # report.json rounds each stage to 1 ms; the round's own seconds are not rounded
    assert stages["feedback_rounds"] >= r1["generate"] + r1["retarget"] + r1["check"] - 0.001
    line = strict_plan.timing.summary()
    assert line.startswith("timing: start-up ") and "feedback rounds" in line and "total" in line


def test_same_seed_same_plan(strict_plan, tiny_model_dir):
    again = plan(
        PlanConfig(scene="table", rounds=0, preset="fast", model=str(tiny_model_dir), seed=3, check=STRICT),
        progress=False,
    )
    np.testing.assert_allclose(again.rounds[0].motion.joints, strict_plan.rounds[0].motion.joints, atol=1e-5)


def test_plan_with_a_timeline(tiny_model_dir, tmp_path):
    spec = tmp_path / "timeline.json"
    spec.write_text(
        json.dumps(
            {
                "seconds": 3.0,
                "tracks": [
                    {"part": "whole_body", "prompt": "a person walks forward", "start": 0.0, "end": 3.0},
                    {
                        "part": "right_arm",
                        "prompt": "a person waves the right hand",
                        "start": 1.0,
                        "end": 2.0,
                    },
                ],
            }
        )
    )
    result = plan(
        PlanConfig(scene="empty", timeline=str(spec), rounds=0, preset="fast", model=str(tiny_model_dir)),
        progress=False,
    )
    assert result.spec is None and "right_arm 1-2 s" in result.text
    assert result.motion.num_frames == 60 and "timeline" in result.final.editing
    assert result.trajectory.qpos.shape[0] == result.report.num_frames


def test_parallel_plots_are_the_same_files(strict_plan, tmp_path):
    """``write_plan(parallel=True)`` (the CLI's) without a video draws half of the plots in a forked
    process: the same plot files, byte for byte, as drawn in one process."""
    one, two = tmp_path / "one", tmp_path / "two"
    write_plan(strict_plan, one, render=False, progress=False)
    write_plan(strict_plan, two, render=False, progress=False, parallel=True)
    plots = sorted(p.name for p in (one / "plots").iterdir())
    assert plots == sorted(p.name for p in (two / "plots").iterdir()) and len(plots) == 4
    for name in plots:
        assert (one / "plots" / name).read_bytes() == (two / "plots" / name).read_bytes(), name


def test_a_failing_plot_in_the_child_is_one_line_and_nothing_is_written(strict_plan, tmp_path):
    out = tmp_path / "plan"
    jobs = [lambda: None, lambda: 1 / 0]
    wait = draw_in_child(jobs)
    with pytest.raises(
        ControlMMError, match=r"^drawing the plots failed: ZeroDivisionError: division by zero$"
    ):
        wait(False)
    assert not out.exists()
