"""Recorded motion in: BVH of each naming family, mapping files, SMPL / SMPL-H / SMPL-X arrays.

Every file is built here from the real HumanML3D sample's joints (tests/mocap_files.py); the
reference is the same joints through HumanML3D's processing (``Motion.from_joints``).
"""

import json

import numpy as np
import pytest
import torch
from cli_helpers import one_line_error, run_cli
from mocap_files import (
    CMU,
    CMU_INSERT,
    CMU_METRES_PER_UNIT,
    CUSTOM,
    LAFAN1,
    MIXAMO,
    smplh,
    smplh_depth_first,
    smplx,
    z_up,
)

from controlmm.errors import ControlMMError
from controlmm.motion import Motion, load_motion
from controlmm.motion.bvh import write_bvh
from controlmm.motion.skeleton import JOINT_INDEX, JOINT_NAMES

ARMS = [JOINT_INDEX[f"{s}_{b}"] for s in ("left", "right") for b in ("collar", "shoulder", "elbow", "wrist")]


@pytest.fixture(scope="module")
def clip(sample_joints):
    """The first 4 s of the sample at 30 fps (resampled), and its HumanML3D import."""
    from controlmm.motion.container import resample

    joints = resample(sample_joints[:81].astype(np.float64), 20, 30)
    return joints, Motion.from_joints(joints, fps=30).joints


def _error(motion, reference, joints=slice(None)):
    assert motion.joints.shape == reference.shape
    return float(np.linalg.norm(motion.joints - reference, axis=-1)[:, joints].max())


@pytest.mark.parametrize(
    "names,units,insert,family,unit,tol",
    [
        (LAFAN1, 100.0, None, "lafan1", "cm", 0.01),
        (MIXAMO, 100.0, None, "mixamo", "cm", 0.01),
        (CMU, 1 / CMU_METRES_PER_UNIT, CMU_INSERT, "cmu", "cmu", 0.04),  # spine2: CMU has 2 spine joints
        (None, 1.0, None, "smpl", "m", 0.01),
    ],
)
def test_bvh_naming_families_are_detected(tmp_path, clip, names, units, insert, family, unit, tol):
    joints, reference = clip
    path = tmp_path / f"{family}.bvh"
    write_bvh(path, joints, 30, names=names, units_per_metre=units, insert=insert)
    if names is None:  # this project's own SMPL-22 BVH in metres loads as it is (30 fps, not processed)
        assert load_motion(path).fps == pytest.approx(30)
        motion = load_motion(path, units="m")
    else:
        motion = load_motion(path)
    info = motion.metadata["import"]
    assert (info["skeleton"], info["units"], info["up"], info["source_fps"]) == (family, unit, "y", 30.0)
    assert motion.fps == 20 and motion.features is not None
    # The BVH's rigid bones fit the resampled joints to a few mm; CMU's SMPL spine2 is the midpoint of its
    # two spine joints, which tilts the chest a little.
    assert _error(motion, reference) < tol
    assert 0.9 < info["size_vs_reference"] < 1.1


def test_shoulder_joints_on_the_centre_line_give_collars_at_mid_clavicle(tmp_path, clip):
    """Some CMU conversions start LeftShoulder at the chest's centre: the collars must stay apart."""
    joints, reference = clip
    central = joints.copy()
    spine3, neck = central[:, JOINT_INDEX["spine3"]], central[:, JOINT_INDEX["neck"]]
    for side in ("left", "right"):
        central[:, JOINT_INDEX[f"{side}_collar"]] = spine3 + 0.6 * (neck - spine3)
    write_bvh(tmp_path / "c.bvh", central, 30, names=CMU, units_per_metre=100, insert=CMU_INSERT)
    motion = load_motion(tmp_path / "c.bvh")
    collars = motion.joints[:, JOINT_INDEX["left_collar"]] - motion.joints[:, JOINT_INDEX["right_collar"]]
    assert np.linalg.norm(collars, axis=-1).min() > 0.1
    legs = [j for j in range(22) if j not in ARMS]
    assert _error(motion, reference, legs) < 0.1


def test_mapping_file_maps_any_skeleton_and_missing_joints_are_named(tmp_path, clip, capsys):
    joints, reference = clip
    bvh = tmp_path / "custom.bvh"
    write_bvh(bvh, joints, 30, names=CUSTOM, units_per_metre=100)
    err = one_line_error(
        capsys, ["convert", str(bvh), str(tmp_path / "o.npz")], "--skeleton-map", "J_PELVIS", "mapping file"
    )
    assert "Traceback" not in err and not (tmp_path / "o.npz").exists()
    mapping = tmp_path / "map.json"
    mapping.write_text(json.dumps({"joints": CUSTOM}))
    assert run_cli(["convert", str(bvh), str(tmp_path / "o.npz"), "--skeleton-map", str(mapping)]) == 0
    assert _error(load_motion(tmp_path / "o.npz"), reference) < 0.01
    # A weighted joint and a partial LAFAN1 skeleton: the error lists what is missing.
    partial = {k: v for k, v in LAFAN1.items() if k != "left_foot"}
    write_bvh(tmp_path / "p.bvh", joints, 30, names={**partial, "left_foot": "L_Toes"}, units_per_metre=100)
    one_line_error(capsys, ["plot", str(tmp_path / "p.bvh"), "--out", str(tmp_path / "p.png")], "LeftToe")
    weighted = dict(LAFAN1, left_foot={"L_Toes": 1.0})
    mapping.write_text(json.dumps({"joints": weighted}))
    assert _error(load_motion(tmp_path / "p.bvh", mapping=mapping), reference) < 0.01
    mapping.write_text(json.dumps({"joints": {"pelvis": "Hips"}}))
    with pytest.raises(ControlMMError, match="no source joint for left_hip"):
        load_motion(tmp_path / "p.bvh", mapping=mapping)


@pytest.mark.parametrize("layout", ["smplh", "smplx", "smplh-depth-first"])
@pytest.mark.parametrize("suffix", [".npy", ".npz", ".pt"])
def test_smpl_family_arrays_z_up(tmp_path, clip, layout, suffix):
    joints, reference = clip
    arr = {"smplh": smplh, "smplx": smplx, "smplh-depth-first": smplh_depth_first}[layout](joints)
    arr = z_up(arr).astype(np.float32)
    path = tmp_path / f"clip{suffix}"
    if suffix == ".npy":
        np.save(path, arr)
        motion = load_motion(path, fps=30)
    elif suffix == ".npz":  # AMASS-style rate key
        np.savez(path, joints=arr, mocap_framerate=np.float64(30))
        motion = load_motion(path)
    else:
        torch.save({"joints": torch.from_numpy(arr), "fps": 30}, path)
        motion = load_motion(path)
    info = motion.metadata["import"]
    assert info["skeleton"] == layout and info["up"] == "z" and info["up_detected"]
    assert _error(motion, reference) < 1e-3
    declared = load_motion(path, fps=30, up="z") if suffix == ".npy" else load_motion(path, up="z")
    assert not declared.metadata["import"]["up_detected"] and _error(declared, reference) < 1e-3


def test_named_joint_arrays_and_mapping_with_joint_names(tmp_path, clip):
    joints, reference = clip
    order = list(JOINT_NAMES)[::-1]  # columns in another order, named by the file
    arr = joints[:, [JOINT_NAMES.index(n) for n in order]]
    np.savez(tmp_path / "named.npz", positions=arr, joint_names=np.array([LAFAN1[n] for n in order]), fps=30)
    assert load_motion(tmp_path / "named.npz").metadata["import"]["skeleton"] == "lafan1"
    assert _error(load_motion(tmp_path / "named.npz"), reference) < 1e-3
    np.save(tmp_path / "bare.npy", arr * 100)  # centimetres, columns named by the mapping
    mapping = tmp_path / "map.json"
    mapping.write_text(json.dumps({"joints": CUSTOM, "joint_names": [CUSTOM[n] for n in order], "fps": 30}))
    with pytest.raises(ControlMMError, match="centimetres; pass --units cm"):
        load_motion(tmp_path / "bare.npy", mapping=mapping)
    assert _error(load_motion(tmp_path / "bare.npy", mapping=mapping, units="cm"), reference) < 1e-3


def test_bad_arrays_are_one_line_exit_2(tmp_path, clip, capsys):
    joints, _ = clip
    out = str(tmp_path / "o.npz")
    np.save(tmp_path / "odd.npy", np.zeros((30, 31, 3)))
    one_line_error(
        capsys, ["convert", str(tmp_path / "odd.npy"), out, "--source-fps", "30"], "31 joints", "52"
    )
    nan = smplh(joints)
    nan[12, 30, 1] = np.nan  # a hand joint: not used, fine
    np.save(tmp_path / "hand_nan.npy", nan)
    assert run_cli(["convert", str(tmp_path / "hand_nan.npy"), out, "--source-fps", "30"]) == 0
    nan[12, 4, 1] = np.nan  # the left knee
    np.save(tmp_path / "nan.npy", nan)
    argv = ["retarget", str(tmp_path / "nan.npy"), "--out", str(tmp_path / "r"), "--source-fps", "30"]
    one_line_error(capsys, argv, "frame 12")
    np.save(tmp_path / "cm.npy", z_up(smplh(joints)) * 100)
    one_line_error(capsys, ["convert", str(tmp_path / "cm.npy"), out, "--force"], "centimetres", "--units cm")
    assert (
        run_cli(["convert", str(tmp_path / "cm.npy"), out, "--force", "--units", "cm", "--source-fps", "30"])
        == 0
    )
    np.save(tmp_path / "h.npy", smplh(joints))
    one_line_error(capsys, ["convert", str(tmp_path / "h.npy"), out, "--force"], "--source-fps")
    one_line_error(capsys, ["convert", str(tmp_path / "h.npy"), out, "--up", "x"], "invalid choice")
    mirrored = smplh(joints) * [-1, 1, 1]  # a mirror image: left is right
    np.save(tmp_path / "mirror.npy", mirrored)
    one_line_error(
        capsys, ["convert", str(tmp_path / "mirror.npy"), out, "--force", "--source-fps", "30"], "mirrored"
    )


def test_intermimic_layout_and_real_clips_of_the_demo_package():
    """The real OMOMO clips of holosoma-retargeting's demo data, when that package is installed."""
    import importlib.util
    from pathlib import Path

    spec = importlib.util.find_spec("holosoma_retargeting")
    if spec is None or not spec.submodule_search_locations:
        pytest.skip("holosoma-retargeting (the mocap-demo extra) is not installed")
    folder = Path(list(spec.submodule_search_locations)[0]) / "demo_data" / "OMOMO_new"
    clips = sorted(folder.glob("*.pt"))
    assert clips
    motion = load_motion(clips[0])
    info = motion.metadata["import"]
    assert info["skeleton"] == "intermimic (smplh-depth-first)" and info["up"] == "z"
    assert 1.2 < info["joint_height_m"] < 1.8 and motion.num_frames > 100
