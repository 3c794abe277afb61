"""Figures that compare retargeters on equal terms (ours, holosoma-retargeting, GMR, ...).

Every figure reads a qpos trajectory through MuJoCo and the human motion it came from, so
trajectories written by other retargeters are measured exactly like ours:

* :func:`similarity_fit`: the robot's keypoints (the mapping's points for pelvis, knees,
  ankles, elbows, wrists) against the human's joints after **one** similarity transform
  (scale, rotation, translation; Umeyama's least squares over all frames and keypoints):
  how closely the motion follows the human, whatever scale and placement each retargeter
  chose.
* :func:`stance_foot_speed`: the mean horizontal speed of each foot body between two frames
  in which the human's foot is in contact (:func:`retarget.stance.detect_contacts`): a
  planted foot should not move. A foot that rolls over its toe or heel moves its body
  while the sole stays put, so
* :func:`stance_sole_speed`: the same for the foot's slowest sole point (the collision
  points it stands on): how fast the part of the foot on the floor slides.
* :func:`joint_jerk_rms`: the RMS of the joints' third differences.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from controlmm.frames import HumanToWorld
from controlmm.motion.skeleton import JOINT_INDEX
from retarget.metrics import foot_steps, replay, replay_keypoints
from retarget.robot_model import RobotModel
from retarget.stance import detect_contacts, detect_stance

FIT_JOINTS = (
    "pelvis",
    "left_knee",
    "right_knee",
    "left_ankle",
    "right_ankle",
    "left_elbow",
    "right_elbow",
    "left_wrist",
    "right_wrist",
)
"""The human joints of the fit (those a robot maps: a legs-only robot uses the first five)."""


@dataclass(frozen=True)
class Fit:
    """A similarity-aligned fit: ``mean`` and ``p95`` distance (m), ``per_joint`` mean (m),
    the similarity's ``scale`` (robot metres per human metre) and the ``joints`` used."""

    mean: float
    p95: float
    per_joint: dict[str, float]
    scale: float
    joints: tuple[str, ...]


def resample_human(human: np.ndarray, human_fps: float, frames: int, fps: float) -> np.ndarray:
    """HumanML3D joints (T_h, 22, 3) linearly resampled to ``frames`` frames at ``fps``."""
    human = np.asarray(human, dtype=np.float64)
    times = np.arange(frames) / fps
    src = np.arange(len(human)) / human_fps
    flat = human.reshape(len(human), -1)
    out = np.stack([np.interp(times, src, flat[:, c]) for c in range(flat.shape[1])], axis=-1)
    return out.reshape(frames, *human.shape[1:])


def umeyama(src: np.ndarray, dst: np.ndarray) -> tuple[float, np.ndarray, np.ndarray]:
    """The similarity (scale, rotation (3, 3), translation (3,)) taking points ``src`` (N, 3)
    closest to ``dst`` (N, 3) in least squares: ``dst ~ scale * R @ src + t`` (Umeyama 1991)."""
    mu_s, mu_d = src.mean(axis=0), dst.mean(axis=0)
    s, d = src - mu_s, dst - mu_d
    u, sig, vt = np.linalg.svd(d.T @ s / len(src))
    sign = np.eye(3)
    if np.linalg.det(u) * np.linalg.det(vt) < 0:
        sign[2, 2] = -1.0
    rot = u @ sign @ vt
    scale = float(np.sum(sig * np.diag(sign)) / max(float(s.var(axis=0).sum()), 1e-12))
    return scale, rot, mu_d - scale * rot @ mu_s


def robot_keypoints(robot: RobotModel, qpos: np.ndarray) -> np.ndarray:
    """(T, K) keypoint world positions (T, K, 3) of ``qpos`` (T, nq), through MuJoCo."""
    return replay_keypoints(robot, replay(robot.model, qpos))


def similarity_fit(
    robot: RobotModel,
    qpos: np.ndarray,
    fps: float,
    human: np.ndarray,
    human_fps: float,
    joints: tuple[str, ...] = FIT_JOINTS,
) -> Fit:
    """The robot's keypoints against the human's joints after one similarity (see the module).

    Args:
        robot: whose mapping names the keypoints (joints it does not map are left out).
        qpos: (T, nq) at ``fps``; human: HumanML3D joints (T_h, 22, 3), metres, Y up, at ``human_fps``.
    """
    names = tuple(j for j in joints if robot.has_keypoint(j))
    kp = robot_keypoints(robot, qpos)[:, [robot.keypoint_index(j) for j in names]]
    world = HumanToWorld(scale=1.0).to_world(resample_human(human, human_fps, len(qpos), fps))
    ref = np.asarray(world)[:, [JOINT_INDEX[j] for j in names]]
    scale, rot, t = umeyama(ref.reshape(-1, 3), kp.reshape(-1, 3))
    aligned = scale * ref @ rot.T + t
    err = np.linalg.norm(aligned - kp, axis=-1)  # (T, J)
    return Fit(
        mean=float(err.mean()),
        p95=float(np.percentile(err, 95)),
        per_joint={j: float(e) for j, e in zip(names, err.mean(axis=0), strict=True)},
        scale=scale,
        joints=names,
    )


def human_contacts(
    human: np.ndarray, human_fps: float, frames: int, fps: float, flat: bool = False
) -> np.ndarray:
    """(frames, 2) the human's left / right foot contact at the trajectory's frames (nearest);
    ``flat``: only its flat stance (:func:`retarget.stance.detect_stance`: heel and toe down
    and still), without the heel strikes and toe-offs around it."""
    human = np.asarray(human, dtype=np.float64)
    near = np.clip(np.rint(np.arange(frames) / fps * human_fps).astype(int), 0, len(human) - 1)
    if flat:
        return np.stack([detect_stance(human, human_fps, side)[near] for side in ("left", "right")], axis=1)
    return np.stack([detect_contacts(human, human_fps, side)[0][near] for side in ("left", "right")], axis=1)


def stance_foot_speed(
    robot: RobotModel,
    qpos: np.ndarray,
    fps: float,
    human: np.ndarray,
    human_fps: float,
    flat: bool = False,
) -> float:
    """Mean horizontal speed (m/s) of the foot bodies between consecutive frames in which the
    human's foot is in contact (``flat``: in flat stance, its heel strikes and toe-offs left
    out) (NaN without such frames)."""
    return _stance_speed(robot, qpos, fps, human, human_fps, sole=False, flat=flat)


def stance_sole_speed(
    robot: RobotModel, qpos: np.ndarray, fps: float, human: np.ndarray, human_fps: float
) -> float:
    """Mean horizontal speed (m/s), between consecutive frames in which the human's foot is in
    contact, of each foot's slowest sole point (its floor points: heel and toe corners); a
    foot pivoting on its toe or heel does not count as moving (NaN without such frames)."""
    return _stance_speed(robot, qpos, fps, human, human_fps, sole=True)


def _stance_speed(
    robot: RobotModel,
    qpos: np.ndarray,
    fps: float,
    human: np.ndarray,
    human_fps: float,
    sole: bool,
    flat: bool = False,
) -> float:
    """The stance speeds above: of the foot body's origin, or of its slowest floor point."""
    rep = replay(robot.model, qpos)
    contact = human_contacts(human, human_fps, len(qpos), fps, flat)
    speeds = []
    for i, side in enumerate(("left", "right")):
        step = foot_steps(robot, rep, side, sole) * fps
        speeds.append(step[contact[1:, i] & contact[:-1, i]])
    all_speeds = np.concatenate(speeds)
    return float(all_speeds.mean()) if all_speeds.size else float("nan")


def joint_jerk_rms(qpos: np.ndarray, fps: float) -> float:
    """RMS (rad/s^3) of the joints' third differences (qpos columns 7 and on)."""
    q = np.asarray(qpos)[:, 7:]
    if len(q) < 4:
        return 0.0
    return float(np.sqrt(np.mean((np.diff(q, n=3, axis=0) * fps**3) ** 2)))
