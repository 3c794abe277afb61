"""Speed of the simulation checks (sim.check_trajectory) on G1 and H1.

    python benchmarks/sim_check.py [--frames 3000] [--repeat 3]

The robot moves through a 60 s motion at 50 fps (squats, arm swings, a turn in place; feet
kept on the floor) in a world with a floor, a table, a post and a mocap ball rolling back
and forth in front of the shins. "typical" keeps the arms beside the body (a motion that
mostly passes); "contact-heavy" sweeps them across the torso and hips (deep mesh
self-collisions every few seconds: the collider's worst case). Each row is the best of
``--repeat`` runs after a warm-up that builds the collision copies of the model once:

* kinematic: ``CheckConfig(dynamics=False)`` with each self-collision collider set;
* dynamic: the inverse-dynamics part alone (kinematic + dynamic minus kinematic);
* tracking: the optional PD replay in physics (``mj_step`` at the model's timestep).
"""

from __future__ import annotations

import argparse
import os
import platform
import sys
import time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

from sim import CheckConfig, check_trajectory, make_world  # noqa: E402
from sim.worlds import Obstacle, robot_world, standing_qpos  # noqa: E402

FPS = 50.0
OBSTACLES = [
    Obstacle("table", "box", (0.3, 0.5, 0.375), (0.9, 0.0, 0.375)),
    Obstacle("post", "cylinder", (0.06, 0.8), (-0.5, 0.6, 0.8)),
    Obstacle("ball", "sphere", (0.1,), (0.0, 2.0, 0.3), mocap=True),
]
MOTION_JOINTS = {
    "g1": dict(hip="hip_pitch_joint", knee="knee_joint", ankle="ankle_pitch_joint", sh_pitch="shoulder_pitch_joint",
               sh_roll="shoulder_roll_joint", elbow="elbow_joint", waist="waist_yaw_joint"),
    "h1": dict(hip="hip_pitch", knee="knee", ankle="ankle", sh_pitch="shoulder_pitch", sh_roll="shoulder_roll",
               elbow="elbow", waist="torso"),
}


def motion(world, robot: str, frames: int, heavy: bool) -> np.ndarray:
    """Squats, arm swings and a slow turn, feet kept on the floor (root height re-solved).

    ``heavy``: the arms sweep across the torso and hips instead of beside them (deep mesh
    self-collisions, the most expensive narrow phase), the worst case for the collider.
    """
    model = world.model
    names = MOTION_JOINTS[robot]
    q0 = standing_qpos(model)
    q = np.tile(q0, (frames, 1))
    t = np.arange(frames) / FPS

    def adr(name: str) -> int:
        return int(model.jnt_qposadr[model.joint(name).id])

    squat = 0.5 - 0.5 * np.cos(2 * np.pi * t / 4.0)  # one squat every 4 s
    for side, sign in (("left", 1.0), ("right", -1.0)):
        q[:, adr(f"{side}_{names['hip']}")] += -0.6 * squat
        q[:, adr(f"{side}_{names['knee']}")] += 1.2 * squat
        q[:, adr(f"{side}_{names['ankle']}")] += -0.6 * squat
        q[:, adr(f"{side}_{names['sh_pitch']}")] += -0.8 * np.sin(2 * np.pi * t / 3.0 + sign)
        roll = (0.5 - 0.5 * np.cos(2 * np.pi * t / 5.0))
        q[:, adr(f"{side}_{names['sh_roll']}")] += sign * (-1.2 if heavy else 0.4) * roll
        q[:, adr(f"{side}_{names['elbow']}")] += 0.3 * np.sin(2 * np.pi * t / 2.0)
    q[:, adr(names["waist"])] += 0.3 * np.sin(2 * np.pi * t / 6.0)
    yaw = 0.5 * np.sin(2 * np.pi * t / 20.0)
    q[:, 3], q[:, 6] = np.cos(yaw / 2), np.sin(yaw / 2)
    return _keep_feet_down(world, q, q0)


def _keep_feet_down(world, q: np.ndarray, q0: np.ndarray) -> np.ndarray:
    """Move the root vertically so the feet's lowest point stays at the standing pose's."""
    import mujoco

    from sim.geometry import support_heights

    m = world.model
    d = mujoco.MjData(m)
    feet = np.concatenate([f.geoms for f in world.feet])
    up = np.array([[0.0, 0.0, 1.0]])

    def lowest(pose: np.ndarray) -> float:
        d.qpos[:] = pose
        mujoco.mj_kinematics(m, d)
        h = support_heights(m, feet, d.geom_xpos[feet][None], d.geom_xmat[feet][None], np.zeros((1, 3)), up,
                            world.hull_vertices)
        return float(np.nanmin(h))

    target = lowest(q0)
    out = q.copy()
    for t in range(out.shape[0]):
        out[t, world.root_qpos_adr + 2] += target - lowest(out[t])
    return out


def best_time(fn, repeat: int) -> float:
    times = []
    for _ in range(repeat):
        start = time.perf_counter()
        fn()
        times.append(time.perf_counter() - start)
    return min(times)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--frames", type=int, default=3000, help="trajectory length at 50 fps (default 3000 = 60 s)")
    parser.add_argument("--repeat", type=int, default=3, help="timed repetitions, best kept (default 3)")
    args = parser.parse_args()

    rows = []
    for robot in ("g1", "h1"):
        start = time.perf_counter()
        model = robot_world(robot, OBSTACLES)
        world = make_world(model)
        ball = model.body("ball").mocapid[0]

        def set_time(data, t, ball=ball):  # the ball rolls back and forth in front of the shins
            data.mocap_pos[ball] = (0.35, 1.5 * np.cos(2 * np.pi * t / 8.0), 0.3)

        world.set_time = set_time
        setup = time.perf_counter() - start
        kin_only = CheckConfig(dynamics=False)
        full = CheckConfig()
        for heavy in (False, True):
            q = motion(world, robot, args.frames, heavy)
            n = q.shape[0]
            label = "contact-heavy" if heavy else "typical"
            for mode in ("model", "capsules"):
                config = CheckConfig(dynamics=False, self_collision=mode)
                check_trajectory(world, q[:10], FPS, config)  # warm-up: builds the collision copies
                t_kin = best_time(lambda c=config: check_trajectory(world, q, FPS, c), args.repeat)
                rows.append((robot, f"kinematic, {label}, self: {mode}", n, t_kin))
            check_trajectory(world, q[:10], FPS, full)
            t_kin = best_time(lambda: check_trajectory(world, q, FPS, kin_only), args.repeat)
            t_full = best_time(lambda: check_trajectory(world, q, FPS, full), args.repeat)
            rows.append((robot, f"dynamic, {label}", n, max(t_full - t_kin, 1e-9)))
            report = check_trajectory(world, q, FPS, full)
            print(f"# {robot} {label}: {len(report.failures)} failures "
                  f"({', '.join(sorted({f.kind for f in report.failures})) or 'none'})", file=sys.stderr)
        short = q[: min(n, 500)]
        tracking = CheckConfig(dynamics=False, tracking=True)
        t_track = best_time(lambda: check_trajectory(world, short, FPS, tracking), 1) - best_time(
            lambda: check_trajectory(world, short, FPS, kin_only), 1)
        rows.append((robot, "PD-tracking replay (mj_step)", short.shape[0], max(t_track, 1e-9)))
        print(f"# {robot}: world setup {setup:.2f} s", file=sys.stderr)

    print(f"machine: {platform.machine()}, {os.cpu_count()} CPU cores, Python {platform.python_version()}, "
          f"MuJoCo {__import__('mujoco').__version__}; trajectory {args.frames} frames at {FPS:g} fps")
    print(f"| {'robot':5} | {'check':45} | {'frames':>6} | {'seconds':>8} | {'frames/s':>9} |")
    print(f"|{'-' * 7}|{'-' * 47}|{'-' * 8}|{'-' * 10}|{'-' * 11}|")
    for robot, what, n, seconds in rows:
        print(f"| {robot:5} | {what:45} | {n:6d} | {seconds:8.3f} | {n / seconds:9.0f} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
