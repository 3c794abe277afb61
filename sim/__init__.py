"""Simulation checks: replay robot trajectories in MuJoCo scenes and report failures."""
