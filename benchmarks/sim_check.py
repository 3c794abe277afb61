"""Speed of the simulation checks (sim.check_trajectory) on G1 and H1.

    python benchmarks/sim_check.py [--frames 3000] [--repeat 3]

The robot moves through a 60 s motion at 50 fps (squats, arm swings, a turn in place; feet
kept on the floor) in a world with a floor, a table, a post and a mocap ball rolling back
and forth in front of the shins. "typical" keeps the arms beside the body (a motion that
mostly passes); "contact-heavy" sweeps them across the torso and hips (deep mesh
self-collisions every few seconds: the collider's worst case). Each row is the best of
``--repeat`` runs after a warm-up that builds the collision copies of the model once:

* kinematic: the whole ``check_trajectory`` call with ``CheckConfig(dynamics=False)``, for
  each self-collision collider set;
* dynamic: the inverse-dynamics stage of a full check (``report.extra["timings_s"]``);
* tracking: the optional PD replay in physics (``mj_step`` at the model's timestep).

Wall time depends on what else runs on the machine (the load average is printed); the CPU
time of the process (the checks are single-threaded) is the steadier figure.
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
    "g1": dict(
        hip="hip_pitch_joint",
        knee="knee_joint",
        ankle="ankle_pitch_joint",
        sh_pitch="shoulder_pitch_joint",
        sh_roll="shoulder_roll_joint",
        elbow="elbow_joint",
        waist="waist_yaw_joint",
    ),
    "h1": dict(
        hip="hip_pitch",
        knee="knee",
        ankle="ankle",
        sh_pitch="shoulder_pitch",
        sh_roll="shoulder_roll",
        elbow="elbow",
        waist="torso",
    ),
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
        roll = 0.5 - 0.5 * np.cos(2 * np.pi * t / 5.0)
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
        h = support_heights(
            m,
            feet,
            d.geom_xpos[feet][None],
            d.geom_xmat[feet][None],
            np.zeros((1, 3)),
            up,
            world.hull_vertices,
        )
        return float(np.nanmin(h))

    target = lowest(q0)
    out = q.copy()
    for t in range(out.shape[0]):
        out[t, world.root_qpos_adr + 2] += target - lowest(out[t])
    return out


def run(fn, repeat: int) -> tuple[float, float, dict, dict]:
    """Best (by wall time) of ``repeat`` calls: wall s, CPU s, the report's stage timings."""
    best = None
    for _ in range(repeat):
        wall, cpu = time.perf_counter(), time.process_time()
        report = fn()
        wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
        if best is None or wall < best[0]:
            best = (wall, cpu, report.extra["timings_s"], report.extra["cpu_s"])
    return best


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument(
        "--frames", type=int, default=3000, help="trajectory length at 50 fps (default 3000 = 60 s)"
    )
    parser.add_argument("--repeat", type=int, default=3, help="timed repetitions, best kept (default 3)")
    args = parser.parse_args()
    load = os.getloadavg()[0]

    rows = []
    for robot in ("g1", "h1"):
        start = time.perf_counter()
        model = robot_world(robot, OBSTACLES)
        world = make_world(model)
        ball = model.body("ball").mocapid[0]

        def set_time(data, t, ball=ball):  # the ball rolls back and forth in front of the robot
            data.mocap_pos[ball] = (0.5, 1.5 * np.cos(2 * np.pi * t / 8.0), 0.3)

        world.set_time = set_time
        setup = time.perf_counter() - start
        for heavy in (False, True):
            q = motion(world, robot, args.frames, heavy)
            n = q.shape[0]
            label = "contact-heavy" if heavy else "typical"
            for mode in ("model", "capsules"):
                config = CheckConfig(dynamics=False, self_collision=mode)
                start = time.perf_counter()
                check_trajectory(world, q[:10], FPS, config)  # warm-up: builds the collision copies once
                if not heavy:
                    setup += time.perf_counter() - start
                wall, cpu, _, _ = run(
                    lambda c=config, w=world, q=q: check_trajectory(w, q, FPS, c), args.repeat
                )
                rows.append((robot, f"kinematic, {label}, self: {mode}", n, wall, cpu))
            full = CheckConfig()
            check_trajectory(world, q[:10], FPS, full)
            _, _, stage, stage_cpu = run(
                lambda w=world, q=q, c=full: check_trajectory(w, q, FPS, c), args.repeat
            )
            rows.append((robot, f"dynamic, {label}", n, stage["dynamics_s"], stage_cpu["dynamics_s"]))
            report = check_trajectory(world, q, FPS, full)
            print(
                f"# {robot} {label}: {len(report.failures)} failures "
                f"({', '.join(sorted({f.kind for f in report.failures})) or 'none'})",
                file=sys.stderr,
            )
        short = q[: min(n, 500)]
        tracking = CheckConfig(dynamics=False, tracking=True)
        _, _, stage, stage_cpu = run(lambda w=world, q=short, c=tracking: check_trajectory(w, q, FPS, c), 1)
        rows.append(
            (
                robot,
                "PD-tracking replay (mj_step)",
                short.shape[0],
                stage["tracking_s"],
                stage_cpu["tracking_s"],
            )
        )
        print(f"# {robot}: world setup incl. collision copies {setup:.2f} s", file=sys.stderr)

    print(
        f"machine: {platform.machine()}, {os.cpu_count()} CPU cores, Python {platform.python_version()}, "
        f"MuJoCo {__import__('mujoco').__version__}; load average at start {load:.1f}; "
        f"trajectory {args.frames} frames at {FPS:g} fps"
    )
    print(
        f"| {'robot':5} | {'check':40} | {'frames':>6} | {'wall s':>7} | {'frames/s':>8} | "
        f"{'CPU s':>7} | {'frames/CPU-s':>12} |"
    )
    print(f"|{'-' * 7}|{'-' * 42}|{'-' * 8}|{'-' * 9}|{'-' * 10}|{'-' * 9}|{'-' * 14}|")
    for robot, what, n, wall, cpu in rows:
        print(
            f"| {robot:5} | {what:40} | {n:6d} | {wall:7.3f} | {n / wall:8.0f} | {cpu:7.3f} | "
            f"{n / max(cpu, 1e-9):12.0f} |"
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
