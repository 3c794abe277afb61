"""``check_trajectory``: the one call that runs every simulation check and returns a Report."""

from __future__ import annotations

import time
from collections.abc import Iterable, Sequence

import numpy as np

from controlmm.errors import ControlMMError
from sim.assemble import build_report
from sim.config import CheckConfig
from sim.dynamics import dynamics_check
from sim.kinematic import kinematic_check
from sim.physics import PhysicsConfig, check_start, track
from sim.report import Report
from sim.tracking import tracking_check
from sim.trajectory import validate_qpos, velocities_and_accelerations
from sim.world import CheckWorld, SetTime, make_world


def check_trajectory(
    scene: object,
    qpos: object,
    fps: float | None = None,
    config: CheckConfig | None = None,
    *,
    robot_geom_ids: Iterable[int] | None = None,
    floor_geom_ids: Iterable[int] | None = None,
    obstacle_geom_ids: Iterable[int] | None = None,
    set_time: SetTime | None = None,
    foot_bodies: Sequence[str] | None = None,
    physics: PhysicsConfig | None = None,
    progress: bool = False,
) -> Report:
    """Replay a robot trajectory in a MuJoCo scene and check it (contract 4).

    Args:
        scene: a ``scenes.Scene`` (anything with ``.model`` and optionally the geom-id sets and
            ``.set_time``), a compiled ``mujoco.MjModel`` of robot + scene, or a
            :class:`~sim.world.CheckWorld` (reuse one across calls to skip the setup).
        qpos: (T, nq) trajectory in MuJoCo order (free joint xyz + quaternion wxyz, joints),
            or an object with ``.qpos`` and ``.fps`` (``retarget.RobotTrajectory``).
        fps: frames per second (taken from ``qpos.fps`` when omitted).
        config: thresholds and options (:class:`~sim.config.CheckConfig`).
        robot_geom_ids, floor_geom_ids, obstacle_geom_ids, set_time, foot_bodies: override
            the scene's (or the automatic) geom sets, mocap motion and feet.
        physics: settings of the physics execution check, run last when ``config.physics``
            (default ``PhysicsConfig()``); its result is ``report.physics``.
        progress: a progress bar for the physics execution check.

    Returns:
        A :class:`~sim.report.Report`; ``report.passed`` is True when no failure is an error
        (warnings are reported in ``report.warnings``).

    Raises:
        ControlMMError: bad qpos (width other than nq, NaN/inf), fps outside [1, 1000], a
            model without a free joint; with ``config.physics`` also a trajectory of one frame,
            a first pose inside the floor or an obstacle (one-line messages).
    """
    config = config or CheckConfig()
    if hasattr(qpos, "qpos"):
        fps = getattr(qpos, "fps", None) if fps is None else fps
        qpos = qpos.qpos
    world = (
        scene
        if isinstance(scene, CheckWorld)
        else make_world(
            scene,
            robot_geom_ids=robot_geom_ids,
            floor_geom_ids=floor_geom_ids,
            obstacle_geom_ids=obstacle_geom_ids,
            set_time=set_time,
            foot_bodies=foot_bodies,
        )
    )
    q, rate = validate_qpos(world, qpos, fps)
    physics_config = (physics or PhysicsConfig()) if config.physics else None
    if physics_config is not None:  # bad input fails before any work
        if q.shape[0] < 2:
            raise ControlMMError("the physics check needs at least 2 frames; got 1")
        check_start(world, q[0], physics_config)
    timings: dict[str, float] = {}
    cpu: dict[str, float] = {}

    def timed(name: str, fn):
        wall, proc = time.perf_counter(), time.process_time()
        out = fn()
        timings[name] = time.perf_counter() - wall
        cpu[name] = time.process_time() - proc
        return out

    qvel, qacc, half = timed("differences_s", lambda: velocities_and_accelerations(world.model, q, rate))
    kin = timed("kinematic_s", lambda: kinematic_check(world, q, rate, half, config))
    dyn = (
        timed(
            "dynamics_s",
            lambda: dynamics_check(world, q, qvel, qacc, kin.support, config, rate, kin.supported),
        )
        if config.dynamics
        else None
    )
    trk = (
        timed("tracking_s", lambda: tracking_check(world, q, qvel, half, rate, config))
        if config.tracking
        else None
    )
    phys = None
    if physics_config is not None:
        if dyn is None:
            dyn = timed(
                "dynamics_s",
                lambda: dynamics_check(world, q, qvel, qacc, kin.support, config, rate, kin.supported),
            )
        phys = timed(
            "physics_s",
            lambda: track(
                q,
                world,
                physics_config,
                fps=rate,
                check=config,
                qvel=qvel,
                dynamics=dyn,
                flight=kin.flight,
                progress=progress,
            ),
        )
    extra = {
        "timings_s": {k: round(v, 4) for k, v in timings.items()},
        "cpu_s": {k: round(v, 4) for k, v in cpu.items()},
        "robot_mass_kg": round(world.mass, 4),
        "nq": world.nq,
        "obstacles": [world.geom_label(g) for g in world.obstacle_geoms],
        "floor": [world.geom_label(g) for g in world.floor_geoms],
    }
    return build_report(world, rate, config, kin, dyn, trk, extra=extra, phys=phys)


def check_pose(scene: object, qpos: np.ndarray, config: CheckConfig | None = None) -> Report:
    """Check a single pose (nq,) as a one-frame trajectory (static: zero velocity)."""
    return check_trajectory(scene, np.asarray(qpos, dtype=np.float64).reshape(1, -1), 1.0, config)
