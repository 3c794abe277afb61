"""Body-part timeline control: spec validation, the control signal and blending as pure functions, and
end-to-end runs on a tiny randomly initialised model directory (real torch modules, real MiniLM)."""

from __future__ import annotations

import json

import numpy as np
import pytest
import torch

from controlmm.cli.main import main
from controlmm.control import LossTerm
from controlmm.editing import EditingConfig
from controlmm.errors import ControlMMError
from controlmm.generate import generate, load_model
from controlmm.motion import load_motion
from controlmm.timeline import (
    BODY_PARTS,
    Timeline,
    Track,
    boundary_speed,
    build_signal,
    generate_timeline,
    held_drift,
    part_joints,
)
from controlmm.timeline.signals import hinge_term, local_positions, reference_targets

STEPS = EditingConfig(name="test", logits_steps=0, codebook_steps=400)


@pytest.fixture(scope="module")
def random_model_dir(tmp_path_factory, humanml3d_dir):
    """A model directory of the ``tiny`` preset with freshly initialised weights (no training)."""
    from controlmm.models import preset_config
    from controlmm.models.model_dir import PARTS, new_manifest, save_part, write_manifest, write_statistics
    from controlmm.motion.normalization import Normalizer

    out = tmp_path_factory.mktemp("timeline") / "random-tiny"
    out.mkdir()
    cfg = preset_config("tiny")
    torch.manual_seed(0)
    manifest = new_manifest(cfg, {})
    for name in ("tokenizer", "transformer", "residual"):
        manifest["parts"][name] = save_part(out, name, PARTS[name].build(cfg), "float32")
    write_statistics(
        out, Normalizer.load(humanml3d_dir / "Mean.npy", humanml3d_dir / "Std.npy").with_feat_bias()
    )
    write_manifest(out, manifest)
    return out


@pytest.fixture(scope="module")
def model(random_model_dir):
    return load_model(random_model_dir)


# -- the spec ---------------------------------------------------------------------------------------
def test_parts_partition_the_skeleton():
    groups = [j for name, joints in BODY_PARTS.items() if name != "whole_body" for j in joints]
    assert sorted(groups) == list(range(22))
    assert part_joints("Left Arm") == part_joints("left-arm") == (13, 16, 18, 20)
    assert BODY_PARTS["whole_body"] == tuple(range(22))


def test_spec_round_trip_and_defaults(tmp_path):
    data = {
        "tracks": [
            {"part": "legs", "prompt": "walk", "start": 0, "end": 4},
            {
                "part": "right arm",
                "prompt": "wave",
                "start": 1,
                "end": 3,
                "probe": {"family": "wave_right", "claims": {"hand": "right"}},
            },
        ]
    }
    timeline = Timeline.from_dict(data)
    assert timeline.seconds == 4.0 and timeline.num_frames == 80 and timeline.base_prompt == "walk"
    assert timeline.tracks[1].part == "right_arm" and timeline.tracks[1].frames(80) == (20, 60)
    path = tmp_path / "t.json"
    path.write_text(json.dumps(timeline.to_dict()))
    assert Timeline.load(path) == timeline
    assert Timeline([Track("head", "nod", 0, 2.5)], seconds=3, base="stand").to_dict()["base"] == "stand"


@pytest.mark.parametrize(
    "data, message",
    [
        ({"tracks": []}, "non-empty 'tracks' list"),
        (
            {"tracks": [{"part": "tail", "prompt": "x", "start": 0, "end": 3}]},
            "track 0: unknown body part 'tail'; allowed: legs, torso",
        ),
        (
            {"tracks": [{"part": "legs", "prompt": "x", "start": 0, "end": 3}], "seconds": 2.5},
            "ends at 3 s, after the timeline's end",
        ),
        ({"tracks": [{"part": "legs", "prompt": "x", "start": -1, "end": 3}]}, "start -1 s is negative"),
        ({"tracks": [{"part": "legs", "prompt": "x", "start": 1, "end": 1.1}], "seconds": 3}, "too short"),
        ({"tracks": [{"part": "legs", "prompt": "", "start": 0, "end": 3}]}, "non-empty prompt"),
        ({"tracks": [{"part": "legs", "prompt": "x", "start": "0", "end": 3}]}, "start must be a number"),
        ({"tracks": [{"part": "legs", "prompt": "x", "start": 0}]}, "track 0 is missing end"),
        (
            {"tracks": [{"part": "legs", "prompt": "x", "start": 0, "end": 3, "speed": 1}]},
            "unknown key(s) speed",
        ),
        (
            {"tracks": [{"part": "legs", "prompt": "x", "start": 0, "end": 12}]},
            "length 12 s is out of range; allowed 2..9.8",
        ),
        (
            {"tracks": [{"part": "legs", "prompt": "x", "start": 0, "end": 3, "probe": {"family": "fly"}}]},
            "no probe for family 'fly'",
        ),
        ({"track": []}, "unknown timeline key(s) track"),
        ([1], "must be a JSON object"),
    ],
)
def test_spec_errors_are_one_line(data, message):
    with pytest.raises(ControlMMError) as info:
        Timeline.from_dict(data)
    assert message in str(info.value) and "\n" not in str(info.value)


# -- the control signal (pure functions) --------------------------------------------------------------
def test_signal_of_an_arm_track_holds_everything_else_in_the_world():
    signal = build_signal(
        40, part_joints("right_arm"), (10, 30), root_moves=False, blend_frames=5, blend_rate=0.05
    )
    assert signal.free.sum() == 20 * 4 and (signal.mask == ~signal.free).all() and len(signal.hold) == 0
    assert set(signal.blend.frames.tolist()) == set(range(10, 15)) | set(range(25, 30))
    first = signal.blend.margins[signal.blend.frames == 10]
    fifth = signal.blend.margins[signal.blend.frames == 14]
    np.testing.assert_allclose(first, 0.008 + 0.05) and np.testing.assert_allclose(fifth, 0.008 + 0.25)
    # a span starting at frame 0 has no start edge to blend
    assert 0 not in build_signal(40, (21,), (0, 20), root_moves=False).blend.frames


def test_signal_of_a_legs_track_carries_the_rest_with_the_body(sample_joints):
    joints = sample_joints[:40].astype(np.float32)
    signal = build_signal(40, part_joints("legs"), (10, 30), root_moves=True)
    assert signal.mask[:10].all() and not signal.mask[10:].any()
    assert len(signal.hold) == 20 * (22 - 9) + 10 * 22
    # moving and turning the whole body after the span start changes no held-relative entry...
    moved = joints.copy()
    c, s = np.cos(0.7), np.sin(0.7)
    rot = np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]], dtype=np.float32)
    moved[10:] = moved[10:] @ rot.T + np.array([0.5, 0.0, -0.3], dtype=np.float32)
    drift = held_drift(moved, joints, signal)
    assert drift[10:].max() < 1e-5
    # ...while a world-held entry or a change of pose relative to the pelvis is measured
    moved[35, 20, 1] += 0.1
    moved[5, 3, 0] += 0.05
    drift = held_drift(moved, joints, signal)
    assert drift[35, 20] == pytest.approx(0.1, abs=1e-5) and drift[5, 3] == pytest.approx(0.05, abs=1e-5)


def test_hinge_term_is_zero_inside_its_margins_and_pulls_outside(sample_joints):
    ref = torch.as_tensor(sample_joints[:40], dtype=torch.float32)
    signal = build_signal(40, part_joints("left_arm"), (10, 30), root_moves=False)
    term = hinge_term("blend", reference_targets(ref.numpy(), signal.blend), signal.blend)
    near = ref.clone()[None]
    near[0, 10:30, 20] += 0.005  # within every margin
    assert float(term(near)[0]) == 0.0
    far = ref.clone()[None].requires_grad_(True)
    loss = term(far + torch.tensor([0.0, 0.3, 0.0]))
    loss.sum().backward()
    assert (
        float(loss[0].detach()) > 0
        and far.grad[0, 10, 20].abs().sum() > 0
        and far.grad[0, 20, 20].abs().sum() == 0
    )
    world = ref[signal.blend.frames, signal.blend.joints]
    np.testing.assert_allclose(
        local_positions(ref, signal.blend).numpy(), world
    )  # world entries stay as they are


def test_boundary_speed_sees_a_jump():
    joints = np.zeros((40, 22, 3), dtype=np.float32)
    joints[:, :, 2] = np.arange(40)[:, None] * 0.01  # 0.2 m/s
    assert boundary_speed(joints, 20) == pytest.approx(0.2, abs=1e-5)
    joints[20:, 21, 1] += 0.1  # 0.1 m in one frame: 2 m/s
    assert boundary_speed(joints, 20) == pytest.approx(np.hypot(2.0, 0.2), abs=1e-4)
    assert boundary_speed(joints, 30) == pytest.approx(0.2, abs=1e-5)


# -- end to end ---------------------------------------------------------------------------------------
def _wrist_up(height: float) -> LossTerm:
    """An extra loss term (as the plan pipeline passes obstacle losses): right wrist up at frames 20..29."""
    return LossTerm("wrist_up", lambda j: torch.relu(height - j[:, 20:30, 21, 1]).pow(2).mean(-1), 1.0)


def test_tracks_keep_what_earlier_passes_fixed(model):
    legs = {"part": "legs", "prompt": "a person walks forward", "start": 0, "end": 2.4}
    arm = {"part": "right_arm", "prompt": "a person waves the right hand", "start": 0.8, "end": 1.8}
    plain = generate(model, "a person walks forward", frames=48, seed=3).motion
    height = float(plain.joints[20:30, 21, 1].max()) + 0.3
    terms = [_wrist_up(height)]
    base, base_report = generate_timeline(
        model, {"tracks": [legs]}, seed=3, preset=STEPS, terms=terms, settle_steps=400
    )
    assert (
        len(base_report["passes"]) == 1 and base_report["passes"][0]["editing_steps"] > 0
    )  # the base made track 0
    motion, report = generate_timeline(
        model, {"tracks": [legs, arm]}, seed=3, preset=STEPS, terms=terms, settle_steps=400
    )
    assert motion.joints.shape == (48, 22, 3) and motion.features.shape == (48, 263)
    assert motion.joints[20:30, 21, 1].min() > height - 0.02  # the extra term holds in every pass
    assert report["passes"][1]["editing_steps"] > 0
    owner = motion.extras["timeline_owner"]
    assert (owner[16:36][:, [14, 17, 19, 21]] == 1).all() and (owner[:16] == 0).all()
    # every entry the arm track does not own stays within 2 cm of the base pass
    drift = np.linalg.norm(motion.joints - base.joints, axis=-1)[owner == 0]
    assert drift.max() < 0.02, f"held entries drifted {100 * drift.max():.2f} cm"
    assert report["max_drift_cm"] == pytest.approx(100 * drift.max(), abs=0.01)
    # no jump at the span edges: at most the base motion's speed plus the blend allowance
    base_speed = max(boundary_speed(base.joints, f) for f in (16, 36))
    for name, frame in (("start", 16), ("end", 36)):
        speed = report["tracks"][1]["boundary_speed_mps"][name]
        assert speed == pytest.approx(boundary_speed(motion.joints, frame), abs=1e-3)
        assert speed <= base_speed + 0.058 * 20 * 2, (name, speed, base_speed)


def test_a_legs_track_carries_the_held_parts_along(model):
    timeline = Timeline(
        [
            Track("left_arm", "a person raises the left arm", 0, 2.4),
            Track("legs", "a person jumps forward", 0.6, 1.6),
        ],
        base="a person stands",
    )
    motion, report = generate_timeline(model, timeline, seed=1, preset=STEPS, settle_steps=400)
    assert [p["track"] for p in report["passes"]] == [None, 0, 1]
    # the legs pass holds the frames before its span in the world and everything else relative to the body
    assert report["passes"][2]["held_entries"] == 48 * 22 - 20 * 9
    owner = motion.extras["timeline_owner"]
    assert (owner[12:32][:, list(part_joints("legs"))] == 1).all() and (owner[:, [13, 16, 18, 20]] == 0).all()
    assert report["passes"][2]["drift_cm"] < 2.0 and report["max_drift_cm"] < 2.0
    assert report["tracks"][0]["final_drift_cm"] < 2.0


def test_cli_writes_motion_report_and_rejects_bad_specs(random_model_dir, tmp_path, capsys):
    spec = tmp_path / "spec.json"
    spec.write_text(
        json.dumps(
            {
                "seconds": 2.4,
                "base": "a person stands",
                "tracks": [{"part": "head", "prompt": "a person nods", "start": 0.4, "end": 2.0}],
            }
        )
    )
    out, report = tmp_path / "out.npz", tmp_path / "report.json"
    code = main(
        [
            "timeline",
            str(spec),
            "--out",
            str(out),
            "--report",
            str(report),
            "--model",
            str(random_model_dir),
            "--seed",
            "0",
            "--codebook-steps",
            "100",
        ]
    )
    assert code == 0
    motion = load_motion(out)
    assert motion.num_frames == 48 and motion.metadata["timeline"]["spec"]["base"] == "a person stands"
    assert json.loads(report.read_text())["tracks"][0]["part"] == "head"
    assert "max drift" in capsys.readouterr().out
    spec.write_text(json.dumps({"tracks": [{"part": "tail", "prompt": "x", "start": 0, "end": 3}]}))
    assert main(["timeline", str(spec), "--out", str(tmp_path / "bad.npz")]) == 2
    err = capsys.readouterr().err.strip()
    assert (
        err
        == (
            "controlmm: error: track 0: unknown body part 'tail'; allowed: legs, torso, head, left_arm, "
            "right_arm, whole_body"
        )
        and not (tmp_path / "bad.npz").exists()
    )
