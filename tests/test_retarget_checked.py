"""Retargeting checked in MuJoCo (``controlmm.pipeline.retarget_checked``) and the flat feet's
lift (``SolverConfig.foot_lift``): T1 on a generated clip whose default output fails
``controlmm validate`` on its 20 N m ankles and whose fallback passes it; a passing output
tried once; the ``controlmm retarget`` command's check line and JSON."""

from __future__ import annotations

import itertools
import json
import subprocess
import sys
from dataclasses import replace

import numpy as np
import pytest

from controlmm.corpus import CorpusConfig, make_clip, plan_clips
from controlmm.errors import ControlMMError
from controlmm.frames import HumanToWorld
from controlmm.motion import Motion, save_motion
from controlmm.pipeline import retarget_checked
from controlmm.pipeline.retarget_checked import FALLBACKS, FIT_GIVE, RETRIED_KINDS
from retarget import SolverConfig, load_robot
from retarget.targets import build_targets
from scenes import load_scene
from sim import check_trajectory

FPS = 30.0


def corpus_clip(index: int, family: str) -> Motion:
    """Clip ``index`` of the default corpus's plan (20 fps), generated here."""
    spec = next(itertools.islice(plan_clips(CorpusConfig(clips=9800, seed=0)), index, None))
    assert spec.family == family
    return Motion(joints=make_clip(spec)[1].astype(np.float32), fps=20.0)


@pytest.fixture(scope="module")
def t1_checked():
    """T1 on corpus clip 000011 (a crouched walk: its push-offs load the ankles past their motors)."""
    return retarget_checked(corpus_clip(11, "crouch_walk"), "t1", fps=FPS, metrics=False)


def test_a_failing_output_is_replaced_by_a_fallback_that_passes(t1_checked):
    """The robot's own settings fail the check on ankle torque; a fallback (flatter contact feet)
    passes it, checked again here independently, within FIT_GIVE of the first fit."""
    out = t1_checked
    first = out.attempts[0]
    assert first.name == "default" and not first.passed and "torque_limit" in first.errors
    assert set(first.errors) <= set(RETRIED_KINDS)
    assert out.fallback in {f.name for f in FALLBACKS}
    assert out.report.passed
    assert check_trajectory(load_scene("empty", robot="t1"), out.trajectory).passed
    kept = next(a for a in out.attempts if a.name == out.fallback)
    assert kept.passed and kept.fit_m <= first.fit_m * (1 + FIT_GIVE)
    assert all(kept.fit_m <= a.fit_m for a in out.attempts[1:] if a.passed)  # the closest pass
    assert len(out.attempts) == 1 + len(FALLBACKS)
    record = out.to_dict()
    assert (
        record["passed"]
        and record["fallback"] == out.fallback
        and len(record["attempts"]) == len(out.attempts)
    )


def test_a_passing_output_is_checked_once():
    """G1 on the same clip passes with its own settings: nothing else is tried."""
    out = retarget_checked(corpus_clip(11, "crouch_walk"), "g1", fps=FPS, metrics=False)
    assert out.report.passed and out.fallback is None
    assert [a.name for a in out.attempts] == ["default"]


def test_a_failure_no_setting_clears_is_not_retried():
    """G1 stepping up onto a platform that the empty scene does not have floats: no foot
    setting changes that, so none is tried (RETRIED_KINDS)."""
    out = retarget_checked(corpus_clip(40, "platform"), "g1", fps=FPS, metrics=False)
    assert not out.report.passed and "floating" in out.attempts[0].errors
    assert [a.name for a in out.attempts] == ["default"] and out.fallback is None


def test_bad_fit_give_is_one_line():
    with pytest.raises(ControlMMError, match="fit_give must be 0 or more; got -0.1"):
        retarget_checked(corpus_clip(11, "crouch_walk"), "g1", fps=FPS, fit_give=-0.1)


def test_flat_feet_lift_straight_up_where_the_human_rolls():
    """With flat contact feet (``foot_roll`` 0), ``foot_lift`` 1 raises the locked ankle
    targets where the human's heel is up (a toe-off) and nowhere lowers them; their
    horizontal place stays. With rolling feet (``foot_roll`` 1) it changes nothing."""
    t1 = load_robot("t1")
    motion = corpus_clip(11, "crouch_walk")
    base = SolverConfig(**t1.mapping.solver)
    transform = HumanToWorld(scale=t1.scale)
    joints = motion.joints.astype(np.float64)
    ankle = t1.keypoint_index("left_ankle")

    def ankle_targets(config: SolverConfig) -> np.ndarray:
        return build_targets(t1, joints, motion.fps, transform, config).kp_pos[:, ankle]

    flat = ankle_targets(replace(base, foot_roll=0.0))
    lifted = ankle_targets(replace(base, foot_roll=0.0, foot_lift=1.0))
    rise = lifted[:, 2] - flat[:, 2]
    assert rise.min() > -1e-9 and rise.max() > 0.02
    np.testing.assert_allclose(lifted[:, :2], flat[:, :2], atol=1e-9)
    np.testing.assert_array_equal(ankle_targets(base), ankle_targets(replace(base, foot_lift=1.0)))


def test_the_retarget_command_reports_the_check(tmp_path):
    """``controlmm retarget`` checks its output (as ``controlmm validate``) by default and says
    so on one line and in OUT.json; ``--no-check`` skips it; a scene that does not exist is one
    line and exit 2, with nothing written."""
    motion = corpus_clip(11, "crouch_walk")
    path = tmp_path / "hop.npz"
    save_motion(motion, path)
    cmd = [sys.executable, "-m", "controlmm", "retarget", str(path), "--robot", "t1", "--fps", "30"]
    done = subprocess.run([*cmd, "--out", str(tmp_path / "a")], capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    assert "check (empty scene, as controlmm validate): PASSED with the fallback" in done.stdout
    check = json.loads((tmp_path / "a.json").read_text())["metrics"]["check"]
    assert (
        check["passed"] and check["scene"] == "empty" and check["attempts"][0]["errors"] == ["torque_limit"]
    )
    done = subprocess.run([*cmd, "--no-check", "--out", str(tmp_path / "b")], capture_output=True, text=True)
    assert done.returncode == 0 and "check (" not in done.stdout
    assert "check" not in json.loads((tmp_path / "b.json").read_text())["metrics"]
    done = subprocess.run(
        [*cmd, "--check-scene", "no_such_scene", "--out", str(tmp_path / "c")], capture_output=True, text=True
    )
    assert done.returncode == 2 and len(done.stderr.strip().splitlines()) == 1, done.stderr
    assert "no_such_scene" in done.stderr
    assert not list(tmp_path.glob("c*"))
