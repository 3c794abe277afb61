"""Simulation checks: replay robot trajectories in MuJoCo scenes and report failures.

``check_trajectory(scene, qpos, fps, config=CheckConfig()) -> Report`` runs the kinematic
replay check (obstacle/floor penetration, self-collision, joint position and velocity limits,
stance-foot sliding, floating), the inverse-dynamics feasibility check (non-physical root
wrench, joint torques), optionally a PD-tracking replay in physics and, with
``CheckConfig(physics=True)``, the physics execution check: ``track(trajectory, world, config)
-> PhysicsResult`` drives the robot through its actuators with a predictive controller and
exports a replayable certificate (``sim.physics``). See ``docs/simulation-checks.md``.
"""

from sim.check import check_pose, check_trajectory
from sim.config import PUBLISHED_VELOCITY_LIMITS, CheckConfig
from sim.failures import KINDS, Failure
from sim.physics import PhysicsConfig, PhysicsResult, replay_certificate, save_certificate, track
from sim.plot import plot_report
from sim.report import Report, load_report
from sim.world import CheckWorld, make_world

__all__ = [
    "KINDS",
    "PUBLISHED_VELOCITY_LIMITS",
    "CheckConfig",
    "CheckWorld",
    "Failure",
    "PhysicsConfig",
    "PhysicsResult",
    "Report",
    "check_pose",
    "check_trajectory",
    "load_report",
    "make_world",
    "plot_report",
    "replay_certificate",
    "save_certificate",
    "track",
]
