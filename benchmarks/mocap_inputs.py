"""Real mocap clips through every input path of ``controlmm.motion.load_motion``, then to the G1.

    pip install --no-deps holosoma-retargeting        # or: pip install -e ".[mocap-demo]"
    python benchmarks/mocap_inputs.py                  # every clip, every path, G1 retargeting
    python benchmarks/mocap_inputs.py --clips 2 --no-retarget

The clips are the real mocap shipped in the demo data of the PyPI package ``holosoma-retargeting``
(read from the installed package, never copied here): OMOMO subjects as InterMimic ``.pt`` tensors
(52 SMPL-H joints, depth-first order, Z up, 30 fps) and climbing sequences as ``.npy`` position
arrays (53 joints named in the package's ``config_types/data_type.py``, Z up, 120 fps: the package's
own loader keeps every 4th frame and calls it 30 fps).

Each clip is imported from its own file (the reference), then its 22 SMPL joints (and its real hand
joints where it has them) are written in every other input format, at the source rate, in the
source's axes, and imported again:

- ``smplh.npy`` / ``smplh.npz`` / ``smplh.pt``: SMPL-H body-first (52), Z up (rate: flag / key / key);
- ``smplx.npz``: SMPL-X (55: jaw and eyes placed from the head), Z up;
- ``lafan1.bvh`` (cm), ``mixamo.bvh`` (cm, ``mixamorig:``), ``cmu.bvh`` (CMU units, ``LHipJoint``,
  ``LowerBack``, ``Neck1``), ``smpl.bvh`` (the depth-first SMPL names, m), Y up as BVH is;
- ``custom.bvh`` + ``custom_map.json``: names no family knows, through a mapping file.

Prints one row per clip and path: the skeleton, up axis and unit that were detected, and the largest
and mean joint distance (mm) to the reference import after HumanML3D processing; then, per clip, the
G1 retargeting of the reference import (keypoint error, time).
"""

from __future__ import annotations

import argparse
import ast
import importlib.util
import json
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import torch

ROOT = Path(__file__).resolve().parents[1]
# This folder holds benchmarks/retarget.py, which would shadow the retarget package.
sys.path[:] = [str(ROOT)] + [p for p in sys.path if Path(p or ".").resolve() != ROOT / "benchmarks"]

from controlmm.motion import Motion, load_motion  # noqa: E402
from controlmm.motion.bvh import write_bvh  # noqa: E402
from controlmm.motion.formats import detect_family  # noqa: E402
from controlmm.motion.formats.arrays import position_array, read_arrays  # noqa: E402
from controlmm.motion.formats.smpl import INTERMIMIC_FPS, smpl_body_joints  # noqa: E402
from controlmm.motion.skeleton import JOINT_INDEX, JOINT_NAMES  # noqa: E402
from retarget import retarget_motion  # noqa: E402

CLIMB_FPS = 120.0
"""The climbing sequences' rate: holosoma's loader keeps every 4th frame and treats them as 30 fps."""

SIDES = (("left", "Left"), ("right", "Right"))


def demo_data() -> Path | None:
    """The installed package's ``demo_data`` folder (the package is never imported), or None."""
    spec = importlib.util.find_spec("holosoma_retargeting")
    if spec is None or not spec.submodule_search_locations:
        return None
    folder = Path(list(spec.submodule_search_locations)[0]) / "demo_data"
    return folder if folder.is_dir() else None


def climbing_joint_names(package: Path) -> list[str]:
    """The 53 joint names of the climbing arrays, read from the package's data-type module (as data)."""
    tree = ast.parse((package / "config_types" / "data_type.py").read_text())
    for node in tree.body:
        if isinstance(node, ast.Assign) and any(
            getattr(t, "id", "") == "MOCAP_DEMO_JOINTS" for t in node.targets
        ):
            return list(ast.literal_eval(node.value))
    raise SystemExit("holosoma-retargeting: no MOCAP_DEMO_JOINTS in config_types/data_type.py")


def hips_style(toe: str, spines: tuple[str, str, str], prefix: str = "") -> dict[str, str]:
    """SMPL joint -> name in the LAFAN1 / Mixamo / CMU style."""
    names = {"pelvis": "Hips", "neck": "Neck", "head": "Head"}
    names.update(zip(("spine1", "spine2", "spine3"), spines, strict=True))
    for side, word in SIDES:
        for smpl, theirs in (
            ("hip", "UpLeg"),
            ("knee", "Leg"),
            ("ankle", "Foot"),
            ("foot", toe),
            ("collar", "Shoulder"),
            ("shoulder", "Arm"),
            ("elbow", "ForeArm"),
            ("wrist", "Hand"),
        ):
            names[f"{side}_{smpl}"] = f"{word}{theirs}"
    return {k: prefix + v for k, v in names.items()}


PHC = {
    "pelvis": "Pelvis",
    "spine1": "Torso",
    "spine2": "Spine",
    "spine3": "Chest",
    "neck": "Neck",
    "head": "Head",
}
for _side, _s in (("left", "L"), ("right", "R")):
    for _smpl, _theirs in (
        ("hip", "Hip"),
        ("knee", "Knee"),
        ("ankle", "Ankle"),
        ("foot", "Toe"),
        ("collar", "Thorax"),
        ("shoulder", "Shoulder"),
        ("elbow", "Elbow"),
        ("wrist", "Wrist"),
    ):
        PHC[f"{_side}_{_smpl}"] = f"{_s}_{_theirs}"

BVH_PATHS: dict[str, tuple[dict[str, str], float, dict[str, str]]] = {
    "lafan1.bvh": (hips_style("Toe", ("Spine", "Spine1", "Spine2")), 100.0, {}),
    "mixamo.bvh": (hips_style("ToeBase", ("Spine", "Spine1", "Spine2"), "mixamorig:"), 100.0, {}),
    "cmu.bvh": (
        hips_style("ToeBase", ("Spine", "SpineMid", "Spine1")),
        0.45 / 0.0254,
        {"LowerBack": "spine1", "LHipJoint": "left_hip", "RHipJoint": "right_hip", "Neck1": "head"},
    ),
    "smpl.bvh": (PHC, 1.0, {}),
    "custom.bvh": ({k: f"Bone_{i:02d}" for i, k in enumerate(JOINT_NAMES)}, 100.0, {}),
}


def z_up_to_y_up(p: np.ndarray) -> np.ndarray:
    """BVH files are Y up: the proper rotation (x, y, z) -> (y, z, x)."""
    return p[..., [1, 2, 0]]


def face_joints(body: np.ndarray) -> np.ndarray:
    """Jaw and eyes (T, 3, 3) placed from the head and neck (SMPL-X's joints 22-24), Z-up input."""
    head, neck = body[:, JOINT_INDEX["head"]], body[:, JOINT_INDEX["neck"]]
    up = head - neck
    left = body[:, JOINT_INDEX["left_collar"]] - body[:, JOINT_INDEX["right_collar"]]
    left /= np.linalg.norm(left, axis=-1, keepdims=True)
    fwd = np.cross(left, up)
    fwd /= np.linalg.norm(fwd, axis=-1, keepdims=True)
    return np.stack(
        [
            head - 0.3 * up + 0.06 * fwd,
            head + 0.4 * up + 0.08 * fwd + 0.03 * left,
            head + 0.4 * up + 0.08 * fwd - 0.03 * left,
        ],
        axis=1,
    )


def hand_joints(body: np.ndarray, side: str) -> np.ndarray:
    """15 finger joints (T, 15, 3) beyond the wrist along the forearm (for clips without hands)."""
    w, e = body[:, JOINT_INDEX[f"{side}_wrist"]], body[:, JOINT_INDEX[f"{side}_elbow"]]
    along = (w - e) / np.linalg.norm(w - e, axis=-1, keepdims=True)
    return w[:, None] + along[:, None] * np.linspace(0.02, 0.09, 15)[None, :, None]


def write_paths(body: np.ndarray, hands: np.ndarray, fps: float, folder: Path) -> dict[str, dict]:
    """Write the clip's SMPL-22 joints (T, 22, 3; Z up, metres) + hands (T, 30, 3) in every format;
    return ``{file name: load_motion keyword arguments}``."""
    smplh = np.concatenate([body, hands], axis=1).astype(np.float32)
    smplx = np.concatenate([body, face_joints(body), hands], axis=1).astype(np.float32)
    np.save(folder / "smplh.npy", smplh)
    np.savez(folder / "smplh.npz", joints=smplh, mocap_framerate=np.float64(fps))
    torch.save({"joints": torch.from_numpy(smplh), "fps": float(fps)}, folder / "smplh.pt")
    np.savez(folder / "smplx.npz", joints=smplx, fps=np.float64(fps))
    paths: dict[str, dict] = {"smplh.npy": {"fps": fps}, "smplh.npz": {}, "smplh.pt": {}, "smplx.npz": {}}
    y_up = z_up_to_y_up(body)
    for name, (names, units, insert) in BVH_PATHS.items():
        write_bvh(folder / name, y_up, fps, names=names, units_per_metre=units, insert=insert)
        paths[name] = {}
    mapping = {"joints": BVH_PATHS["custom.bvh"][0]}
    (folder / "custom_map.json").write_text(json.dumps(mapping))
    paths["custom.bvh"] = {"mapping": str(folder / "custom_map.json")}
    return paths


def clips(data: Path, count: int | None) -> list[tuple[str, Path, np.ndarray, np.ndarray, float]]:
    """(name, file, SMPL-22 joints (T, 22, 3), hand joints (T, 30, 3), fps) of each real clip, Z up."""
    out = []
    for path in sorted((data / "OMOMO_new").glob("*.pt")):
        arr = position_array(read_arrays(path, ".pt"), str(path))
        body, layout = smpl_body_joints(arr.positions, str(path))
        assert layout == "smplh-depth-first"
        pos = arr.positions  # depth-first: the left hand's 15 joints at 18..32, the right's at 37..51
        out.append(
            (path.stem, path, body, np.concatenate([pos[:, 18:33], pos[:, 37:52]], axis=1), INTERMIMIC_FPS)
        )
    names = climbing_joint_names(data.parent)
    for path in sorted((data / "climb").glob("*/*.npy")):
        pos = np.load(path).astype(np.float64)
        family = detect_family(names, pos)
        assert family is not None
        body = family.apply(names, pos)
        hands = np.concatenate([hand_joints(body, "left"), hand_joints(body, "right")], axis=1)
        out.append((path.parent.name, path, body, hands, CLIMB_FPS))
    return out[:count] if count else out


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--clips", type=int, default=None, help="at most this many clips (default all 7)")
    parser.add_argument("--no-retarget", action="store_true", help="only the imports")
    parser.add_argument("--robot", default="g1")
    args = parser.parse_args(argv)
    data = demo_data()
    if data is None:
        print(
            "holosoma-retargeting is not installed: pip install --no-deps holosoma-retargeting",
            file=sys.stderr,
        )
        return 2
    torch.set_num_threads(1)
    rows, fits = [], []
    for name, path, body, hands, fps in clips(data, args.clips):
        t0 = time.perf_counter()
        if path.suffix == ".pt":
            reference = load_motion(path)
        else:  # the climbing arrays name no joints: the names go into an npz beside the clip
            with tempfile.TemporaryDirectory() as tmp:
                named = Path(tmp) / "named.npz"
                names = climbing_joint_names(data.parent)
                np.savez(named, joints=np.load(path), joint_names=np.array(names), fps=np.float64(fps))
                reference = load_motion(named)
        info = reference.metadata["import"]
        rows.append(
            (name, path.name, len(body), fps, reference.num_frames, info, 0.0, 0.0, time.perf_counter() - t0)
        )
        with tempfile.TemporaryDirectory() as tmp:
            for file, options in write_paths(body, hands, fps, Path(tmp)).items():
                t0 = time.perf_counter()
                motion = load_motion(Path(tmp) / file, **options)
                seconds = time.perf_counter() - t0
                dist = np.linalg.norm(motion.joints - reference.joints, axis=-1)
                rows.append(
                    (
                        name,
                        file,
                        len(body),
                        fps,
                        motion.num_frames,
                        motion.metadata["import"],
                        float(dist.max()),
                        float(dist.mean()),
                        seconds,
                    )
                )
        if not args.no_retarget:
            fits.append((name, reference, _retarget(reference, args.robot)))
    head = "| clip | input | source frames @ fps | frames @ 20 fps | skeleton | up | unit "
    print(head + "| max / mean vs reference (mm) | load s |")
    print("|---|---|---|---|---|---|---|---|---:|")
    for name, file, frames, fps, out, info, worst, mean, seconds in rows:
        skeleton = "mapping file" if str(info["skeleton"]).endswith(".json") else info["skeleton"]
        print(
            f"| {name} | {file} | {frames} @ {fps:g} | {out} | {skeleton} | {info['up']} "
            f"| {info['units']} | {worst * 1000:.1f} / {mean * 1000:.1f} | {seconds:.2f} |"
        )
    if fits:
        print()
        print(
            f"| clip | frames @ 20 fps | joint height (m) | {args.robot} keypoint error mean / max (mm) | s |"
        )
        print("|---|---|---|---|---:|")
        for name, motion, (errors, seconds) in fits:
            height = motion.metadata["import"]["joint_height_m"]
            print(f"| {name} | {motion.num_frames} | {height:.3f} | {errors} | {seconds:.1f} |")
    return 0


def _retarget(motion: Motion, robot: str) -> tuple[str, float]:
    t0 = time.perf_counter()
    traj = retarget_motion(motion, robot=robot, fps=50)
    seconds = time.perf_counter() - t0
    groups = traj.metrics.get("keypoint_error_mm", {})
    text = "; ".join(f"{g} {v['mean']:.0f} / {v['max']:.0f}" for g, v in groups.items())
    return text, seconds


if __name__ == "__main__":
    sys.exit(main())
