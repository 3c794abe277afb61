"""What the velocity and acceleration terms act on, and their weights per frame pair.

The temporal terms penalise finite differences of x(t) = (root position - reference, unwrapped
root rotation, joint angles), (T, n): the reference is the smoothed human pelvis
(:func:`retarget.reference.reference_root`), so the root may accelerate as the human's does
(a jump's arc) but not on its own. Frames of different spans (independent problems side by
side) are not coupled.
"""

from __future__ import annotations

import numpy as np

from retarget.costs.base import Configuration

REFERENCE_FPS = 20.0
"""Frame rate (Hz) the temporal weights are given at (rescaled for other rates)."""


def temporal_values(cfg: Configuration, ref_x: np.ndarray) -> np.ndarray:
    """(T, n) the sequences the temporal terms act on (``ref_x`` (T, n): their reference)."""
    return np.concatenate([cfg.root_pos, cfg.root_unwrapped, cfg.q], axis=1) - ref_x


def coordinate_weights(n: int, root: float, joint: float | np.ndarray) -> np.ndarray:
    """(n,) a weight per velocity coordinate: ``root`` for the 6 root ones, ``joint`` (a
    number or (n - 6,) one per joint) for the joints."""
    return np.concatenate([np.full(6, root), np.broadcast_to(joint, (n - 6,))])


def coupled_pairs(span: np.ndarray) -> np.ndarray:
    """(T - 1,) True where frames t and t + 1 belong to the same span."""
    return span[1:] == span[:-1]
