"""The physics execution check (``sim.track``): certificate replay, verdicts, bad input, feedback.

Short clips and few samples keep these fast; what the controller achieves on real motion is
measured in ``benchmarks/physics.py`` (docs/BENCHMARKS.md).
"""

from __future__ import annotations

import copy
import json
import os
import re
from dataclasses import replace
from functools import cache

import mujoco
import numpy as np
import pytest
from cli_helpers import one_line_error, run_cli
from sim_motions import hold

from controlmm.errors import ControlMMError, ShapeError
from controlmm.frames import HumanToWorld
from controlmm.pipeline.feedback import feedback_terms
from controlmm.user_cache import CACHE_ENV
from retarget.exports import read_csv_qpos, read_export
from sim import (
    CheckConfig,
    Failure,
    PhysicsConfig,
    check_trajectory,
    load_report,
    make_world,
    replay_certificate,
    track,
)
from sim.physics import save_certificate
from sim.physics.certificate import CSV_FPS
from sim.physics.model import PLAN_SENSOR_PREFIX, near_pairs_apart
from sim.physics.model_cache import MAX_ENTRIES, ModelTextCache, model_key
from sim.physics.track import physics_models
from sim.world import CheckWorld
from sim.worlds import Obstacle, robot_spec, standing_qpos

FPS = 50.0
FAST = PhysicsConfig(samples=8, horizon_s=0.2, knots=3)


@cache
def g1() -> CheckWorld:
    """G1 on a floor, built from its MjSpec (the physics check saves the model from it)."""
    return make_world(robot_spec("g1"))


def stand(frames: int) -> np.ndarray:
    return hold(standing_qpos(g1().model), frames)


@pytest.fixture(scope="module")
def standing_run():
    return track(stand(25), g1(), FAST, fps=FPS)


def test_standing_stays_up_and_passes(standing_run):
    r = standing_run
    assert r.passed and not r.fell and r.failures == []
    assert np.nanmax(r.root_error_m) < 0.02 and np.nanmax(r.joint_error_rad) < 0.05
    assert r.foot_contact.all() and not r.other_contact.any()  # both feet down, nothing else
    assert 0.0 < np.nanmax(r.torque_ratio) < 1.0  # the actuators carry the robot within their limits


def test_certificate_replays_exactly_from_the_saved_model(standing_run, tmp_path):
    paths = save_certificate(standing_run, tmp_path)
    xml = paths["physics_model.xml"].read_text()
    assert 'file="' not in xml  # self-contained: meshes inline, nothing beside it
    # The documented replay, independently of the library: load, set the first state, step the ctrl.
    model = mujoco.MjModel.from_xml_path(str(paths["physics_model.xml"]))
    with np.load(paths["physics.npz"]) as npz:
        qpos, qvel, ctrl, dt = npz["qpos"], npz["qvel"], npz["ctrl"], float(npz["timestep"])
    assert dt == model.opt.timestep and ctrl.shape == (qpos.shape[0] - 1, model.nu)
    lo, hi = model.actuator_ctrlrange.T
    assert ((ctrl >= lo) & (ctrl <= hi)).all()  # within the actuators' control ranges
    data = mujoco.MjData(model)
    data.qpos[:], data.qvel[:] = qpos[0], qvel[0]
    for s in range(ctrl.shape[0]):
        data.ctrl[:] = ctrl[s]
        mujoco.mj_step(model, data)
        assert np.array_equal(data.qpos, qpos[s + 1]), s
    assert np.array_equal(replay_certificate(paths["physics_model.xml"], paths["physics.npz"]), qpos)
    # Only the robot's own actuators acted: the MJCF's, on its hinges, never on the free joint;
    # no external force was ever applied during the run.
    robot = g1().model
    assert [model.actuator(a).name for a in range(model.nu)] == [
        robot.actuator(a).name for a in range(robot.nu)
    ]
    for field in ("actuator_ctrlrange", "actuator_forcerange", "actuator_gear", "actuator_trnid"):
        assert np.allclose(getattr(model, field), getattr(robot, field), rtol=1e-9, atol=1e-12), field
    assert (model.jnt_type[model.actuator_trnid[:, 0]] == mujoco.mjtJoint.mjJNT_HINGE).all()
    assert standing_run.stats["max_external_force"] == 0.0
    # robot_physics.csv: the simulated states at 50 fps (every 10th step of 2 ms), LAFAN1-G1 rows (xyzw)
    stride = int(round(1.0 / CSV_FPS / dt))
    assert read_csv_qpos(paths["robot_physics.csv"], "xyzw").tolist() == qpos[::stride].tolist()


def test_the_planning_copy_keeps_the_robots_dynamics_but_not_its_joint_friction():
    # The rollouts run on a copy of the executed model: 5x the timestep, no dry joint friction
    # (one constraint row per joint, ~1.4x the cost of a G1 rollout step), no collision tests
    # between links the joints keep apart (mesh pairs a few mm apart at every step); the
    # executed model keeps all of it.
    world = g1()
    executed, _, plan = physics_models(world, 5, CheckConfig().tracking_kp, CheckConfig().tracking_kd)
    assert (executed.dof_frictionloss > 0).sum() == executed.nu  # G1: 0.3 N m on every actuated joint
    assert (plan.dof_frictionloss == 0).all()
    assert (plan.nq, plan.nv, plan.nu) == (executed.nq, executed.nv, executed.nu)
    assert np.array_equal(plan.body_mass, executed.body_mass)
    assert np.array_equal(plan.dof_armature, executed.dof_armature)
    assert plan.opt.timestep == pytest.approx(5 * executed.opt.timestep)
    assert np.array_equal(plan.geom_size, executed.geom_size)  # the same geoms and meshes
    for model in (executed, plan):  # the cost's sensors, last: com, com velocity, feet
        assert model.sensor_adr[-1] + 3 == model.nsensordata
        assert mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SENSOR, PLAN_SENSOR_PREFIX + "com") >= 0

    def pair(m: mujoco.MjModel, ga: int, gb: int) -> bool:
        ct, ca = m.geom_contype, m.geom_conaffinity
        return bool(ct[ga] & ca[gb] or ct[gb] & ca[ga])

    def collides(m: mujoco.MjModel, a: str, b: str) -> bool:  # the first collision geom of each body
        robot = world.robot_geoms
        ga, gb = (int(robot[np.flatnonzero(m.geom_bodyid[robot] == m.body(n).id)[0]]) for n in (a, b))
        return pair(m, ga, gb)

    apart = [  # one limb's links; a limb's first links with the one it branches from
        ("left_elbow_link", "left_wrist_pitch_link"),
        ("left_hip_roll_link", "left_knee_link"),
        ("pelvis", "right_hip_roll_link"),
        ("pelvis", "torso_link"),
        ("torso_link", "left_shoulder_roll_link"),
    ]
    touching = [  # links that motions can bring together
        ("left_knee_link", "right_knee_link"),
        ("left_ankle_roll_link", "right_ankle_roll_link"),
        ("left_wrist_yaw_link", "pelvis"),
        ("right_wrist_yaw_link", "left_hip_roll_link"),
        ("left_knee_link", "torso_link"),
        ("left_elbow_link", "torso_link"),
        ("left_wrist_yaw_link", "right_wrist_yaw_link"),
    ]
    for a, b in apart + touching:
        assert collides(executed, a, b), (a, b)
    assert not any(collides(plan, a, b) for a, b in apart)
    assert all(collides(plan, a, b) for a, b in touching)
    assert all(pair(plan, a, f) == pair(executed, a, f) for a in world.robot_geoms for f in world.floor_geoms)
    # Standing on the floor, the copy sees the executed model's contacts that it tests (the feet's).
    contacts = []
    for model in (executed, plan):
        data = mujoco.MjData(model)
        data.qpos[:] = stand(1)[0]
        mujoco.mj_forward(model, data)
        contacts.append(sorted(map(tuple, data.contact.geom[: data.ncon].tolist())))
    floor = set(world.floor_geoms.tolist())
    assert contacts[0] and contacts[1] == [c for c in contacts[0] if pair(plan, *c)]
    assert all(c[0] in floor or c[1] in floor for c in contacts[1])
    # A robot whose MJCF already keeps some of its links from colliding (Apollo's bitmasks) is
    # left as it is: the segments would turn pairs on that its author turned off.
    apollo = make_world(robot_spec("apollo"))
    copy_ = copy.copy(apollo.model)
    assert not near_pairs_apart(copy_, apollo.robot_geoms)
    assert np.array_equal(copy_.geom_contype, apollo.model.geom_contype)
    assert np.array_equal(copy_.geom_conaffinity, apollo.model.geom_conaffinity)


def test_a_fall_is_retried_from_an_earlier_state_and_the_run_still_replays(tmp_path):
    # A reference turned upside down at frame 12 (0.24 s): no controller follows it, so every
    # try falls there; the controller backs up twice (0.1 s, then 0.2 s before the fall), then the
    # fall stands. The exported ctrl, the final tries' included, replays the exported states.
    q = stand(25)
    q[12:, 3:7] = [0.0, 0.0, 1.0, 0.0]
    config = replace(FAST, retries=2, retry_back_s=0.1)
    r = track(q, g1(), config, fps=FPS)
    # Falls at the flip; the planner sees the flipped reference within its horizon and may tip
    # the robot past 60 degrees a frame before it.
    assert r.fell and r.fall_frame in (11, 12) and r.stats["retries"] == 2
    assert np.isfinite(r.root_error_m[: r.fall_frame + 1]).all() and r.simulated[: r.fall_frame + 1].all()
    paths = save_certificate(r, tmp_path)
    assert np.array_equal(replay_certificate(paths["physics_model.xml"], paths["physics.npz"]), r.qpos)
    no_retry = track(q, g1(), replace(config, retries=0), fps=FPS)
    assert no_retry.fell and no_retry.stats["retries"] == 0
    assert no_retry.stats["rollout_steps"] < r.stats["rollout_steps"]  # the retries planned again


def test_a_root_lifted_without_a_jump_fails_as_a_tracking_error():
    q = stand(30)
    q[5:, 2] += 0.4  # the reference floats 40 cm up from frame 5
    r = track(q, g1(), FAST, fps=FPS)
    assert not r.passed
    errors = [f for f in r.failures if f.kind == "tracking_error" and f.robot_body == "pelvis"]
    assert errors and errors[0].depth > 0.3
    # Each time the root got 25 cm from its reference the controller backed up, in vain.
    assert r.stats["retries"] == FAST.retries
    assert track(q, g1(), replace(FAST, retry_lost=False), fps=FPS).stats["retries"] == 0


def test_a_root_teleported_half_a_metre_fails():
    q = stand(30)
    q[8:, 0] += 0.5
    r = track(q, g1(), FAST, fps=FPS)
    assert not r.passed and {f.kind for f in r.failures} & {"tracking_error", "tracking_fall"}


def test_bad_input_is_a_one_line_error():
    q = stand(5)
    with pytest.raises(ShapeError, match="nq=36"):
        track(q[:, :30], g1(), FAST, fps=FPS)
    bad = q.copy()
    bad[2, 9] = np.nan
    with pytest.raises(ShapeError, match="NaN"):
        track(bad, g1(), FAST, fps=FPS)
    sunk = q.copy()
    sunk[:, 2] -= 0.05
    with pytest.raises(ControlMMError, match="starts inside the scene") as err:
        check_trajectory(g1(), sunk, FPS, CheckConfig(physics=True), physics=FAST)
    assert "\n" not in str(err.value) and re.search(r"by \d+\.\d mm", str(err.value))
    with pytest.raises(ControlMMError, match="MjSpec"):  # a bare MjModel cannot be saved as one MJCF file
        track(q, make_world(robot_spec("g1").compile()), FAST, fps=FPS)
    boxed = make_world(robot_spec("g1", [Obstacle("crate", "box", (0.2, 0.2, 0.2), (0.0, 0.0, 0.5))]))
    with pytest.raises(ControlMMError, match="inside crate"):
        track(hold(standing_qpos(boxed.model), 5), boxed, FAST, fps=FPS)


def test_physics_failures_become_smoothness_terms(sample_joints):
    failures = [
        Failure("tracking_fall", 40, 99, "pelvis", None, 0.5),
        Failure("tracking_error", 10, 30, "left_wrist_yaw_link", None, 0.3),
    ]
    body_joints = {"pelvis": ("pelvis", "left_hip", "right_hip"), "left_wrist_yaw_link": ("left_wrist",)}
    terms = feedback_terms(
        failures,
        np.asarray(sample_joints[:60]),
        body_joints=body_joints,
        transform=HumanToWorld(scale=0.78),
        robot_fps=FPS,
        round_index=0,
    )
    names = sorted(t.name for t in terms)
    assert names == ["feedback1:tracking_error:left_wrist_yaw_link", "feedback1:tracking_fall:pelvis"]


def _write(path, qpos):
    np.savez(path, qpos=qpos, fps=np.float64(FPS), robot=np.array("g1"))


@pytest.mark.slow  # end to end: the scene's model is saved and compiled for this one call
def test_validate_physics_writes_a_certificate_that_replays(tmp_path, capsys):
    _write(tmp_path / "stand.npz", stand(20))
    out = tmp_path / "out" / "report.json"
    out.parent.mkdir()
    args = ["validate", str(tmp_path / "stand.npz"), "--out", str(out), "--no-plot", "--no-progress"]
    assert run_cli([*args, "--physics", "--physics-samples", "8"]) == 0
    report = json.loads(out.read_text())
    assert report["passed"] and report["physics"]["passed"] and not report["physics"]["fell"]
    assert len(report["frames"]["physics_root_error_m"]) == 20
    assert "physics: PASSED" in capsys.readouterr().out
    qpos = replay_certificate(out.parent / "physics_model.xml", out.parent / "physics.npz")
    with np.load(out.parent / "physics.npz") as npz:
        assert np.array_equal(qpos, npz["qpos"])
    rows, _ = read_export(out.parent / "robot_physics.csv", "lafan1", fps=CSV_FPS)
    assert rows.tolist() == qpos[::10].tolist()  # 50 fps rows of the 2 ms simulation
    assert run_cli([*args, "--physics"]) == 2  # the files exist: --force is needed


@pytest.mark.parametrize("bad", ["nan", "width", "inside"])
def test_validate_physics_bad_input_exits_2_and_writes_nothing(tmp_path, capsys, bad):
    q = stand(10)
    if bad == "nan":
        q[3, 12] = np.nan
    elif bad == "width":
        q = q[:, :35]
    else:
        q[:, 2] -= 0.05  # 5 cm into the floor from the first frame
    _write(tmp_path / "bad.npz", q)
    out = tmp_path / "out"
    out.mkdir()
    argv = ["validate", str(tmp_path / "bad.npz"), "--physics", "--out", str(out / "r.json"), "--no-progress"]
    err = one_line_error(capsys, argv)
    assert {"nan": "NaN", "width": "(T, nq=36", "inside": "starts inside the scene"}[bad] in err
    assert list(out.iterdir()) == []


def test_report_carries_the_physics_verdict_and_reloads(tmp_path):
    report = check_trajectory(g1(), stand(12), FPS, CheckConfig(physics=True), physics=FAST)
    assert report.physics is not None and report.passed and report.stats["physics"]["passed"]
    assert "physics: PASSED" in report.summary()
    report.save(tmp_path / "report.json")
    loaded = load_report(tmp_path / "report.json")
    assert loaded.stats["physics"]["fell"] is False and "physics: PASSED" in loaded.summary()
    assert loaded.frames["physics_root_error_m"].shape == (12,)


def test_the_saved_model_is_cached_per_model_and_an_unusable_entry_is_rebuilt(tmp_path, monkeypatch):
    # Saving G1 + floor as one 12 MB MJCF takes MuJoCo seconds: a later process (here: a new
    # world of the same model) reads the text from the user's cache and compiles it instead.
    monkeypatch.setenv(CACHE_ENV, str(tmp_path))
    gains = (CheckConfig().tracking_kp, CheckConfig().tracking_kd)
    first, xml, _ = physics_models(make_world(robot_spec("g1")), 5, *gains)
    entries = list((tmp_path / "physics").glob("*.xml"))
    assert len(entries) == 1 and entries[0].read_text() == xml
    assert entries[0].stem == model_key(g1().model, "pelvis", *[f.name for f in g1().feet])
    again, xml_again, _ = physics_models(make_world(robot_spec("g1")), 5, *gains)
    assert xml_again == xml and np.array_equal(again.body_mass, first.body_mass)
    # Another robot is another entry; the same robot's key does not depend on the build.
    assert model_key(make_world(robot_spec("h1")).model) != model_key(g1().model)
    assert model_key(make_world(robot_spec("g1")).model) == model_key(g1().model)
    # A damaged entry (here: a model without the cost's sensors) is rebuilt and rewritten.
    entries[0].write_text(robot_spec("g1").to_xml())
    rebuilt, xml_rebuilt, _ = physics_models(make_world(robot_spec("g1")), 5, *gains)
    assert xml_rebuilt == xml and entries[0].read_text() == xml
    # No persistent cache when the variable is empty.
    monkeypatch.setenv(CACHE_ENV, "")
    assert ModelTextCache().path("x") is None


def test_the_model_cache_keeps_the_most_recently_used_entries(tmp_path):
    cache = ModelTextCache(tmp_path)
    for i in range(MAX_ENTRIES + 2):
        cache.put(f"k{i:02d}", f"<mujoco model='{i}'/>")
        os.utime(tmp_path / "physics" / f"k{i:02d}.xml", (i, i))  # distinct, increasing times
    assert cache.get("k02") == "<mujoco model='2'/>"  # read: now the most recent
    cache.put("new", "<mujoco/>")
    kept = sorted(p.stem for p in (tmp_path / "physics").glob("*.xml"))
    assert len(kept) == MAX_ENTRIES and "new" in kept and "k02" in kept
    assert "k00" not in kept and "k01" not in kept and "k03" not in kept
    assert cache.get("k00") is None
    (tmp_path / "physics" / "bad.xml").write_text("not a model")
    assert cache.get("bad") is None
