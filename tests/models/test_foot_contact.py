"""The foot-contact term and run (controlmm.editing.foot_contact): values on hand-made joints, the preset
setting and its validation."""

from __future__ import annotations

import pytest
import torch

from controlmm.editing import PRESETS, EditingConfig
from controlmm.editing.foot_contact import foot_contact_term
from controlmm.errors import ControlMMError


def _feet(heights: float, step_m: float, frames: int = 11) -> torch.Tensor:
    """(1, T, 22, 3) joints: both feet (10, 11) at ``heights`` m moving ``step_m`` m along X per frame."""
    j = torch.zeros(1, frames, 22, 3)
    x = torch.arange(frames, dtype=torch.float32) * step_m
    for foot in (10, 11):
        j[0, :, foot, 0] = x
        j[0, :, foot, 1] = heights
    return j


def test_the_term_penalises_planted_feet_that_slide():
    term = foot_contact_term(weight=1.0)
    # 0.05 m per frame at 20 fps = 1 m/s, both feet on the floor: (1 - 0.5)^2 per foot and step, over T
    sliding = term(_feet(0.0, 0.05))
    torch.testing.assert_close(sliding, torch.tensor([2 * 10 * 0.25 / 11]))
    assert float(term(_feet(0.0, 0.02))) == 0.0  # 0.4 m/s: under the 0.5 m/s a planted foot may move
    assert float(term(_feet(0.2, 0.05))) == 0.0  # feet in the air may move
    assert float(foot_contact_term(weight=3.0)(_feet(0.0, 0.05))) == pytest.approx(3 * float(sliding))
    # contact is not differentiated: the gradient asks for slower feet, not for lifted ones
    j = _feet(0.0, 0.05).requires_grad_(True)
    term(j).sum().backward()
    assert float(j.grad[0, :, 10, 1].abs().sum()) == 0.0 and float(j.grad[0, :, 10, 0].abs().sum()) > 0


def test_accurate_preset_runs_it_and_bad_settings_are_refused():
    assert PRESETS["accurate"].contact_steps == 200 and PRESETS["accurate"].contact_weight == 0.3
    assert PRESETS["fast"].contact_steps == 0 and PRESETS["medium"].contact_steps == 0
    with pytest.raises(ControlMMError, match="contact_steps must be a whole number >= 0; got -1"):
        EditingConfig(contact_steps=-1)
    with pytest.raises(ControlMMError, match="contact_weight must be positive; got 0"):
        EditingConfig(contact_weight=0)
