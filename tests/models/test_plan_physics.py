"""``plan`` with the physics execution check as the last check of its rounds, on a tiny trained model."""

from __future__ import annotations

import json

import numpy as np
import pytest

from controlmm.pipeline import PlanConfig, plan, write_plan
from sim import CheckConfig, PhysicsConfig, replay_certificate


@pytest.mark.slow
def test_plan_executes_its_round_in_physics_and_exports_the_certificate(tiny_model_dir, tmp_path):
    config = PlanConfig(
        scene="empty",
        text="a person bends down and stands back up",
        seconds=2.0,
        rounds=0,
        preset="fast",
        model=str(tiny_model_dir),
        seed=1,
        render=False,
        plots=False,
        check=CheckConfig(physics=True),
        physics=PhysicsConfig(samples=8, horizon_s=0.2),
    )
    result = plan(config, progress=False)
    physics = result.report.physics
    assert physics is not None and physics.num_frames == result.trajectory.num_frames
    assert result.report.passed == (not result.report.errors)
    kinds = {f.kind for f in physics.failures}
    assert kinds <= {"tracking_fall", "tracking_error"}
    assert all(f in result.report.failures for f in physics.failures)  # physics failures are report failures
    out = tmp_path / "plan"
    write_plan(result, out, progress=False)
    report = json.loads((out / "report.json").read_text())
    assert report["physics"]["passed"] == physics.passed
    assert report["rounds"][0]["physics"]["fell"] == physics.fell
    assert json.loads((out / "plan.json").read_text())["physics"]["samples"] == 8
    qpos = replay_certificate(out / "physics_model.xml", out / "physics.npz")
    with np.load(out / "physics.npz") as npz:
        assert np.array_equal(qpos, npz["qpos"])
    rows = np.loadtxt(out / "robot_physics.csv", delimiter=",", ndmin=2)
    assert rows.shape[1] == result.trajectory.qpos.shape[1]
