"""A peer for the physics benchmark: holosoma's G1 whole-body tracking policy (ONNX) in MuJoCo.

    python benchmarks/holosoma_peer.py [--seconds 6] [--policy ppo|fastsac]

Needs the optional ``peers`` extra (``pip install -e ".[peers]"``: the PyPI package
``holosoma-inference``, which ships ``models/wbt/{ppo,fastsac}_g1_29dof_dancing.onnx``, and
``onnxruntime``; the package's own runner needs the Unitree SDK, so this is a plain MuJoCo +
onnxruntime loop, facts from the ONNX file's metadata). The policy tracks the dance clip
embedded in the ONNX file (it returns the reference joints and torso orientation of any time
step); it is a tracking policy for that clip, not a general validator, so it runs on its own
clip only, side by side with ``sim.track`` on ours.

The loop: Menagerie G1 (its MJCF, the robot's own masses and limits) with the actuators turned
into the policy's PD servos (``kp``/``kd`` from the metadata, the effort limits of its training
config as force ranges), physics at 200 Hz, the policy at 50 Hz (decimation 4), as trained.
Observation (154, terms in alphabetical order): last action (29), root angular velocity in the
root frame (3), joint positions minus the default pose (29), joint velocities (29), the
reference joint positions and velocities (58), the reference torso orientation in the robot
torso's frame, both with their initial yaw removed, as the first two columns of its rotation
matrix (6). Target = default + action x 0.25 x effort limit / kp. The robot starts in the
clip's first pose with its lowest point on the floor.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from importlib import resources

import mujoco
import numpy as np

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

from retarget import robot_mjcf  # noqa: E402
from sim.geometry import support_heights  # noqa: E402
from sim.world import make_world  # noqa: E402

PHYSICS_DT = 0.005
DECIMATION = 4
ACTION_SCALE = 0.25
FALL_HEIGHT = 0.4
"""The robot has fallen when its root is below this height (m)."""


def _policy(name: str):
    import onnx  # optional peer dependency (the ``peers`` extra)
    import onnxruntime as ort  # optional peer dependency (the ``peers`` extra)

    path = resources.files("holosoma_inference") / "models" / "wbt" / f"{name}_g1_29dof_dancing.onnx"
    meta = {p.key: p.value for p in onnx.load(str(path), load_external_data=False).metadata_props}
    options = ort.SessionOptions()
    options.intra_op_num_threads = 1
    return ort.InferenceSession(str(path), options, providers=["CPUExecutionProvider"]), meta


def _yaw_free(quat: np.ndarray, yaw: float) -> np.ndarray:
    """``quat`` (wxyz) rotated by -yaw about the world z axis."""
    out = np.zeros(4)
    mujoco.mju_mulQuat(out, np.array([np.cos(-yaw / 2), 0.0, 0.0, np.sin(-yaw / 2)]), quat)
    return out


def _yaw(quat: np.ndarray) -> float:
    w, x, y, z = quat
    return float(np.arctan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z)))


def _model(kp: np.ndarray, kd: np.ndarray, effort: np.ndarray) -> mujoco.MjModel:
    spec = mujoco.MjSpec.from_file(str(robot_mjcf("g1")))
    spec.worldbody.add_geom(name="floor", type=mujoco.mjtGeom.mjGEOM_PLANE, size=[0, 0, 0.05])
    spec.option.timestep = PHYSICS_DT
    for i, actuator in enumerate(spec.actuators):
        gain, bias = np.zeros(10), np.zeros(10)
        gain[0], bias[1], bias[2] = kp[i], -kp[i], -kd[i]
        actuator.gainprm, actuator.biasprm = gain, bias
        actuator.ctrllimited = mujoco.mjtLimited.mjLIMITED_FALSE
        actuator.forcelimited = mujoco.mjtLimited.mjLIMITED_TRUE
        actuator.forcerange = [-effort[i], effort[i]]
    return spec.compile()


def run_dance_policy(seconds: float, policy: str = "ppo") -> dict:
    """Run the policy on its dance clip for ``seconds``; returns time up and speed figures."""
    session, meta = _policy(policy)
    config = json.loads(meta["experiment_config"])["robot"]
    names = json.loads(meta["dof_names"])
    kp, kd = np.array(json.loads(meta["kp"])), np.array(json.loads(meta["kd"]))
    effort = np.array(config["dof_effort_limit_list"], dtype=np.float64)
    default = np.array([config["init_state"]["default_joint_angles"][n] for n in names])
    scale = ACTION_SCALE * effort / kp
    m = _model(kp, kd, effort)
    if [m.actuator(i).name for i in range(m.nu)] != names:
        raise RuntimeError("the policy's joint order differs from the Menagerie G1's actuators")
    d = mujoco.MjData(m)
    torso = m.body("torso_link").id

    def reference(step: int, obs: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        out = session.run(
            ["actions", "joint_pos", "joint_vel", "ref_quat_xyzw"],
            {"obs": obs[None].astype(np.float32), "time_step": np.array([[step]], dtype=np.float32)},
        )
        ref_quat = np.asarray(out[3][0], dtype=np.float64)[[3, 0, 1, 2]]
        return (
            out[0][0].astype(np.float64),
            np.concatenate([out[1][0], out[2][0]]).astype(np.float64),
            ref_quat,
        )

    _, command, ref_quat = reference(0, np.zeros(154))
    d.qpos[7:] = command[:29]
    d.qpos[3:7] = ref_quat  # the torso's orientation for the root: close while the waist is near zero
    world = make_world(m)
    mujoco.mj_kinematics(m, d)
    geoms = world.robot_geoms
    low = support_heights(
        m,
        geoms,
        d.geom_xpos[geoms][None],
        d.geom_xmat[geoms][None],
        np.zeros((1, 3)),
        np.array([[0.0, 0.0, 1.0]]),
        world.hull_vertices,
    )
    d.qpos[2] -= float(np.nanmin(low))  # lowest point on the floor
    mujoco.mj_forward(m, d)
    motion_yaw = _yaw(ref_quat)
    robot_yaw = _yaw(d.xquat[torso])
    action = np.zeros(29)
    steps = int(round(seconds / (PHYSICS_DT * DECIMATION)))
    fell_at = None
    rot = np.zeros(9)
    errors = []
    wall, cpu = time.perf_counter(), time.process_time()
    for k in range(steps):
        rel = np.zeros(4)
        inv = np.zeros(4)
        mujoco.mju_negQuat(inv, _yaw_free(d.xquat[torso], robot_yaw))
        mujoco.mju_mulQuat(rel, inv, _yaw_free(ref_quat, motion_yaw))
        mujoco.mju_quat2Mat(rot, rel)
        obs = np.concatenate(
            [action, d.qvel[3:6], d.qpos[7:] - default, d.qvel[6:], command, rot.reshape(3, 3)[:, :2].ravel()]
        )
        errors.append(float(np.sqrt(np.mean((d.qpos[7:] - command[:29]) ** 2))))
        raw, command, ref_quat = reference(k, obs)
        action = np.clip(raw, -100.0, 100.0)
        d.ctrl[:] = default + action * scale
        for _ in range(DECIMATION):
            mujoco.mj_step(m, d)
        if d.qpos[2] < FALL_HEIGHT:
            fell_at = (k + 1) * PHYSICS_DT * DECIMATION
            break
    wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
    simulated = (k + 1) * PHYSICS_DT * DECIMATION
    return {
        "fell": fell_at is not None,
        "time_up_s": fell_at if fell_at is not None else simulated,
        "simulated_s": simulated,
        "wall_s": wall,
        "realtime_factor": simulated / wall,
        "realtime_factor_cpu": simulated / cpu,
        "mean_joint_error_rad": float(np.mean(errors)),
    }


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--seconds", type=float, default=6.0, help="seconds of the dance to run (default 6)")
    parser.add_argument(
        "--policy", choices=("ppo", "fastsac"), default="ppo", help="which policy (default ppo)"
    )
    args = parser.parse_args()
    r = run_dance_policy(args.seconds, args.policy)
    state = f"fell at {r['time_up_s']:.2f} s" if r["fell"] else "stayed up"
    print(
        f"holosoma {args.policy} dance policy: {state}; "
        f"joint error mean {r['mean_joint_error_rad']:.3f} rad; "
        f"{r['realtime_factor']:.2f}x real time ({r['wall_s']:.1f} s)"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
