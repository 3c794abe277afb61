import json

import numpy as np
import pytest
import torch

from controlmm.control import ControlSpec, constraint_errors, control_loss
from controlmm.errors import ControlMMError
from controlmm.frames import HumanToWorld


def test_sparse_and_dense_forms(tmp_path):
    data = {
        "coords": "human",
        "constraints": [
            {"joint": "right_wrist", "frame": 60, "position": [0.3, 1.2, 0.5]},
            {"joint": 0, "frame_range": [10, 12], "positions": [[0, 0.9, 0.1], [0, 0.9, 0.2], [0, 0.9, 0.3]]},
        ],
    }
    (tmp_path / "spec.json").write_text(json.dumps(data))
    spec = ControlSpec.load(tmp_path / "spec.json")
    assert len(spec.constraints) == 4
    targets, mask = spec.dense(100)
    assert mask.sum() == 4 and mask[60, 21] and mask[11, 0]
    assert np.allclose(targets[12, 0], [0, 0.9, 0.3])
    assert ControlSpec.from_dict(spec.to_dict()) == spec


def test_world_coords_convert_through_frames():
    tf = HumanToWorld(scale=0.8, yaw=0.0, translation=(1.0, 0.0, 0.0))
    spec = ControlSpec.from_dict(
        {"coords": "world", "constraints": [{"joint": "head", "frame": 5, "position": [1.8, 0.0, 1.2]}]}
    )
    human = spec.human_positions(tf)
    assert np.allclose(tf.to_world(human), [[1.8, 0.0, 1.2]])
    assert np.allclose(human, [[0.0, 1.5, 1.0]])  # 1 m ahead, 1.5 m up in human units


@pytest.mark.parametrize(
    "spec,needle",
    [
        (
            {"constraints": [{"joint": "left_hand", "frame": 1, "position": [0, 0, 0]}]},
            "valid joints: pelvis",
        ),
        ({"constraints": [{"joint": 22, "frame": 1, "position": [0, 0, 0]}]}, "out of range"),
        ({"constraints": [{"joint": "head", "frame": -1, "position": [0, 0, 0]}]}, ">= 0"),
        ({"constraints": [{"joint": "head", "frame": 1, "position": [0, "nan", 0]}]}, "NaN"),
        ({"constraints": [{"joint": "head", "frame": 1, "position": [0, 0]}]}, "shape"),
        (
            {
                "constraints": [
                    {"joint": "head", "frame": 1, "position": [0, 0, 0]},
                    {"joint": 15, "frame": 1, "position": [1, 0, 0]},
                ]
            },
            "duplicate",
        ),
        ({"constraints": [{"joint": "head", "frame_range": [3, 5], "positions": [[0, 0, 0]]}]}, "(3, 3)"),
        ({"coords": "robot", "constraints": []}, "coords must be one of"),
        ({"constraints": [{"joint": "head", "frame": 1.5, "position": [0, 0, 0]}]}, "whole number"),
    ],
)
def test_bad_specs_are_one_line_errors(spec, needle):
    with pytest.raises(ControlMMError) as info:
        ControlSpec.from_dict(json.loads(json.dumps(spec).replace('"nan"', "NaN")))
    assert needle in str(info.value) and "\n" not in str(info.value)


def test_frame_outside_motion():
    spec = ControlSpec.from_dict({"constraints": [{"joint": "head", "frame": 120, "position": [0, 1, 0]}]})
    with pytest.raises(ControlMMError, match=r"frames 0\.\.99"):
        spec.dense(100)


def test_bad_json_file(tmp_path):
    (tmp_path / "bad.json").write_text("{not json")
    with pytest.raises(ControlMMError, match="not valid JSON"):
        ControlSpec.load(tmp_path / "bad.json")


def test_control_loss_matches_definition_and_errors(sample_joints):
    spec = ControlSpec.from_dict(
        {
            "constraints": [
                {"joint": "pelvis", "frame": 10, "position": (sample_joints[10, 0] + [0.1, 0, 0]).tolist()},
                {"joint": "left_wrist", "frame": 30, "position": sample_joints[30, 20].tolist()},
            ]
        }
    )
    targets, mask = spec.dense(len(sample_joints))
    joints = torch.tensor(sample_joints)[None].repeat(2, 1, 1, 1)
    joints[1, 30, 20, 1] += 0.2
    loss = control_loss(joints, torch.tensor(targets), torch.tensor(mask))
    assert torch.allclose(loss, torch.tensor([0.01 / 6, (0.01 + 0.04) / 6]), atol=1e-6)
    err = constraint_errors(sample_joints, spec)
    assert np.allclose(err, [0.1, 0.0], atol=1e-6)


def test_pinned_frame0_warning():
    spec = ControlSpec.from_dict(
        {"constraints": [{"joint": "pelvis", "frame": 0, "position": [0.5, 0.9, 0.0]}]}
    )
    assert "frame 0" in spec.pinned_frame0_warnings()[0]
