"""The core's input type: one reference sample as received (light: no torch, no models)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ['ReferenceSample']


@dataclass(frozen=True, eq=False)
class ReferenceSample:
    """One reference sample as received, in the sender's joint order.

    Attributes:
        stamp_ns: header stamp [ns].
        names: joint names of the columns.
        q: (m,) positions [rad].
        v: (m,) velocities [rad/s].
        a: (m,) accelerations [rad/s^2], or None to estimate them causally.
        lacks: what the message lacked that the sample would be made of, in words (e.g. 'the
            JointTrajectory has no points'), or None; the core refuses such a sample as a shape
            error naming it.
    """

    stamp_ns: int
    names: tuple[str, ...]
    q: np.ndarray
    v: np.ndarray
    a: np.ndarray | None = None
    lacks: str | None = None
