"""Retargeting: human joints (HumanML3D, Y up) -> humanoid robot qpos (MuJoCo, Z up)."""

from retarget.robots import DEFAULT_ROBOT, available_robots, robot_mjcf, robot_scene

__all__ = ["DEFAULT_ROBOT", "available_robots", "robot_mjcf", "robot_scene"]
