"""The retargeter's result and its files: Unitree/BeyondMimic CSV, NPZ and a JSON sidecar.

``RobotTrajectory.save("out/walk")`` writes

* ``walk.csv``: one row per frame, no header, comma-separated: root position x, y, z (m),
  root quaternion **qx, qy, qz, qw** (xyzw, the Unitree LAFAN1-G1 / BeyondMimic order), then
  the joint angles (rad) in MJCF (qpos) order. Numbers are written with 17 significant
  digits, so reading them back gives the same floats (joint limits hold exactly).
* ``walk.npz``: ``fps`` (float), ``qpos`` (T, nq; MuJoCo order: xyz, quaternion **wxyz**,
  joints; for a robot file whose joints the retargeter changed as it read it, a floating base
  written as joints or the rods of closed chains, the file's own qpos, and the free-joint
  rows the CSV has as ``qpos_floating``: :mod:`retarget.file_layout`), ``qvel`` (T, nv;
  ``mj_differentiatePos`` central differences, free-joint angular velocity in the body frame
  as in MuJoCo; of ``qpos_floating`` where there is one, as the body arrays), ``joint_names``
  (nj,), ``body_names`` (B,),
  ``body_pos_w`` (T, B, 3), ``body_quat_w`` (T, B, 4, wxyz) from ``mj_kinematics``, plus
  ``stance`` (T, 2: left, right human stance flags), ``robot`` and ``meta`` (the sidecar JSON).
* ``walk.json``: robot, MJCF and mapping, source motion, scale and transform, fps, the CSV
  column names and quaternion orders, metrics, solver details.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import mujoco
import numpy as np

from controlmm.atomic import atomic_open, atomic_path, write_text
from controlmm.errors import ControlMMError, InputFileError
from controlmm.frames import HumanToWorld
from retarget.metrics import replay
from retarget.robot_model import RobotModel, load_robot

TRAJECTORY_FORMAT = "controlmm-robot-trajectory/1"
CSV_ROOT_COLUMNS = ("root_x", "root_y", "root_z", "root_qx", "root_qy", "root_qz", "root_qw")


@dataclass
class RobotTrajectory:
    """A robot joint trajectory in MuJoCo order.

    Attributes:
        robot: packaged robot name (``g1``) or the mapping file that names the MJCF.
        fps: frames per second.
        qpos: (T, nq) free joint xyz + quaternion wxyz, then hinge angles in MJCF order.
        joint_names: names of the hinge joints (qpos[7:]).
        scale: human -> robot uniform scale used.
        transform: the :class:`HumanToWorld` that placed the human.
        metrics: quality figures (see :func:`retarget.metrics.trajectory_metrics`).
        stance: (T, 2) bool human stance flags (left, right) at this rate.
        source: information about the source motion (path, text, fps, frames).
        solver: solver details (iterations, time, cost).
    """

    robot: str
    fps: float
    qpos: np.ndarray
    joint_names: list[str]
    scale: float
    transform: HumanToWorld
    metrics: dict[str, Any] = field(default_factory=dict)
    stance: np.ndarray | None = None
    source: dict[str, Any] = field(default_factory=dict)
    solver: dict[str, Any] = field(default_factory=dict)
    model: RobotModel | None = field(default=None, repr=False, compare=False)
    """The RobotModel used (kept in memory; rebuilt from ``robot`` after loading)."""

    @property
    def num_frames(self) -> int:
        return int(self.qpos.shape[0])

    def robot_model(self) -> RobotModel:
        """The :class:`retarget.robot_model.RobotModel` of this trajectory."""
        if self.model is None:
            self.model = load_robot(self.robot)
        return self.model

    # -- derived arrays ------------------------------------------------------------------------
    def qvel(self) -> np.ndarray:
        """(T, nv) velocities by central differences with ``mj_differentiatePos``."""
        model = self.robot_model().model
        t = self.num_frames
        out = np.zeros((t, model.nv))
        if t < 2:
            return out
        dt = 1.0 / self.fps
        for i in range(t):
            a, b = max(i - 1, 0), min(i + 1, t - 1)
            mujoco.mj_differentiatePos(model, out[i], (b - a) * dt, self.qpos[a], self.qpos[b])
        return out

    def body_poses(self) -> tuple[list[str], np.ndarray, np.ndarray]:
        """Body names (without world), world positions (T, B, 3) and quaternions (T, B, 4, wxyz)."""
        robot = self.robot_model()
        rep = replay(robot.model, self.qpos)
        return robot.body_names, rep.xpos[:, 1:], rep.xquat[:, 1:]

    def csv_columns(self) -> list[str]:
        return list(CSV_ROOT_COLUMNS) + list(self.joint_names)

    def sidecar(self) -> dict[str, Any]:
        robot = self.robot_model()
        return {
            "format": TRAJECTORY_FORMAT,
            "robot": robot.name,
            "mjcf": str(robot.mjcf),
            "mapping": robot.mapping.source,
            "source_motion": self.source,
            "scale": self.scale,
            "transform": {
                "scale": self.transform.scale,
                "yaw": self.transform.yaw,
                "translation": list(self.transform.translation),
            },
            "fps": self.fps,
            "frames": self.num_frames,
            "nq": int(self.qpos.shape[1]),
            **self._file_nq(robot),
            "csv_columns": self.csv_columns(),
            "quaternion_order": {"csv": "xyzw", "npz_qpos": "wxyz", "npz_body_quat_w": "wxyz"},
            "joint_names": list(self.joint_names),
            "metrics": self.metrics,
            "solver": self.solver,
        }

    @staticmethod
    def _file_nq(robot: RobotModel) -> dict[str, Any]:
        """The sidecar's note of the file's own qpos where it differs (see the module)."""
        layout = robot.file_layout
        if layout is None:
            return {}
        return {
            "nq_mjcf": int(layout.model.nq),
            "npz_qpos": "the MJCF file's own qpos; qpos_floating: the free-joint rows of the CSV",
        }

    # -- files -----------------------------------------------------------------------------------
    def save(self, prefix: str | Path, csv: bool = True) -> dict[str, Path]:
        """Write ``prefix.csv`` (unless ``csv`` is False), ``prefix.npz`` and ``prefix.json`` atomically;
        return the paths. Other formats: :func:`retarget.exports.save_trajectory`."""
        prefix = Path(prefix)
        if prefix.suffix.lower() in (".csv", ".npz", ".json"):
            prefix = prefix.with_suffix("")
        exts = ("csv", "npz", "json") if csv else ("npz", "json")
        paths = {ext: prefix.with_name(prefix.name + "." + ext) for ext in exts}
        meta = self.sidecar()
        names, body_pos, body_quat = self.body_poses()
        if csv:
            rows = np.concatenate([self.qpos[:, 0:3], self.qpos[:, [4, 5, 6, 3]], self.qpos[:, 7:]], axis=1)
            with atomic_open(paths["csv"], "w", encoding="ascii", newline="") as fh:
                np.savetxt(fh, rows, fmt="%.17g", delimiter=",")
        layout = self.robot_model().file_layout
        arrays: dict[str, np.ndarray] = {
            "fps": np.asarray(self.fps, dtype=np.float64),  # a 0-d array, as np.savez stores a scalar
            "qpos": self.qpos if layout is None else layout.to_file(self.qpos),
            "qvel": self.qvel(),
            "joint_names": np.array(self.joint_names),
            "body_names": np.array(names),
            "body_pos_w": body_pos,
            "body_quat_w": body_quat,
            "robot": np.array(self.robot),
            "meta": np.array(json.dumps(meta)),
        }
        if layout is not None:
            arrays["qpos_floating"] = self.qpos
        if self.stance is not None:
            arrays["stance"] = self.stance
        with atomic_path(paths["npz"]) as tmp:
            # allow_pickle named so that no array of ``arrays`` can take the keyword.
            np.savez_compressed(tmp, allow_pickle=False, **arrays)
        write_text(paths["json"], json.dumps(meta, indent=2) + "\n")
        return paths

    @classmethod
    def load(cls, path: str | Path) -> RobotTrajectory:
        """Read a trajectory back from its ``.npz`` (the sidecar is stored inside it)."""
        path = Path(path)
        if path.suffix.lower() != ".npz":
            path = path.with_name(path.name + ".npz") if not path.suffix else path
        if not path.is_file():
            raise InputFileError(f"trajectory file '{path}' does not exist")
        try:
            with np.load(path, allow_pickle=False) as data:
                qpos = np.asarray(
                    data["qpos_floating" if "qpos_floating" in data else "qpos"], dtype=np.float64
                )
                fps = float(data["fps"])
                joint_names = [str(x) for x in data["joint_names"]]
                robot = str(data["robot"])
                meta = json.loads(str(data["meta"]))
                stance = np.asarray(data["stance"]) if "stance" in data else None
        except (KeyError, ValueError, OSError) as exc:
            raise InputFileError(f"'{path}' is not a controlmm robot trajectory: {exc}") from None
        if meta.get("format") != TRAJECTORY_FORMAT:
            raise InputFileError(
                f"'{path}' has format '{meta.get('format')}'; expected '{TRAJECTORY_FORMAT}'"
            )
        tr = meta.get("transform", {})
        transform = HumanToWorld(
            scale=float(tr.get("scale", meta.get("scale", 1.0))),
            yaw=float(tr.get("yaw", 0.0)),
            translation=tuple(tr.get("translation", (0.0, 0.0, 0.0))),
        )
        if qpos.ndim != 2 or qpos.shape[1] != 7 + len(joint_names):
            raise ControlMMError(
                f"'{path}': qpos has shape {qpos.shape}; expected (T, {7 + len(joint_names)})"
            )
        return cls(
            robot=robot,
            fps=fps,
            qpos=qpos,
            joint_names=joint_names,
            scale=float(meta.get("scale", 1.0)),
            transform=transform,
            metrics=meta.get("metrics", {}),
            stance=stance,
            source=meta.get("source_motion", {}),
            solver=meta.get("solver", {}),
        )
