"""Signal operations on uniformly sampled columns: the zero-phase low-pass and differentiation.

Both work on arrays (N, n), one column per joint, sampled every ``period_s`` seconds.
``scipy.signal`` is imported on first use: it takes about a second, which the ROS nodes that
import this module (the replay) would otherwise pay at start-up.
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np

from id_learning.errors import DatasetError

__all__ = ['butterworth', 'differentiate', 'lowpass']


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
    return np.gradient(np.asarray(x, dtype=float), period_s, axis=0, edge_order=2)
