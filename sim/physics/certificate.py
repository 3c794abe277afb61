"""The replayable certificate of a physics run, and its replay.

Three files (written atomically, each on its own):

* ``physics_model.xml``: the robot + scene + actuators as one self-contained MJCF file saved by
  MuJoCo (meshes inline; :mod:`sim.physics.model`). The run was simulated on this very file.
* ``physics.npz``: ``qpos`` (S+1, nq) and ``qvel`` (S+1, nv) at every simulation step (row 0 is
  the initial state), ``ctrl`` (S, nu) the control input of each ``mj_step``, ``timestep`` (s),
  ``fps`` (the trajectory's rate), ``frame_steps`` (T,) the step of each trajectory frame (-1
  after an early stop), ``passed``, ``joint_names``, ``actuator_names``; with moving obstacles
  also ``mocap_pos`` (S, nmocap, 3) and ``mocap_quat`` (S, nmocap, 4, wxyz) set before each step.
* ``robot_physics.csv``: the simulated motion at 50 fps in the Unitree LAFAN1-G1 / BeyondMimic
  row layout (no header; root x, y, z, root quaternion qx, qy, qz, qw, then the joint
  positions in MJCF order), 17 significant digits: written by
  :func:`retarget.exports.write_lafan1_csv`, read back by :func:`retarget.exports.read_export`.

Replay (:func:`replay_certificate`)::

    model = mujoco.MjModel.from_xml_path("physics_model.xml")
    data = mujoco.MjData(model)
    data.qpos[:], data.qvel[:] = qpos[0], qvel[0]
    for s in range(len(ctrl)):
        data.ctrl[:] = ctrl[s]          # (and mocap_pos/mocap_quat[s] when present)
        mujoco.mj_step(model, data)     # data.qpos == qpos[s + 1]
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import mujoco
import numpy as np

from controlmm.atomic import atomic_path, write_text
from controlmm.errors import ControlMMError, InputFileError
from retarget.exports import write_lafan1_csv
from sim.physics.result import PhysicsResult

MODEL_FILE = "physics_model.xml"
STATES_FILE = "physics.npz"
CSV_FILE = "robot_physics.csv"
CERTIFICATE_FILES = (STATES_FILE, MODEL_FILE, CSV_FILE)
CSV_FPS = 50.0
"""Rate of ``robot_physics.csv`` (BeyondMimic's training rate)."""


def certificate_paths(directory: str | Path) -> dict[str, Path]:
    """The three certificate files in ``directory``."""
    directory = Path(directory)
    return {name: directory / name for name in CERTIFICATE_FILES}


def resample_states(qpos: np.ndarray, timestep: float, fps: float, root_adr: int = 0) -> np.ndarray:
    """``qpos`` at every simulation step -> rows at ``fps``: the simulated states themselves when
    ``1 / fps`` is a whole number of steps (0.02 s = 10 steps of 0.002 s), else linear between the
    two nearest steps (root quaternion normalised)."""
    duration = (qpos.shape[0] - 1) * timestep
    times = np.arange(int(np.floor(duration * fps + 1e-9)) + 1) / fps
    x = np.minimum(times / timestep, qpos.shape[0] - 1)
    whole = np.round(x)
    x = np.where(np.abs(x - whole) < 1e-6, whole, x)  # on a step: that step's state, bit for bit
    i0 = np.floor(x).astype(np.int64)
    i1 = np.minimum(i0 + 1, qpos.shape[0] - 1)
    a = x - i0
    out = qpos[i0].copy()
    between = a > 0
    if between.any():
        w = a[between, None]
        mixed = (1.0 - w) * qpos[i0[between]] + w * qpos[i1[between]]
        quat = mixed[:, root_adr + 3 : root_adr + 7]
        mixed[:, root_adr + 3 : root_adr + 7] = quat / np.linalg.norm(quat, axis=1, keepdims=True)
        out[between] = mixed
    return out


def save_certificate(result: PhysicsResult, directory: str | Path) -> dict[str, Path]:
    """Write ``physics_model.xml``, ``physics.npz`` and ``robot_physics.csv`` into ``directory``."""
    if result.root_qpos_adr != 0:
        raise ControlMMError("the LAFAN1/BeyondMimic CSV layout needs the robot's free joint first in qpos")
    paths = certificate_paths(directory)
    frame_steps = np.round(np.arange(result.num_frames) / result.fps / result.timestep).astype(np.int64)
    frame_steps[frame_steps > result.steps] = -1
    arrays: dict[str, Any] = {
        "qpos": result.qpos,
        "qvel": result.qvel,
        "ctrl": result.ctrl,
        "timestep": np.float64(result.timestep),
        "fps": np.float64(result.fps),
        "frame_steps": frame_steps,
        "passed": np.bool_(result.passed),
        "joint_names": np.array(result.joints),
        "actuator_names": np.array(result.actuators),
    }
    if result.mocap_pos is not None and result.mocap_quat is not None:
        arrays["mocap_pos"] = result.mocap_pos
        arrays["mocap_quat"] = result.mocap_quat
    write_text(paths[MODEL_FILE], result.model_xml)
    with atomic_path(paths[STATES_FILE]) as tmp:
        np.savez_compressed(tmp, **arrays)
    write_lafan1_csv(resample_states(result.qpos, result.timestep, CSV_FPS), paths[CSV_FILE])
    return paths


def replay_certificate(model_path: str | Path, states_path: str | Path) -> np.ndarray:
    """Re-simulate a certificate: load the MJCF, set the first state, apply ``ctrl`` step by step.

    Returns the replayed ``qpos`` (S+1, nq); it equals the certificate's ``qpos`` (same MuJoCo).
    """
    try:
        model = mujoco.MjModel.from_xml_path(str(model_path))
    except ValueError as exc:
        raise InputFileError(f"cannot load '{model_path}': {' '.join(str(exc).split())}") from None
    try:
        with np.load(states_path, allow_pickle=False) as npz:
            qpos, qvel, ctrl = npz["qpos"], npz["qvel"], npz["ctrl"]
            mocap_pos = npz["mocap_pos"] if "mocap_pos" in npz else None
            mocap_quat = npz["mocap_quat"] if "mocap_quat" in npz else None
    except (OSError, KeyError, ValueError) as exc:
        raise InputFileError(f"'{states_path}' is not a physics certificate: {exc}") from None
    if qpos.shape[1] != model.nq or ctrl.shape[1] != model.nu:
        raise InputFileError(
            f"'{states_path}' has nq={qpos.shape[1]}, nu={ctrl.shape[1]}; '{model_path}' has "
            f"nq={model.nq}, nu={model.nu}"
        )
    data = mujoco.MjData(model)
    data.qpos[:], data.qvel[:] = qpos[0], qvel[0]
    out = np.empty((ctrl.shape[0] + 1, model.nq))
    out[0] = data.qpos
    for s in range(ctrl.shape[0]):
        data.ctrl[:] = ctrl[s]
        if mocap_pos is not None and mocap_quat is not None:
            data.mocap_pos[:] = mocap_pos[s]
            data.mocap_quat[:] = mocap_quat[s]
        mujoco.mj_step(model, data)
        out[s + 1] = data.qpos
    return out
