"""The tracking cost of a batch of rollouts (what the predictive sampler minimises).

Per rollout step, against the reference at the same time (weights in ``PhysicsConfig``):

* root height and horizontal position, root orientation (``1 - <q, q_ref>^2``: 0 when aligned,
  1 when upside down, smooth and sign-free);
* actuated joint angles (mean squared error);
* centre of mass: horizontal position and velocity (balance: where the weight is and where
  it goes, as in MuJoCo MPC's humanoid tasks);
* feet positions (where the steps land);
* effort: the targets' deviation from the nominal (PD + feed-forward) ones.

The total is the mean over the horizon plus ``terminal`` times the last step, so a plan is
judged by where it leaves the robot as well as by how it gets there. Everything is
vectorised over samples and steps; no Python loop per sample.
"""

from __future__ import annotations

import numpy as np

from sim.physics.config import PhysicsConfig
from sim.physics.reference import Reference


def rollout_cost(
    qpos: np.ndarray,
    sensors: np.ndarray,
    offsets: np.ndarray,
    ref: Reference,
    after: np.ndarray,
    before: np.ndarray,
    root_adr: int,
    joint_adr: np.ndarray,
    config: PhysicsConfig,
) -> np.ndarray:
    """Cost (B,) of rollouts.

    Args:
        qpos: (B, H, nq) positions after each rollout step.
        sensors: (B, H, 6 + 3F) the planning sensors (centre of mass, its velocity, feet),
            measured at the start of each rollout step.
        offsets: (B, H, nu) the targets' deviation from the nominal ones.
        ref: the reference; after / before: (H,) simulation steps at the end / start of each
            rollout step (where ``qpos`` / ``sensors`` are compared).
        root_adr: qpos address of the root; joint_adr: (nu,) qpos addresses of the actuated joints.
        config: weights.
    """
    root = qpos[..., root_adr : root_adr + 3]
    quat = qpos[..., root_adr + 3 : root_adr + 7]
    c = config.w_root_height * (root[..., 2] - ref.root_pos[after, 2]) ** 2
    c += config.w_root_xy * np.sum((root[..., :2] - ref.root_pos[after, :2]) ** 2, axis=-1)
    dot = np.sum(quat * ref.root_quat[after], axis=-1)
    c += config.w_root_rot * (1.0 - dot**2)
    c += config.w_joint * np.mean((qpos[..., joint_adr] - ref.joints[after]) ** 2, axis=-1)
    com, com_vel, feet = sensors[..., 0:3], sensors[..., 3:6], sensors[..., 6:]
    c += config.w_com * np.sum((com[..., :2] - ref.com[before, :2]) ** 2, axis=-1)
    c += config.w_com_vel * np.sum((com_vel - ref.com_vel[before]) ** 2, axis=-1)
    feet_ref = ref.feet[before].reshape(before.size, -1)
    c += config.w_feet * np.sum((feet - feet_ref) ** 2, axis=-1)
    if config.w_effort:
        c += config.w_effort * np.mean(offsets**2, axis=-1)
    return c.mean(axis=1) + config.terminal * c[:, -1]
