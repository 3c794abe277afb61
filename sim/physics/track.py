"""``track``: execute a trajectory in MuJoCo physics with the predictive controller, and judge it.

The robot starts in the first frame's pose and velocity, in contact with the floor and the
scene, with no external force of any kind (``xfrc_applied`` and ``qfrc_applied`` stay zero);
only its actuators act, within their control and force ranges. Every ``replan_s`` the
predictive sampler (:mod:`sim.physics.sampler`) plans from the true simulated state; between
plans its targets (nominal PD + feed-forward targets plus the planned foot-space offsets) go to
the actuators at every ``mj_step`` (:mod:`sim.physics.actuation`). Every control input and state
is recorded, so the run can be replayed from ``physics_model.xml`` alone
(:mod:`sim.physics.certificate`).
"""

from __future__ import annotations

import math
import time

import mujoco
import numpy as np
from tqdm import tqdm

from controlmm.errors import ControlMMError
from sim.config import CheckConfig
from sim.dynamics import DynamicsResult, dynamics_check
from sim.kinematic import kinematic_check
from sim.physics.actuation import Actuation, actuation, servo_planning
from sim.physics.config import PhysicsConfig
from sim.physics.model import (
    add_plan_sensors,
    check_same_layout,
    compile_xml,
    inline_meshes,
    plan_sensor_start,
    planning_model,
)
from sim.physics.model_cache import ModelTextCache, model_key
from sim.physics.reference import Reference, build_reference
from sim.physics.result import PhysicsResult, fall_frame, verdict
from sim.physics.sampler import FULL_STATE, PredictiveSampler
from sim.trajectory import validate_qpos, velocities_and_accelerations
from sim.world import CheckWorld, make_world


def check_start(world: CheckWorld, qpos0: np.ndarray, config: PhysicsConfig) -> None:
    """Raise when the first pose puts the robot inside the floor or an obstacle.

    Depth is MuJoCo's contact distance between a robot collision geom and a floor or obstacle
    geom (convex hulls for meshes); more than ``config.start_penetration_m`` is bad input.
    """
    m = world.model
    d = mujoco.MjData(m)
    d.qpos[:] = qpos0
    mocap = world.mocap_poses(np.zeros(1))
    if mocap is not None:
        d.mocap_pos[:] = mocap[0][0]
        d.mocap_quat[:] = mocap[1][0]
    mujoco.mj_kinematics(m, d)
    mujoco.mj_collision(m, d)
    robot = np.zeros(m.ngeom, dtype=bool)
    robot[world.robot_geoms] = True
    scene = np.zeros(m.ngeom, dtype=bool)
    scene[world.floor_geoms] = True
    scene[world.obstacle_geoms] = True
    worst, where = 0.0, ""
    for i in range(d.ncon):
        g1, g2 = int(d.contact.geom[i, 0]), int(d.contact.geom[i, 1])
        if robot[g1] == robot[g2] or not (scene[g1] or scene[g2]):
            continue
        depth = -float(d.contact.dist[i])
        if depth > worst:
            r, o = (g1, g2) if robot[g1] else (g2, g1)
            worst, where = depth, f"{world.body_name(int(m.geom_bodyid[r]))} is inside {world.geom_label(o)}"
    if worst > config.start_penetration_m:
        raise ControlMMError(
            f"the robot starts inside the scene: at frame 0 {where} by {worst * 1000:.1f} mm "
            f"(at most {config.start_penetration_m * 1000:.0f} mm allowed); move the trajectory or the scene"
        )


def _executed(xml: str, original: mujoco.MjModel) -> mujoco.MjModel:
    """The executed model compiled from its saved MJCF text: the scene model's state layout and
    the cost's sensors, else a one-line error."""
    model = compile_xml(xml)
    check_same_layout(original, model)
    plan_sensor_start(model)
    return model


def _planning(
    world: CheckWorld, executed: mujoco.MjModel, substeps: int, act_kp: float, act_kv: float
) -> mujoco.MjModel:
    """The planning copy (:func:`sim.physics.model.planning_model`, motors as servos)."""
    plan = planning_model(executed, substeps, world.robot_geoms)
    servo_planning(plan, actuation(executed, act_kp, act_kv))
    return plan


def physics_models(
    world: CheckWorld, substeps: int, act_kp: float, act_kv: float
) -> tuple[mujoco.MjModel, str, mujoco.MjModel]:
    """The executed model, its MJCF text and the planning copy, built once per world.

    The executed model is the robot + scene with the meshes inline and the cost's sensors,
    compiled from its saved text (read from the user's cache when an earlier process saved the
    same model: :mod:`sim.physics.model_cache`); the planning copy is that model with a few
    fields changed.
    """
    if world.spec is None:
        raise ControlMMError(
            "the physics check needs the scene's MjSpec (to save the model and build the planning copy): "
            "build the world from a scenes.Scene, an MjSpec or sim.worlds.robot_spec(...)"
        )
    spec, original = world.spec, world.model
    root, feet = world.body_name(world.root_body), [f.name for f in world.feet]

    def executed() -> tuple[mujoco.MjModel, str]:
        cache = ModelTextCache()
        key = model_key(original, root, *feet) if cache.directory is not None else ""
        cached = cache.get(key) if key else None
        if cached is not None:
            try:
                return _executed(cached, original), cached
            except ControlMMError:  # an unusable entry: rebuilt and rewritten below
                pass
        inline = inline_meshes(spec, original)
        add_plan_sensors(inline, root, feet)
        xml = inline.to_xml()
        model = _executed(xml, original)
        if key:
            cache.put(key, xml)
        return model, xml

    model, xml = world.derived(("physics_executed",), executed)
    plan = world.derived(
        ("physics_plan", substeps, act_kp, act_kv),
        lambda: _planning(world, model, substeps, act_kp, act_kv),
    )
    return model, xml, plan


def _feedforward(
    world: CheckWorld, q: np.ndarray, fps: float, check: CheckConfig
) -> tuple[np.ndarray, DynamicsResult, np.ndarray]:
    qvel, qacc, half = velocities_and_accelerations(world.model, q, fps)
    kin = kinematic_check(world, q, fps, half, check)
    dyn = dynamics_check(world, q, qvel, qacc, kin.support, check, fps, kin.supported)
    return qvel, dyn, kin.flight


def track(
    trajectory: object,
    world: object,
    config: PhysicsConfig | None = None,
    *,
    fps: float | None = None,
    check: CheckConfig | None = None,
    qvel: np.ndarray | None = None,
    dynamics: DynamicsResult | None = None,
    flight: np.ndarray | None = None,
    progress: bool = False,
) -> PhysicsResult:
    """Execute ``trajectory`` in ``world`` with the predictive tracking controller.

    Args:
        trajectory: (T, nq) qpos (free joint xyz + quaternion wxyz, joints), or an object with
            ``.qpos`` and ``.fps`` (``retarget.RobotTrajectory``).
        world: a :class:`~sim.world.CheckWorld`, a ``scenes.Scene``, an ``MjSpec`` (anything
            :func:`~sim.world.make_world` takes); the certificate needs its MjSpec.
        config: controller and verdict settings.
        fps: frame rate (taken from ``trajectory.fps`` when omitted).
        check: thresholds of the inverse-dynamics check that gives the feed-forward torques
            (default ``CheckConfig()``; its ``tracking_kp/kd`` are the PD gains for motors).
        qvel, dynamics, flight: the trajectory's finite-difference velocities, the
            inverse-dynamics result and the kinematic check's flight frames when the caller has
            them (``check_trajectory`` does), else computed here.
        progress: a progress bar on stderr.

    Returns:
        A :class:`PhysicsResult` (verdict, per-frame measures, the certificate arrays).

    Raises:
        ControlMMError: a width other than nq, NaN/inf, fewer than 2 frames, a first pose
            inside the floor or an obstacle, unsupported actuators (one line each).
    """
    config = config or PhysicsConfig()
    check = check or CheckConfig()
    if hasattr(trajectory, "qpos"):
        fps = getattr(trajectory, "fps", None) if fps is None else fps
        trajectory = trajectory.qpos
    world = world if isinstance(world, CheckWorld) else make_world(world)
    q, rate = validate_qpos(world, trajectory, fps)
    if q.shape[0] < 2:
        raise ControlMMError("the physics check needs at least 2 frames; got 1")
    check_start(world, q[0], config)
    exec_model, xml, plan_model = physics_models(
        world, config.plan_substeps, check.tracking_kp, check.tracking_kd
    )
    if qvel is None or dynamics is None or flight is None:
        qvel, dynamics, flight = _feedforward(world, q, rate, check)
    act = actuation(exec_model, check.tracking_kp, check.tracking_kd)
    dt = float(exec_model.opt.timestep)
    ref = build_reference(world, act, q, qvel, rate, dynamics.joint_torque, dt, config, flight)
    mocap = world.mocap_poses(np.arange(ref.steps + 1) * dt)
    sampler = PredictiveSampler(
        plan_model, act, ref, config, config.plan_substeps, world.root_qpos_adr, mocap
    )
    try:
        return _simulate(world, exec_model, xml, act, ref, sampler, mocap, config, progress)
    finally:
        sampler.close()


def _simulate(
    world: CheckWorld,
    m: mujoco.MjModel,
    xml: str,
    act: Actuation,
    ref: Reference,
    sampler: PredictiveSampler,
    mocap: tuple[np.ndarray, np.ndarray] | None,
    config: PhysicsConfig,
    progress: bool,
) -> PhysicsResult:
    """The closed loop: plan every ``replan_s``, apply the targets at every ``mj_step``, measure
    every frame, stop ``after_fall_s`` after a fall; then the verdict and the statistics."""
    T, fps, dt, S = ref.frame_qpos.shape[0], ref.fps, ref.dt, ref.steps
    d = mujoco.MjData(m)
    d.qpos[:] = ref.frame_qpos[0]
    d.qvel[:] = ref.frame_qvel[0]
    qpos = np.full((S + 1, m.nq), np.nan)
    qvel = np.full((S + 1, m.nv), np.nan)
    ctrl = np.zeros((S, m.nu))
    qpos[0], qvel[0] = d.qpos, d.qvel
    frame_step = np.minimum(np.round(np.arange(T) / fps / dt).astype(np.int64), S)
    step_frame = np.full(S + 1, -1, dtype=np.int64)
    step_frame[frame_step] = np.arange(T)
    J = world.joints
    limit = np.where(np.isfinite(J.torque_limit) & (J.torque_limit > 0), J.torque_limit, np.inf)
    feet = world.feet
    foot_geoms = np.zeros(m.ngeom, dtype=np.int64) - 1
    for i, f in enumerate(feet):
        foot_geoms[f.geoms] = i
    is_robot = np.zeros(m.ngeom, dtype=bool)
    is_robot[world.robot_geoms] = True
    is_scene = np.zeros(m.ngeom, dtype=bool)
    is_scene[world.floor_geoms] = True
    is_scene[world.obstacle_geoms] = True
    nan = np.full(T, np.nan)
    root_error, root_height, tilt, joint_error = nan.copy(), nan.copy(), nan.copy(), nan.copy()
    eff_error = np.full((T, ref.effectors.size), np.nan)
    foot_contact = np.zeros((T, len(feet)), dtype=bool)
    other_contact = np.zeros(T, dtype=bool)
    torque = np.full((T, len(J.names)), np.nan)
    simulated = np.zeros(T, dtype=bool)
    peak = np.zeros(len(J.names))
    external = 0.0  # largest |xfrc_applied| or |qfrc_applied| seen: nothing but the actuators may act
    root, adr = world.root_body, world.root_qpos_adr
    replan = max(1, int(round(config.replan_s / dt)))
    stop = S
    fell_at: int | None = None
    state = np.empty(mujoco.mj_stateSize(m, FULL_STATE))
    mocap_pos = np.zeros((S, m.nmocap, 3)) if mocap is not None else None
    mocap_quat = np.zeros((S, m.nmocap, 4)) if mocap is not None else None

    def measure(t: int) -> None:
        nonlocal external
        external = max(external, float(np.abs(d.xfrc_applied).max()), float(np.abs(d.qfrc_applied).max()))
        mujoco.mj_kinematics(m, d)  # positions of the current state (the step's own are one behind)
        simulated[t] = True
        p_ref = ref.frame_qpos[t, adr : adr + 3]
        root_error[t] = float(np.linalg.norm(d.qpos[adr : adr + 3] - p_ref))
        root_height[t] = d.qpos[adr + 2]
        rot = d.xmat[root].reshape(3, 3)
        cos = float(np.clip(rot[:, 2] @ ref.frame_up[t], -1.0, 1.0))
        tilt[t] = math.degrees(math.acos(cos))
        err = d.qpos[act.qpos_adr] - ref.frame_qpos[t, act.qpos_adr]
        joint_error[t] = float(np.sqrt(np.mean(err**2))) if err.size else 0.0
        rel = (d.xpos[ref.effectors] - d.xpos[root]) @ rot
        eff_error[t] = np.linalg.norm(rel - ref.frame_effectors[t], axis=1)
        mujoco.mj_collision(m, d)
        for i in range(d.ncon):
            g1, g2 = int(d.contact.geom[i, 0]), int(d.contact.geom[i, 1])
            if d.contact.dist[i] > 0 or not (is_scene[g1] or is_scene[g2]):
                continue
            r = g1 if is_robot[g1] else g2 if is_robot[g2] else -1
            if r < 0:
                continue
            if foot_geoms[r] >= 0:
                foot_contact[t, foot_geoms[r]] = True
            else:
                other_contact[t] = True
        torque[t] = peak / limit
        peak[:] = 0.0

    # Every planning step's state and plan, to back up to after a fall (config.retries).
    snap_kind = mujoco.mjtState.mjSTATE_INTEGRATION  # everything mj_step reads: replays exactly
    snaps = np.empty((S // replan + 1, mujoco.mj_stateSize(m, snap_kind)))
    plans = np.empty((S // replan + 1, *sampler.best.shape))
    plan_steps = np.zeros(S // replan + 1, dtype=np.int64)
    retries = 0

    def back_up(fall_step: int) -> int:
        """Restore the planning step ``retries * retry_back_s`` before ``fall_step``; its step."""
        k = max(0, fall_step - int(round(retries * config.retry_back_s / dt))) // replan
        s0 = k * replan
        mujoco.mj_setState(m, d, snaps[k], snap_kind)
        margin = int(round(config.flight_margin_s / dt))
        sampler.restart(plans[k], int(plan_steps[k]), retries, fall_step + margin)
        later = frame_step > s0
        for per_frame in (root_error, root_height, tilt, joint_error, eff_error, torque):
            per_frame[later] = np.nan
        simulated[later], foot_contact[later], other_contact[later] = False, False, False
        qpos[s0 + 1 :], qvel[s0 + 1 :] = np.nan, np.nan
        peak[:] = 0.0
        bar.n = round(s0 * dt, 2)
        bar.refresh()
        return s0

    wall, cpu = time.perf_counter(), time.process_time()
    bar = tqdm(total=round(S * dt, 2), unit="s", desc="physics", disable=not progress, leave=False)
    measure(0)
    s = 0
    while s < S:
        if s % replan == 0:
            k = s // replan
            mujoco.mj_getState(m, d, snaps[k], snap_kind)
            plans[k], plan_steps[k] = sampler.best, sampler.plan_step
            mujoco.mj_getState(m, d, state, FULL_STATE)
            sampler.plan(state, s)
        target = ref.nominal[s] + sampler.offset(s)
        d.ctrl[:] = act.controls(target, d.qpos, d.qvel)
        ctrl[s] = d.ctrl
        if mocap is not None:
            d.mocap_pos[:] = mocap[0][s]
            d.mocap_quat[:] = mocap[1][s]
            mocap_pos[s], mocap_quat[s] = d.mocap_pos, d.mocap_quat  # type: ignore[index]
        mujoco.mj_step(m, d)
        qpos[s + 1], qvel[s + 1] = d.qpos, d.qvel
        np.maximum(peak, np.abs(d.qfrc_actuator[J.dof_adr]), out=peak)
        t = int(step_frame[s + 1])
        if t >= 0:
            measure(t)
            reference_height = np.minimum(ref.frame_qpos[t : t + 1, adr + 2], ref.frame_qpos[0, adr + 2])
            down = fall_frame(root_height[t : t + 1], reference_height, tilt[t : t + 1], config)
            lost = down is not None or (config.retry_lost and root_error[t] > config.max_root_error_m)
            if fell_at is None and lost and retries < config.retries:
                retries += 1
                s = back_up(s + 1)
                continue
            if fell_at is None and down is not None:
                fell_at = t
                stop = min(S, s + 1 + int(round(config.after_fall_s / dt)))
        s += 1
        if s % replan == 0:
            bar.update(round(replan * dt, 4))
        if s >= stop:
            break
    bar.close()
    wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
    taken = min(stop, S) if S else 0
    if not np.isfinite(qpos[: taken + 1]).all():
        raise ControlMMError("the simulation diverged (non-finite state); the trajectory cannot be executed")
    root_drop = ref.frame_qpos[:, adr + 2] - root_height
    names = [world.body_name(b) for b in ref.effectors]
    failures = verdict(fell_at, root_error, root_drop, eff_error, world.body_name(root), names, fps, config)
    up_frames = simulated & (np.arange(T) < (fell_at if fell_at is not None else T))
    sim_seconds = taken * dt
    stats = {
        "fell": fell_at is not None,
        "fall_frame": fell_at,
        "time_up_s": (fell_at if fell_at is not None else T - 1) / fps,
        "mean_root_error_m": float(np.nanmean(root_error[up_frames])) if up_frames.any() else 0.0,
        "max_root_error_m": float(np.nanmax(root_error[up_frames])) if up_frames.any() else 0.0,
        "mean_joint_error_rad": float(np.nanmean(joint_error[up_frames])) if up_frames.any() else 0.0,
        "max_effector_error_m": float(np.nanmax(eff_error[up_frames]))
        if up_frames.any() and eff_error.size
        else 0.0,
        "max_tilt_error_deg": float(np.nanmax(tilt[up_frames])) if up_frames.any() else 0.0,
        "max_torque_ratio": float(torque[simulated].max()) if torque.size and simulated.any() else 0.0,
        "mean_torque_ratio": float(torque[simulated].max(axis=1).mean())
        if torque.size and simulated.any()
        else 0.0,
        "max_external_force": external,
        "foot_contact_frames": [int(n) for n in foot_contact.sum(axis=0)],
        "other_contact_frames": int(other_contact.sum()),
        "simulated_s": sim_seconds,
        "timestep": dt,
        "steps": taken,
        "rollout_steps": sampler.rollouts,
        "retries": retries,
        "wall_s": wall,
        "realtime_factor": sim_seconds / wall if wall > 0 else 0.0,
        "cpu_s": cpu,
        "threads": config.threads,
        "realtime_factor_cpu": sim_seconds * config.threads / cpu if cpu > 0 else 0.0,
        "error_kinds": sorted({f.kind for f in failures}),
    }
    return PhysicsResult(
        passed=not failures,
        fps=fps,
        timestep=dt,
        fell=fell_at is not None,
        fall_frame=fell_at,
        failures=failures,
        root_error_m=root_error,
        root_height_m=root_height,
        tilt_error_deg=tilt,
        joint_error_rad=joint_error,
        effector_error_m=eff_error,
        foot_contact=foot_contact,
        other_contact=other_contact,
        torque_ratio=torque,
        simulated=simulated,
        feet=[f.name for f in world.feet],
        effectors=names,
        joints=list(J.names),
        actuators=list(act.names),
        root_qpos_adr=adr,
        qpos=qpos[: taken + 1],
        qvel=qvel[: taken + 1],
        ctrl=ctrl[:taken],
        mocap_pos=None if mocap_pos is None else mocap_pos[:taken],
        mocap_quat=None if mocap_quat is None else mocap_quat[:taken],
        model_xml=xml,
        config=config,
        stats=stats,
    )
