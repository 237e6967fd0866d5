"""Signal operations on uniformly sampled columns: zero-phase low-pass, derivative, time shift.

All work on arrays (N, n), one column per joint, sampled every ``period_s`` seconds.
``scipy.signal`` is imported on first use: it takes about a second, which the ROS nodes that
import this module (the replay) would otherwise pay at start-up.
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np

from id_learning.errors import DatasetError

__all__ = ['butterworth', 'differentiate', 'lowpass', 'time_shifted']


@lru_cache(maxsize=128)
def butterworth(cutoff_hz: float, period_s: float, order: int) -> np.ndarray:
    """Second-order sections of a Butterworth low-pass (designed once per setting)."""
    from scipy import signal

    sos: np.ndarray = signal.butter(order, cutoff_hz, btype='low', fs=1.0 / period_s, output='sos')
    return sos


def lowpass(x: np.ndarray, cutoff_hz: np.ndarray, period_s: float, order: int = 4) -> np.ndarray:
    """Zero-phase Butterworth low-pass of each column of x (N, n) with its own cut-off [Hz].

    Forward and backward (``scipy.signal.sosfiltfilt`` with its default padding), so the
    attenuation is squared and there is no phase lag.

    Raises:
        DatasetError: too few samples for the filter's padding.
    """
    from scipy import signal

    x = np.asarray(x, dtype=float)
    cutoff_hz = np.asarray(cutoff_hz, dtype=float)
    out = np.empty_like(x)
    # Columns that share a cut-off are filtered together (one call over a 2-D block).
    for cutoff in np.unique(cutoff_hz):
        columns = np.flatnonzero(cutoff_hz == cutoff)
        sos = butterworth(float(cutoff), period_s, order)
        try:
            out[:, columns] = signal.sosfiltfilt(sos, x[:, columns], axis=0)
        except ValueError as err:
            raise DatasetError(
                f'{len(x)} samples are too few for the {cutoff:g} Hz low-pass '
                f'of column {int(columns[0])}: {err}'
            ) from err
    return out


def differentiate(x: np.ndarray, period_s: float) -> np.ndarray:
    """Time derivative of uniformly sampled columns by central differences (second-order edges)."""
    out: np.ndarray = np.gradient(np.asarray(x, dtype=float), period_s, axis=0, edge_order=2)
    return out


def time_shifted(x: np.ndarray, delay_s: float, period_s: float) -> np.ndarray:
    """Columns x (N, ...) sampled every ``period_s``, at each sample's time less ``delay_s``.

    A cubic spline through the samples (for signals well inside the sampling band, such as
    filtered torques); the first ``delay_s`` are extrapolated.
    """
    from scipy import interpolate

    x = np.asarray(x, dtype=float)
    if len(x) < 4:
        raise DatasetError(f'time_shifted: {len(x)} samples are too few for a cubic spline')
    t = np.arange(len(x)) * period_s
    shifted: np.ndarray = interpolate.CubicSpline(t, x, axis=0)(t - delay_s)
    return shifted
