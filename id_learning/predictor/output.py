"""What leaves the predictor: clamped to the torque limits, slew-limited, held when unsure.

Every published torque moves from the one before by at most

    slew * min(max(stamp - last stamp, T), stale threshold)    per joint,
    slew = torque limit / torque_rise_s,

T the IPO period: no feed-forward a valid reference needs rises from zero to the drive's torque
limit faster than ``torque_rise_s`` (50 ms by default, six IPO cycles; on the twin's recordings the
measured tau_u moves by at most 4.6 % of the limit per cycle, the default allows 16 %). The
interval is counted in stamps, at least one period (a flood of samples cannot add up to a jump),
at most the stale threshold (a stream resuming after a silence ramps in).

A sample that yields no model torque (it fails the consistency gate, or the gate is re-arming)
gets the hold output: the last published torque, slewed towards the physics prior's torque at
rest at the last pose served (``hold target``), for as long as the reference is not stale.
"""

from __future__ import annotations

import numpy as np

__all__ = ['OutputStage']


class OutputStage:
    """Clamp, slew-limit and hold the published torque of one stream.

    Args:
        limit: (n,) the clamp [N*m] (torque limits times their scale).
        slew: (n,) the largest rate of change [N*m/s].
        period_s: the IPO period [s].
        stale_after_s: the stale threshold [s] (the longest interval a step may use).
    """

    def __init__(
        self, limit: np.ndarray, slew: np.ndarray, period_s: float, stale_after_s: float
    ) -> None:
        self.limit = limit
        self.slew = slew
        self._min_ns = round(period_s * 1e9)
        self._max_ns = max(self._min_ns, round(stale_after_s * 1e9))
        self.last: np.ndarray | None = None
        self._last_stamp_ns: int | None = None

    def _bound(self, stamp_ns: int) -> np.ndarray:
        last = self._last_stamp_ns
        interval_ns = (
            self._min_ns if last is None else min(max(stamp_ns - last, self._min_ns), self._max_ns)
        )
        bound: np.ndarray = self.slew * (interval_ns * 1e-9)
        return bound

    def serve(self, tau: np.ndarray, stamp_ns: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(published torque, clamped joints, slew-limited joints) for a model torque."""
        over = np.abs(tau) > self.limit
        out = np.clip(tau, -self.limit, self.limit) if over.any() else tau
        slewed = np.zeros(len(tau), dtype=bool)
        if self.last is not None:
            bound = self._bound(stamp_ns)
            step = out - self.last
            slewed = np.abs(step) > bound
            if slewed.any():
                out = self.last + np.clip(step, -bound, bound)
        self.last = np.array(out, dtype=float)
        self._last_stamp_ns = stamp_ns
        return self.last, over, slewed

    def hold(self, target: np.ndarray | None, stamp_ns: int) -> np.ndarray | None:
        """The last torque moved towards ``target`` within the slew bound; None before any."""
        if self.last is None:
            return None
        if target is not None:
            self.serve(np.asarray(target, dtype=float), stamp_ns)
        else:
            self._last_stamp_ns = stamp_ns
        return self.last
