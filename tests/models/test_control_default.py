"""The embedded default model (when shipped) meets a spec taken from the real HumanML3D clip."""

from __future__ import annotations

import numpy as np
import pytest

from controlmm.assets import default_model_dir
from controlmm.control import ControlSpec
from controlmm.motion.recover import features_to_joints_np

pytestmark = pytest.mark.skipif(
    not (default_model_dir() / "model.json").is_file(), reason="no embedded default model in this checkout"
)


def test_embedded_default_meets_a_real_multi_joint_spec(sample_features):
    import torch

    from controlmm.generate import generate_controlled, load_model

    torch.set_num_threads(1)
    model = load_model()
    assert {"tokenizer", "transformer", "residual", "control"} <= set(model.parts)
    j = features_to_joints_np(sample_features[:120])  # real HumanML3D clip 012314, its own joints
    spec = ControlSpec.from_dict(
        {
            "coords": "human",
            "constraints": [
                {"joint": "pelvis", "frame_range": [0, 39], "positions": j[0:40, 0].tolist()},  # dense
                {"joint": "right_wrist", "frame": 60, "position": j[60, 21].tolist()},  # sparse
                {"joint": "left_foot", "frame": 90, "position": j[90, 10].tolist()},
                {"joint": "head", "frame": 110, "position": j[110, 15].tolist()},
            ],
        }
    )
    out = generate_controlled(
        model, "a person walks forward and turns around", control=spec, frames=120, preset="medium", seed=0
    )
    errors = out.errors[0]
    assert errors.shape == (43,) and float(errors.max()) <= 0.02
    uncontrolled = generate_controlled(
        model,
        "a person walks forward and turns around",
        control=spec,
        frames=120,
        preset=model_free_preset(),
        seed=0,
    )
    assert float(np.mean(uncontrolled.errors[0])) > 10 * float(np.mean(errors))


def model_free_preset():
    from controlmm.editing import EditingConfig

    return EditingConfig(name="none", control_model=False, logits_steps=0, codebook_steps=0)


def test_foot_contact_run_stops_planted_feet_sliding_and_keeps_the_spec():
    import torch

    from controlmm.editing import PRESETS
    from controlmm.editing.foot_contact import foot_contact_term
    from controlmm.generate import generate, generate_controlled, load_model
    from controlmm.motion.geometry import foot_skating_ratio

    torch.set_num_threads(1)
    model = load_model()
    text = "a person walks forward"
    walk = generate(model, text, frames=120, seed=0).motion.joints
    # the model's own walk, its pelvis moved 15 cm sideways at three frames: editing makes the feet slide
    spec = ControlSpec.from_dict(
        {
            "coords": "human",
            "constraints": [
                {
                    "joint": "pelvis",
                    "frame": f,
                    "position": (walk[f, 0] + np.array([0.15, 0.0, 0.0])).tolist(),
                }
                for f in (30, 60, 90)
            ],
        }
    )
    without = generate_controlled(
        model,
        text,
        control=spec,
        frames=120,
        seed=0,
        preset=PRESETS["accurate"].with_overrides(contact_steps=0),
    )
    with_run = generate_controlled(model, text, control=spec, frames=120, seed=0, preset="accurate")
    assert not without.records[0].contact_kept and with_run.records[0].contact_kept
    assert float(without.errors[0].max()) <= 0.01 and float(with_run.errors[0].max()) <= 0.01
    slide = foot_contact_term(weight=1.0)
    before = float(slide(torch.as_tensor(without.motion.joints)[None]))
    after = float(slide(torch.as_tensor(with_run.motion.joints)[None]))
    assert after < 0.5 * before
    assert foot_skating_ratio(with_run.motion.joints) < foot_skating_ratio(without.motion.joints)
