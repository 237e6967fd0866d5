"""The reference a controller would send, rebuilt from recorded joint states (for the replay).

A controller's reference (q, v, a) is smooth: it comes from the interpolator, not from encoders.
Recorded joint states carry measurement noise; models are fitted and scored on inputs made from
them by an input definition (``dataset.inputs``: a controller's, by default, whose velocity
smoothing sits far above the motion's band). The replay rebuilds the reference the same way, over
the whole replayed span at once (it knows the future, as the interpolator does):

1. q and v low-passed (zero-phase Butterworth) as the input definition says, or kept as recorded;
2. a = central differences of v over the actual stamps (second-order one-sided at both ends).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from id_learning.dataset.inputs import InputDefinition
from id_learning.errors import DatasetError

__all__ = ['Reference', 'reference_from_states']

NS_PER_S = 1e9


@dataclass(frozen=True, eq=False)
class Reference:
    """Reference samples in the recorded joint order.

    Attributes:
        joints: joint names (column order).
        stamps_ns: (N,) stamps [ns].
        q, v, a: (N, n) positions [rad], velocities [rad/s], accelerations [rad/s^2].
    """

    joints: tuple[str, ...]
    stamps_ns: np.ndarray
    q: np.ndarray
    v: np.ndarray
    a: np.ndarray


def reference_from_states(
    joints: tuple[str, ...],
    stamps_ns: np.ndarray,
    q: np.ndarray,
    v: np.ndarray,
    *,
    period_s: float,
    inputs: InputDefinition | None = None,
) -> Reference:
    """Positions, velocities and accelerations of each sample of a recorded run.

    Args:
        joints: joint names of the columns.
        stamps_ns: (N,) strictly increasing stamps [ns].
        q: (N, n) positions [rad].
        v: (N, n) velocities [rad/s].
        period_s: the sample period the filters assume [s].
        inputs: how q and v are smoothed (its cut-offs in ``joints`` order); None keeps them as
            recorded.

    Raises:
        DatasetError: fewer than 3 samples, stamps not increasing, or too few for the filter.
    """
    stamps = np.asarray(stamps_ns, dtype=np.int64)
    if len(stamps) < 3:
        raise DatasetError(f'a reference needs at least 3 samples, got {len(stamps)}')
    if (np.diff(stamps) <= 0).any():
        raise DatasetError('reference stamps must increase strictly')
    q = np.asarray(q, dtype=float)
    v = np.asarray(v, dtype=float)
    if inputs is not None:
        smoothed = inputs.motion(q, v, period_s)
        q, v = smoothed.q, smoothed.v
    t_s = (stamps - stamps[0]) / NS_PER_S
    a = np.gradient(v, t_s, axis=0, edge_order=2)
    return Reference(tuple(joints), stamps, q, v, a)
