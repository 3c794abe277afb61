"""Procedural motion corpus in HumanML3D format."""
