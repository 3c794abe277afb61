"""Human foot contact from HumanML3D joints: stance frames, heel and toe contacts, lock ramps.

A foot is in *stance* when it is low, flat and slow (:func:`detect_stance`); it is in
*contact* when in stance or with its heel or toe down (:func:`detect_contacts`: heel strikes,
toe-offs, tiptoes). Around contact a foot lock ramps in and out (:func:`lock_ramp`), faded by
how slowly the human foot moves (:func:`slowness`). All in the human frame (metres, Y up).
"""

from __future__ import annotations

import numpy as np
from scipy.ndimage import gaussian_filter1d

from controlmm.motion.skeleton import JOINT_INDEX

STANCE_ANKLE_HEIGHT = 0.085
STANCE_TOE_HEIGHT = 0.05
STANCE_SPEED = 0.35
"""Human stance test (HumanML3D metres, m/s): ankle and toe low and both slower than this."""

CONTACT_RISE = 0.02
"""A heel (ankle) or toe joint within this of its flat-stance height (HumanML3D metres) may be
on the floor."""
CONTACT_SPEED = 0.5
"""...and is on it when slower than this (m/s; the ankle circles the heel during a heel strike)."""

STANCE_MIN_SECONDS = 0.15
STANCE_SMOOTH_SECONDS = 0.075
MERGE_GAP_SECONDS = 0.4
MERGE_DISTANCE = 0.05
"""Two stances of a foot closer than this in time (s) and place (m), with the foot kept low, are one."""
RAMP_SECONDS = 0.1
"""Foot locks ramp in and out over this time (s); horizontally they hold this much longer."""
RAMP_SPEED = 1.0
"""The ramp of a lock fades with the human foot's horizontal speed, to nothing at this (m/s)."""


def true_runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """[start, end) runs of True."""
    padded = np.concatenate([[False], mask, [False]])
    edges = np.flatnonzero(np.diff(padded.astype(int)))
    return list(zip(edges[::2], edges[1::2], strict=True))


def smoothed_foot(joints: np.ndarray, fps: float, side: str) -> tuple[np.ndarray, np.ndarray]:
    """(ankle, toe) positions (T, 3) of one foot, smoothed over ~STANCE_SMOOTH_SECONDS when T >= 4."""
    a, t = joints[:, JOINT_INDEX[f"{side}_ankle"]], joints[:, JOINT_INDEX[f"{side}_foot"]]
    if len(joints) >= 4:
        sigma = STANCE_SMOOTH_SECONDS * fps
        a = gaussian_filter1d(a.astype(np.float64), sigma, axis=0, mode="nearest")
        t = gaussian_filter1d(t.astype(np.float64), sigma, axis=0, mode="nearest")
    return a, t


def horizontal_speed(p: np.ndarray, fps: float, combine: np.ufunc) -> np.ndarray:
    """(T,) horizontal speed (m/s) of points (T, 3), T >= 2: each frame ``combine``s its arriving
    and leaving steps (np.maximum: fast on either side; np.minimum: slow on either side)."""
    d = np.linalg.norm(np.diff(p[:, [0, 2]], axis=0), axis=1) * fps
    return combine(np.concatenate([d[:1], d]), np.concatenate([d, d[-1:]]))


def detect_stance(joints: np.ndarray, fps: float, side: str) -> np.ndarray:
    """Human stance frames (T,) bool of one foot from HumanML3D joints (metres, Y up).

    A stance frame has the ankle below 8.5 cm, the toe below 5 cm and both moving slower than
    0.35 m/s horizontally (positions smoothed over ~0.075 s first, so that jittery input
    still plants its feet); gaps of one frame are filled and runs shorter than 0.15 s dropped.
    """
    a, t = smoothed_foot(joints, fps, side)
    n = len(joints)
    if n < 2:
        return np.array([a[0, 1] < STANCE_ANKLE_HEIGHT and t[0, 1] < STANCE_TOE_HEIGHT])
    ok = (
        (a[:, 1] < STANCE_ANKLE_HEIGHT)
        & (t[:, 1] < STANCE_TOE_HEIGHT)
        & (horizontal_speed(a, fps, np.maximum) < STANCE_SPEED)
        & (horizontal_speed(t, fps, np.maximum) < STANCE_SPEED)
    )
    for s, e in true_runs(~ok):  # fill one-frame gaps inside stance
        if 0 < s and e < n and e - s <= 1:
            ok[s:e] = True
    min_len = max(2, int(round(STANCE_MIN_SECONDS * fps)))
    for s, e in true_runs(ok):
        if e - s < min_len:
            ok[s:e] = False
    # One stance when the foot comes back to (almost) the same place soon after leaving it.
    runs = true_runs(ok)
    foot = (a + t)[:, [0, 2]] / 2
    for (s0, e0), (s1, e1) in zip(runs[:-1], runs[1:], strict=True):
        if (s1 - e0) <= MERGE_GAP_SECONDS * fps:
            moved = np.linalg.norm(foot[s0:e0].mean(axis=0) - foot[s1:e1].mean(axis=0))
            low = np.all(a[e0:s1, 1] < STANCE_ANKLE_HEIGHT + 0.03) and np.all(
                t[e0:s1, 1] < STANCE_TOE_HEIGHT + 0.03
            )
            if moved < MERGE_DISTANCE and low:
                ok[e0:s1] = True
    return ok


def lock_ramp(stance: np.ndarray, fps: float, hold: int = 0) -> np.ndarray:
    """1 in stance (and ``hold`` frames around it), then falling linearly to 0 over RAMP_SECONDS."""
    r = max(1, int(round(RAMP_SECONDS * fps)))
    dist = np.full(len(stance), np.inf)
    idx = np.flatnonzero(stance)
    if len(idx):
        frames = np.arange(len(stance))
        dist = np.abs(frames[:, None] - idx[None, :]).min(axis=1)
    return np.clip(1.0 - np.maximum(dist - hold, 0) / (r + 1), 0.0, 1.0)


def detect_contacts(
    joints: np.ndarray, fps: float, side: str, stance: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Human foot contact per frame: (contact, heel_down, toe_down), each (T,) bool.

    ``heel_down``: the ankle within ``CONTACT_RISE`` of its flat-stance height and slower than
    ``CONTACT_SPEED`` (heel strike, flat foot); ``toe_down``: the toe joint within
    ``CONTACT_RISE`` of its flat-stance height and slower than ``STANCE_SPEED`` (the pivot of
    a toe-off, tiptoes). ``contact`` = flat stance (:func:`detect_stance`) or either, with
    one-frame gaps filled and one-frame runs dropped. Heights are relative to the clip's own
    flat-stance heights of that foot (HumanML3D puts the floor at the lowest joint).
    """
    st = detect_stance(joints, fps, side) if stance is None else stance
    a, t = smoothed_foot(joints, fps, side)
    n = len(joints)
    if n < 2:
        return st.copy(), st.copy(), st.copy()

    low = max(1, n // 20)
    a_ref = float(np.median(a[st, 1])) if st.any() else float(np.sort(a[:, 1])[:low].mean())
    t_ref = float(np.median(t[st, 1])) if st.any() else float(np.sort(t[:, 1])[:low].mean())
    heel = (a[:, 1] < a_ref + CONTACT_RISE) & (horizontal_speed(a, fps, np.minimum) < CONTACT_SPEED)
    toe = (t[:, 1] < t_ref + CONTACT_RISE) & (horizontal_speed(t, fps, np.minimum) < STANCE_SPEED)
    contact = st | heel | toe
    for s, e in true_runs(~contact):  # fill one-frame gaps
        if 0 < s and e < n and e - s <= 1:
            contact[s:e] = True
    for s, e in true_runs(contact):
        if e - s < 2:
            contact[s:e] = False
    return contact, heel & contact, toe & contact


def slowness(joints: np.ndarray, fps: float, side: str) -> np.ndarray:
    """(T,) 1 for a human foot at rest horizontally, falling to 0 at ``RAMP_SPEED``."""
    feet = joints[:, [JOINT_INDEX[f"{side}_ankle"], JOINT_INDEX[f"{side}_foot"]]][..., [0, 2]]
    if len(feet) < 2:
        return np.ones(len(feet))
    step = np.linalg.norm(np.diff(feet, axis=0), axis=2).max(axis=1) * fps  # (T-1,)
    speed = np.minimum(np.r_[step[:1], step], np.r_[step, step[-1:]])  # arriving at / leaving rest counts
    return np.clip(1.0 - speed / RAMP_SPEED, 0.0, 1.0)
