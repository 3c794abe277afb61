"""Scene library (MJCF worlds, Z up) and signed distance functions from MuJoCo geometry."""
