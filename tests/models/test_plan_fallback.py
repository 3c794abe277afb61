"""``controlmm plan`` with the Booster T1: the bundled example's rounds fail ``validate`` on the
T1's 20 N m ankles until the retargeter's fallback settings (``with_fallbacks``) are tried on
the same motion; the plan then passes, and its report names the fallback."""

from __future__ import annotations

import pytest

from controlmm.assets import default_model_dir
from controlmm.pipeline import PlanConfig, plan
from controlmm.pipeline.retarget_checked import FALLBACKS
from scenes import load_scene
from sim import check_trajectory

pytestmark = pytest.mark.skipif(
    not (default_model_dir() / "model.json").is_file(), reason="no embedded default model in this checkout"
)


def test_a_t1_plan_passes_with_a_retargeting_fallback():
    import torch

    torch.set_num_threads(1)
    result = plan(PlanConfig(robot="t1"), progress=False)
    assert result.passed
    kept = [r for r in result.rounds if r.fallback is not None]
    assert kept and kept[0].fallback in {f.name for f in FALLBACKS}
    final = result.final
    assert check_trajectory(load_scene(result.scene.name, robot="t1"), final.trajectory).passed
    assert final.to_dict()["retarget_fallback"] == final.fallback
    # rounds that passed with the robot's own settings or failed on other kinds record none
    assert all(r.to_dict()["retarget_fallback"] is None for r in result.rounds if r.fallback is None)
