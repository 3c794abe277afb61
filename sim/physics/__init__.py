"""Physics execution check: a predictive controller runs the trajectory in MuJoCo, judged on what happened.

``track(trajectory, world, config) -> PhysicsResult`` (:mod:`sim.physics.track`); the
certificate files (``physics.npz``, ``physics_model.xml``, ``robot_physics.csv``) and their
replay in :mod:`sim.physics.certificate`. See ``docs/simulation-checks.md`` ("Physics execution").
"""

from sim.physics.certificate import CERTIFICATE_FILES, replay_certificate, save_certificate
from sim.physics.config import PhysicsConfig
from sim.physics.result import PhysicsResult
from sim.physics.track import check_start, track

__all__ = [
    "CERTIFICATE_FILES",
    "PhysicsConfig",
    "PhysicsResult",
    "check_start",
    "replay_certificate",
    "save_certificate",
    "track",
]
