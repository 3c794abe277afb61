"""Runs GMR on LAFAN1 BVH files, headless, inside GMR's own environment.

Not imported by the project: ``benchmarks/retarget_peers.py`` runs it with the Python of a
virtual environment that holds GMR (github.com/YanjieZe/GMR, installed from its repository)::

    .venv-gmr/bin/python benchmarks/peers/gmr_driver.py --output peer.npz a.bvh b.bvh

Each BVH (LAFAN1 names, centimetres, Y up, LAFAN1's bone frames: ``lafan1_bvh.py`` writes
them) is loaded with GMR's LAFAN1 loader and retargeted to the G1 frame by frame by a fresh
``GeneralMotionRetargeting("bvh", "unitree_g1")`` given the human height that loader returns,
as GMR's own BVH script does, without its viewer. The output npz holds, per file stem,
``<stem>`` qpos (T, 36; MuJoCo order, root quaternion wxyz as GMR returns it) and
``<stem>__seconds`` (wall time of the per-frame retargeting, once the file and the robot are
loaded), plus ``names``, ``version`` (GMR's git commit when its checkout is a repository) and
``mujoco`` (the MuJoCo version it ran with).
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import time
from pathlib import Path

import general_motion_retargeting
import mujoco
import numpy as np
from general_motion_retargeting import GeneralMotionRetargeting
from general_motion_retargeting.utils.lafan1 import load_lafan1_file

ROBOT = "unitree_g1"


def retarget_file(bvh: Path, robot: str = ROBOT) -> tuple[np.ndarray, float]:
    """GMR's qpos (T, nq) for a LAFAN1 BVH and the seconds its per-frame retargeting took."""
    frames, height = load_lafan1_file(str(bvh))
    gmr = GeneralMotionRetargeting(src_human="bvh", tgt_robot=robot, actual_human_height=height)
    start = time.perf_counter()
    qpos = np.stack([gmr.retarget(frame) for frame in frames])
    return qpos, time.perf_counter() - start


def version() -> str:
    """GMR's git commit (short), or ``unknown`` when its checkout is not a git repository."""
    root = Path(general_motion_retargeting.__file__).resolve().parents[1]
    done = subprocess.run(["git", "-C", str(root), "rev-parse", "--short", "HEAD"], capture_output=True)
    return done.stdout.decode().strip() or "unknown"


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("bvh", type=Path, nargs="+", help="LAFAN1 BVH files")
    p.add_argument("--output", type=Path, required=True, help="npz of qpos and seconds per file stem")
    p.add_argument("--robot", default=ROBOT, help=f"GMR's robot name (default {ROBOT})")
    args = p.parse_args()
    out: dict[str, np.ndarray] = {}
    for path in args.bvh:
        qpos, seconds = retarget_file(path, args.robot)
        out[path.stem], out[f"{path.stem}__seconds"] = qpos, np.array(seconds)
    out["names"] = np.array([path.stem for path in args.bvh])
    out["version"] = np.array(version())
    out["mujoco"] = np.array(mujoco.__version__)
    np.savez(args.output, **out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
