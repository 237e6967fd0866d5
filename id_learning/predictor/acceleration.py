"""Causal acceleration estimate for a reference that carries positions and velocities only.

The estimate is the backward difference of the velocity over the stamps,

    a_k = (v_k - v_{k-1}) / (t_k - t_{k-1}),    a_0 = 0 (no history yet),

optionally smoothed by a first-order low-pass with cut-off f_c (exact discretisation of
1 / (1 + s / (2 pi f_c)) for a held input over each step):

    y_k = y_{k-1} + alpha_k (a_k - y_{k-1}),    alpha_k = 1 - exp(-2 pi f_c (t_k - t_{k-1})).

It lags the central differences the models were trained on by half a period (plus the filter's
delay); a controller reference that carries accelerations avoids both. The online estimator and
the batch function give the same numbers, so an offline prediction can reproduce the online one.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ['CausalAccelerationEstimator', 'causal_acceleration']

NS_PER_S = 1e9


def _alpha(cutoff_hz: float, dt_s: float) -> float:
    return 1.0 if cutoff_hz <= 0 else 1.0 - math.exp(-2.0 * math.pi * cutoff_hz * dt_s)


class CausalAccelerationEstimator:
    """Sample-by-sample acceleration estimate [rad/s^2] from velocities [rad/s] and stamps [ns]."""

    def __init__(self, cutoff_hz: float = 0.0) -> None:
        """Set the low-pass cut-off [Hz]; 0 keeps the raw backward difference."""
        self.cutoff_hz = cutoff_hz
        self._last_stamp_ns: int | None = None
        self._last_v: np.ndarray | None = None
        self._last_a: np.ndarray | None = None

    def reset(self) -> None:
        """Forget the history: the next sample gets a = 0."""
        self._last_stamp_ns = None
        self._last_v = None
        self._last_a = None

    def update(self, stamp_ns: int, v: np.ndarray) -> np.ndarray:
        """The estimate at this sample, (n,) [rad/s^2]; stamps must increase (caller checks)."""
        if self._last_stamp_ns is None or self._last_v is None or self._last_a is None:
            a = np.zeros_like(v, dtype=float)
        else:
            dt_s = (stamp_ns - self._last_stamp_ns) / NS_PER_S
            raw = (v - self._last_v) / dt_s
            a = self._last_a + _alpha(self.cutoff_hz, dt_s) * (raw - self._last_a)
        self._last_stamp_ns = stamp_ns
        self._last_v = np.array(v, dtype=float)
        self._last_a = a
        return a


def causal_acceleration(
    stamps_ns: np.ndarray, v: np.ndarray, cutoff_hz: float = 0.0
) -> np.ndarray:
    """The estimator's output for a whole run at once.

    Args:
        stamps_ns: (N,) strictly increasing stamps [ns].
        v: (N, n) velocities [rad/s].
        cutoff_hz: low-pass cut-off [Hz], 0 for none.

    Returns:
        (N, n) accelerations [rad/s^2], equal to feeding the samples to
        CausalAccelerationEstimator one by one.
    """
    estimator = CausalAccelerationEstimator(cutoff_hz)
    v = np.asarray(v, dtype=float)
    out = np.empty_like(v)
    for k, stamp in enumerate(np.asarray(stamps_ns, dtype=np.int64).tolist()):
        out[k] = estimator.update(stamp, v[k])
    return out
