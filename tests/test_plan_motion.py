"""`controlmm plan --motion`: a recorded clip codebook-edited into a scene, as close to the clip as the
constraints allow, with its displacement reported and plotted."""

import json

import numpy as np
import pytest
from cli_helpers import one_line_error, run_cli
from mocap_files import smplh, z_up

from controlmm.generate import load_model
from controlmm.motion.container import resample
from controlmm.motion.skeleton import FPS, JOINT_INDEX
from controlmm.pipeline.clip import ClipEditor, closeness_term, displacement, load_clip


@pytest.fixture(scope="module")
def smplh_clip(sample_joints, tmp_path_factory):
    """3 s of the real sample as SMPL-H joint positions, Z up, 30 fps (.npy)."""
    path = tmp_path_factory.mktemp("clip") / "walk_smplh.npy"
    np.save(path, z_up(smplh(resample(sample_joints[:61].astype(np.float64), 20, 30))).astype(np.float32))
    return path


def test_an_unconstrained_clip_is_kept_exactly(smplh_clip):
    clip = load_clip(str(smplh_clip), {"fps": 30})
    editor = ClipEditor(load_model(), clip)
    assert np.allclose(editor.decode(editor.latent)[0].numpy(), clip.joints, atol=1e-5)
    edited = editor.edit(editor.latent, None, None, [closeness_term(clip.joints)], _fast(), "walk")
    moved = displacement(edited.motion.joints, clip.joints)
    assert moved.max_m < 1e-5 and edited.record["codebook_steps"] == 0


def _fast():
    from controlmm.editing.presets import editing_preset

    return editing_preset("fast")


def test_plan_edits_the_clip_onto_a_target_and_reports_the_displacement(smplh_clip, tmp_path, capsys):
    clip = load_clip(str(smplh_clip), {"fps": 30})
    frame, wrist = 30, JOINT_INDEX["right_wrist"]
    target = clip.joints[frame, wrist] + np.array([0.0, 0.12, 0.0])  # 12 cm higher than recorded
    spec = tmp_path / "spec.json"
    spec.write_text(
        json.dumps({"constraints": [{"joint": "right_wrist", "frame": frame, "position": target.tolist()}]})
    )
    out = tmp_path / "plan"
    argv = ["plan", "--motion", str(smplh_clip), "--source-fps", "30", "--up", "z", "--scene", "empty"]
    argv += ["--control", str(spec), "--rounds", "0", "--preset", "fast", "--no-render", "--out", str(out)]
    argv += ["--format", "lafan1,gmr", "--no-progress"]
    code = run_cli(argv)
    stdout = capsys.readouterr().out
    assert code in (0, 1), stdout
    assert "from the recorded clip" in stdout
    report = json.loads((out / "report.json").read_text())
    moved = report["clip"]["displacement"]
    assert report["clip"]["import"]["skeleton"] == "smplh" and report["clip"]["frames"] == clip.num_frames
    assert report["rounds"][0]["constraint_errors_m"][0] < 0.02  # the target is met
    per_frame = np.array(moved["per_frame_max_m"])
    assert 0.08 < moved["max_m"] == pytest.approx(per_frame.max(), abs=1e-5)  # the arm moved to get there
    far = np.abs(np.arange(len(per_frame)) - frame) > 1.0 * FPS
    assert per_frame[far].mean() < 0.02 and moved["mean_m"] < 0.03  # and little else did
    for name in ("robot.pkl", "robot.csv", "robot.npz", "source_motion.npz", "plots/displacement.png"):
        assert (out / name).is_file(), name
    assert not (out / "robot_qpos.csv").exists()


def test_plan_motion_bad_input_is_one_line(tmp_path, smplh_clip, capsys):
    out = str(tmp_path / "plan")
    one_line_error(capsys, ["plan", "--motion", str(smplh_clip), "--out", out], "--source-fps")
    argv = ["plan", "--motion", str(smplh_clip), "--source-fps", "30", "--timeline", "t.json", "--out", out]
    one_line_error(capsys, argv, "motion to edit or a timeline")
    argv = ["plan", "--motion", str(smplh_clip), "--source-fps", "30", "--motion-start", "2.5", "--out", out]
    one_line_error(capsys, argv, "at least 2 s")
    assert not (tmp_path / "plan").exists()
