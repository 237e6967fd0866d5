"""The consistency gate of a predictor stream, with the accelerations it is given checked too.

``dataset.consistency`` compares consecutive velocities with the given accelerations, allowing
2x the acceleration limit: a sender that fills the accelerations with zeros while the arm
accelerates (up to 3 rad/s^2 on the MABI's first joint) passed it, and the model was served
accelerations 19 % of joint 1's torque limit away from the motion's. Here the velocities' own
change over the gate's window (W samples back, at most ``WINDOW_S``, D long, steps h_i) is
compared with the trapezoid integral I of the given accelerations a over it; per joint:

    |v_k - v_(k-W) - I|  <=  s L (max a - min a)  +  s sum(h_i |a_(i+1) - a_i|) / 2
                             +  r |I|  +  S max |a|  +  f V  +  f A D

over the samples of the window, s the gate's ``scale``, the other letters its own
(``dataset.consistency``: L the lag, r the scale error, S the hold, f the floor share, V the
velocity limit, A twice the acceleration limit). Why each term:

- ``s L (max a - min a)``: accelerations that lag or lead their velocities by up to L (a filter,
  a central difference) integrate to the velocities' change shifted by L, off by at most L times
  the accelerations' change;
- ``s sum(h |da|) / 2``: the trapezoid rule's largest error where a moves monotonically within
  each step;
- ``r |I|``, ``S max |a|``: a scale error between the signals, a signal held up to S;
- ``f V``: noise and quantisation of the velocities, the gate's own floor (the twins' velocity
  noise is 1e-3 rad/s, 1/85 of it on joint 1); ``f A D``: of the accelerations over the window.

Every term but the floors grows with the accelerations given, so accelerations that do not move
while the velocities do are held to the floors: zeros on the MABI's joint 1 fail where it
accelerates by more than about 2 rad/s^2 (joint 2: 1.65, joint 3: 1.7; the floor over a 50 ms
window), and a stream with true accelerations uses a small share of it (measured on the shipped
bag's reference: ``test/predictor/test_acceleration_gate.py``). A sample that fails gets no model
torque (the hold output, as any inconsistency). Only samples whose window carries accelerations
throughout are checked: without them the predictor estimates its own.
"""

from __future__ import annotations

from collections import deque

import numpy as np

from id_learning.dataset.consistency import (
    FLOOR_SHARE,
    ConsistencyStream,
    Inconsistency,
    KinematicConsistency,
)

__all__ = ['StreamGate', 'acceleration_terms']


def acceleration_terms(
    gate: KinematicConsistency, dt_s: np.ndarray, dv: np.ndarray, a: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(mismatch, tolerance, integral) of a window's velocity change against its accelerations.

    Args:
        gate: the gate whose settings the tolerance is derived from.
        dt_s: (W, 1) the steps between the window's samples [s].
        dv: (n,) the velocities' change over the window [rad/s].
        a: (W + 1, n) the accelerations of its samples [rad/s^2].
    """
    integral: np.ndarray = (0.5 * (a[1:] + a[:-1]) * dt_s).sum(axis=0)
    tolerance = (
        gate.scale * gate.lag_s * (a.max(axis=0) - a.min(axis=0))
        + gate.scale * 0.5 * (dt_s * np.abs(np.diff(a, axis=0))).sum(axis=0)
        + gate.relative * np.abs(integral)
        + gate.stale_s * np.abs(a).max(axis=0)
        + gate.floor_v
        + FLOOR_SHARE * gate.accel * float(dt_s.sum())
    )
    return np.abs(dv - integral), tolerance, integral


class StreamGate(ConsistencyStream):
    """``ConsistencyStream`` with the given accelerations checked over its window (see above)."""

    def __init__(self, gate: KinematicConsistency) -> None:
        super().__init__(gate)
        #: (stamp [ns], v, a or None) of the last window, oldest first.
        self._given: deque[tuple[int, np.ndarray, np.ndarray | None]] = deque(maxlen=gate.window)

    def reset(self) -> None:
        """Forget the history: the next sample is compared with none."""
        super().reset()
        self._given.clear()

    def check(
        self, stamp_ns: int, q: np.ndarray, v: np.ndarray, a: np.ndarray | None
    ) -> Inconsistency | None:
        """The worst failing joint of this sample against the history, or None when it agrees."""
        found = super().check(stamp_ns, q, v, a)
        return found if found is not None else self._accelerations(stamp_ns, v, a)

    def _accelerations(
        self, stamp_ns: int, v: np.ndarray, a: np.ndarray | None
    ) -> Inconsistency | None:
        given = self._given
        if a is None or not given or any(entry[2] is None for entry in given):
            return None
        stamps = np.array([entry[0] for entry in given] + [stamp_ns], dtype=np.int64)
        steps_s = (np.diff(stamps) * 1e-9)[:, None]
        accelerations = np.array([entry[2] for entry in given] + [a], dtype=float)
        dv = v - given[0][1]
        mismatch, tolerance, integral = acceleration_terms(self.gate, steps_s, dv, accelerations)
        ratio = mismatch / tolerance
        j = int(np.argmax(ratio))
        if not ratio[j] > 1.0:
            return None
        span = float(steps_s.sum())
        return Inconsistency(
            self.gate.joints[j], 'velocity', float(dv[j]), float(integral[j]), float(tolerance[j]),
            span,
        )  # fmt: skip

    def push(self, stamp_ns: int, q: np.ndarray, v: np.ndarray, a: np.ndarray | None) -> None:
        """Append a sample to the history (after ``check``, whether it passed or not)."""
        super().push(stamp_ns, q, v, a)
        self._given.append((stamp_ns, v, a))
