"""Runs holosoma-retargeting on SMPL-22 joint sequences, inside holosoma's own environment.

Not imported by the project: ``benchmarks/retarget_peers.py`` runs it with the Python of a
virtual environment that holds ``holosoma-retargeting`` (it needs mujoco <= 3.11)::

    .venv-holosoma/bin/python benchmarks/peers/holosoma_driver.py --input motions.npz --output peer.npz
    .venv-holosoma/bin/python benchmarks/peers/holosoma_driver.py --export-demo demo.npz

``--input``: an npz with ``names`` (M,) and per motion ``<name>`` (T, 22, 3) global joint
positions in metres, Z up (SMPL order), at 30 fps, and ``<name>__height`` (m). Each motion is
retargeted to the G1 by holosoma's own example script (``robot_only``, data format
``smplx``); the output npz holds ``<name>`` qpos (T, 36; root quaternion wxyz) and
``<name>__seconds`` (wall time of that run, loading included). ``--export-demo`` writes the
SMPL-22 joints (Z up, 30 fps) of the OMOMO clips holosoma ships and retargets them in their
own format (``smplh``), so both retargeters see the same real mocap.
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import holosoma_retargeting
import numpy as np

PACKAGE = Path(holosoma_retargeting.__file__).resolve().parent
SCRIPT = "examples/robot_retarget.py"

SMPL22_IN_SMPLH_DEMO = (
    "Pelvis", "L_Hip", "R_Hip", "Torso", "L_Knee", "R_Knee", "Spine", "L_Ankle", "R_Ankle", "Chest", "L_Toe",
    "R_Toe", "Neck", "L_Thorax", "R_Thorax", "Head", "L_Shoulder", "R_Shoulder", "L_Elbow", "R_Elbow",
    "L_Wrist", "R_Wrist",
)  # fmt: skip
"""holosoma's name (``SMPLH_DEMO_JOINTS``) of each SMPL-22 joint, in SMPL/HumanML3D order. Its OMOMO
clips store the 52 SMPL-H joints depth first (a leg, the other leg, the spine, an arm with its hand, the
other arm), not in SMPL's order: their first 22 rows are not the body joints."""


def _run(args: list[str], log: Path) -> float:
    start = time.perf_counter()
    with log.open("w") as out:
        subprocess.run([sys.executable, SCRIPT, *args], cwd=PACKAGE, check=True, stdout=out, stderr=out)
    return time.perf_counter() - start


def retarget_joints(joints: np.ndarray, height: float, name: str, work: Path) -> tuple[np.ndarray, float]:
    """holosoma's G1 qpos (T, 36) for SMPL-22 joints (T, 22, 3) Z up, and the seconds it took."""
    data, out = work / "in", work / "out"
    data.mkdir(parents=True, exist_ok=True)
    np.savez(data / f"{name}.npz", global_joint_positions=joints.astype(np.float64), height=float(height))
    args = ["--data_path", str(data), "--task-type", "robot_only", "--task-name", name]
    args += ["--data_format", "smplx", "--task-config.ground-range", "-10", "10", "--save_dir", str(out)]
    seconds = _run(args, work / f"{name}.log")
    with np.load(out / f"{name}.npz") as res:
        return np.asarray(res["qpos"]), seconds


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--input", type=Path)
    p.add_argument("--output", type=Path)
    p.add_argument(
        "--export-demo", type=Path, help="write holosoma's OMOMO clips (SMPL-22, Z up) and its qpos"
    )
    args = p.parse_args()
    out: dict[str, np.ndarray] = {}
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        if args.export_demo:
            # their loader and joint names, their environment
            from holosoma_retargeting.config_types.data_type import SMPLH_DEMO_JOINTS
            from holosoma_retargeting.src.utils import load_intermimic_data

            body = [SMPLH_DEMO_JOINTS.index(n) for n in SMPL22_IN_SMPLH_DEMO]

            demo = PACKAGE / "demo_data" / "OMOMO_new"
            names = sorted(f.stem for f in demo.glob("*.pt"))
            for name in names:
                joints, _ = load_intermimic_data(str(demo / f"{name}.pt"))
                out[name] = np.asarray(joints[:, body], dtype=np.float64)
                args_run = ["--data_path", str(demo), "--task-type", "robot_only", "--task-name", name]
                args_run += ["--data_format", "smplh", "--save_dir", str(work / "demo")]
                out[f"{name}__seconds"] = np.array(_run(args_run, work / f"{name}.log"))
                with np.load(work / "demo" / f"{name}.npz") as res:
                    out[f"{name}__qpos"] = np.asarray(res["qpos"])
            out["names"] = np.array(names)
            np.savez(args.export_demo, **out)
            return 0
        with np.load(args.input) as data:
            names = [str(n) for n in data["names"]]
            for name in names:
                qpos, seconds = retarget_joints(data[name], float(data[f"{name}__height"]), name, work)
                out[name], out[f"{name}__seconds"] = qpos, np.array(seconds)
        out["names"] = np.array(names)
        np.savez(args.output, **out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
