"""Time curves for procedural motion: easing, keyframes, integration and gentle noise.

Times are in seconds; a clip of T frames at ``fps`` has times ``arange(T) / fps``.
"""

from __future__ import annotations

from typing import overload

import numpy as np
from scipy.interpolate import CubicHermiteSpline, PchipInterpolator


def smoothstep(x: np.ndarray) -> np.ndarray:
    """3x^2 - 2x^3 on [0, 1] (clamped outside): zero slope at both ends."""
    x = np.clip(np.asarray(x, dtype=np.float64), 0.0, 1.0)
    return x * x * (3.0 - 2.0 * x)


def minjerk(x: np.ndarray) -> np.ndarray:
    """Minimum-jerk profile 10x^3 - 15x^4 + 6x^5 on [0, 1] (clamped): zero velocity and
    acceleration at both ends."""
    x = np.clip(np.asarray(x, dtype=np.float64), 0.0, 1.0)
    return x * x * x * (10.0 + x * (-15.0 + 6.0 * x))


def ramp(t: np.ndarray, t0: float, t1: float) -> np.ndarray:
    """0 before ``t0``, 1 after ``t1``, a minimum-jerk ease between."""
    if t1 <= t0:
        return (np.asarray(t) >= t0).astype(np.float64)
    return minjerk((np.asarray(t, dtype=np.float64) - t0) / (t1 - t0))


def window(t: np.ndarray, t0: float, t1: float, rise: float, fall: float | None = None) -> np.ndarray:
    """Smooth on/off envelope: 0 -> 1 over [t0, t0+rise], 1 -> 0 over [t1-fall, t1]."""
    fall = rise if fall is None else fall
    return ramp(t, t0, t0 + rise) * (1.0 - ramp(t, t1 - fall, t1))


def keyframes(t: np.ndarray, times: list[float] | np.ndarray, values: list | np.ndarray) -> np.ndarray:
    """Minimum-jerk interpolation through keyframes, holding before the first and after the last.

    Args:
        t: (T,) query times.
        times: (K,) increasing key times.
        values: (K, ...) key values.

    Returns:
        (T, ...) values; each segment eases in and out (the motion rests at every key).
    """
    times = np.asarray(times, dtype=np.float64)
    values = np.asarray(values, dtype=np.float64)
    t = np.asarray(t, dtype=np.float64)
    out = np.broadcast_to(values[0], t.shape + values.shape[1:]).copy()
    for k in range(1, len(times)):
        w = ramp(t, times[k - 1], times[k]).reshape(t.shape + (1,) * (values.ndim - 1))
        seg = (t >= times[k - 1]).reshape(w.shape)
        out = np.where(seg, values[k - 1] + w * (values[k] - values[k - 1]), out)
    return out


def smooth_keys(t: np.ndarray, times: list[float] | np.ndarray, values: list | np.ndarray) -> np.ndarray:
    """Shape-preserving (PCHIP) interpolation through keyframes, holding before the first and
    after the last: unlike :func:`keyframes` the motion flows through intermediate keys (it only
    rests at the first and last key and where the values turn back), so a sit-down or a bow has
    no pauses.

    Args:
        t: (T,) query times.
        times: (K,) increasing key times (K >= 2).
        values: (K, ...) key values.

    Returns:
        (T, ...) values.
    """
    times = np.asarray(times, dtype=np.float64)
    values = np.asarray(values, dtype=np.float64)
    tq = np.clip(np.asarray(t, dtype=np.float64), times[0], times[-1])
    slopes = PchipInterpolator(times, values, axis=0).derivative()(times)
    slopes[0] = 0.0
    slopes[-1] = 0.0
    return CubicHermiteSpline(times, values, slopes, axis=0)(tq)


def integrate(rate: np.ndarray, fps: float) -> np.ndarray:
    """Trapezoidal running integral of a rate sampled at ``fps`` (value 0 at frame 0)."""
    rate = np.asarray(rate, dtype=np.float64)
    steps = 0.5 * (rate[1:] + rate[:-1]) / fps
    return np.concatenate([np.zeros((1,) + rate.shape[1:]), np.cumsum(steps, axis=0)], axis=0)


def gentle_noise(
    rng: np.random.Generator,
    t: np.ndarray,
    amplitude: float,
    freq: tuple[float, float] = (0.15, 0.6),
    terms: int = 3,
) -> np.ndarray:
    """A smooth random signal: a sum of ``terms`` sinusoids with random frequencies (Hz) and
    phases, scaled to peak amplitude about ``amplitude``. For idle sway and breathing."""
    f = rng.uniform(freq[0], freq[1], size=terms)
    phase = rng.uniform(0.0, 2.0 * np.pi, size=terms)
    weight = rng.uniform(0.5, 1.0, size=terms)
    sig = (weight[:, None] * np.sin(2.0 * np.pi * f[:, None] * np.asarray(t)[None] + phase[:, None])).sum(0)
    return amplitude * sig / weight.sum()


@overload
def wrap_angle(a: float) -> float: ...


@overload
def wrap_angle(a: np.ndarray) -> np.ndarray: ...


def wrap_angle(a: float | np.ndarray) -> float | np.ndarray:
    """Wrap angles (rad) to (-pi, pi]: a float for a float, an array of the same shape for an array."""
    return np.angle(np.exp(1j * np.asarray(a, dtype=np.float64)))
