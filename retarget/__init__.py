"""Retargeting: human joints (HumanML3D, Y up) -> humanoid robot qpos (MuJoCo, Z up).

Public API::

    from retarget import retarget_motion, robot_scale, RobotTrajectory
    traj = retarget_motion(motion, robot="g1", fps=50)   # or a humanoid MJCF .xml, or a mapping .json
    traj.save("out/walk")                                 # walk.csv, walk.npz, walk.json
    save_trajectory(traj, "out/walk", ["lafan1", "beyondmimic", "gmr", "qpos"])  # + tracker formats
"""

from retarget.automap import describe_mapping, infer_mapping, mapping_file_text
from retarget.catalog import RobotInfo, describe_robot, robot_catalog
from retarget.exports import EXPORT_FORMATS, read_export, save_trajectory
from retarget.mapping import Mapping, load_mapping, packaged_mappings
from retarget.retarget_motion import check_fps, retarget_motion, robot_scale
from retarget.robot_files import load_robot_spec, robot_mjcf_path
from retarget.robot_model import RobotModel, load_robot
from retarget.robots import DEFAULT_ROBOT, available_robots, robot_mjcf, robot_scene
from retarget.solver_config import SolverConfig
from retarget.trajectory import RobotTrajectory

__all__ = [
    "DEFAULT_ROBOT",
    "EXPORT_FORMATS",
    "Mapping",
    "RobotInfo",
    "RobotModel",
    "RobotTrajectory",
    "SolverConfig",
    "available_robots",
    "check_fps",
    "describe_mapping",
    "describe_robot",
    "infer_mapping",
    "load_mapping",
    "load_robot",
    "load_robot_spec",
    "mapping_file_text",
    "packaged_mappings",
    "read_export",
    "retarget_motion",
    "robot_catalog",
    "robot_mjcf",
    "robot_mjcf_path",
    "robot_scale",
    "robot_scene",
    "save_trajectory",
]
