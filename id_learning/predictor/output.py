"""What leaves the predictor: clamped to the torque limits, slew-limited, held when unsure.

Every published torque moves from the one before by at most

    slew * min(stamp - last stamp, stale threshold)    per joint,
    slew = torque limit / torque_rise_s,

so that over any span of rising stamps t1 < t2 the published torque moves by at most
slew * (t2 - t1): no feed-forward a valid reference needs rises from zero to the drive's torque
limit faster than ``torque_rise_s`` (50 ms by default, six IPO cycles; on the twin's recordings
the measured tau_u moves by at most 4.6 % of the limit per cycle, the default allows 16 %). The
interval is counted in stamps, however close they lie (references stamped 1 ms apart move by an
eighth of an 8 ms period's worth each: a flood of samples cannot add up to a jump), at most the
stale threshold (a stream resuming after a silence ramps in). Where the stamps step back (a
resync, the one place they may: ``predictor.stamps``) the step is one IPO period's worth: the one
allowance beyond the rate.

The torque limits (times ``torque_limit_scale``) hold on every torque given out, the clamp
coming last: where the limit was lowered at runtime below the last torque, that torque is brought
to the new limit at once, faster than the slew limit (the one step that may: a torque beyond the
limit in force is never published), and counted as clamped.

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
        period_s: the IPO period [s] (the step allowed where the stamps step back).
        stale_after_s: the stale threshold [s] (the longest interval a step may use).
    """

    def __init__(
        self, limit: np.ndarray, slew: np.ndarray, period_s: float, stale_after_s: float
    ) -> None:
        self.last: np.ndarray | None = None
        self._last_stamp_ns: int | None = None
        self.configure(limit, slew, period_s, stale_after_s)

    def configure(
        self, limit: np.ndarray, slew: np.ndarray, period_s: float, stale_after_s: float
    ) -> None:
        """New limits for the running stream, in force from the next torque given out.

        The last torque and its stamp are kept: the slew continues from them, and a limit
        lowered below the last torque holds on the next one.
        """
        self.limit = limit
        self.slew = slew
        self._period_ns = round(period_s * 1e9)
        self._max_ns = max(self._period_ns, round(stale_after_s * 1e9))

    def _bound(self, stamp_ns: int) -> np.ndarray:
        last = self._last_stamp_ns
        elapsed = self._period_ns if last is None else stamp_ns - last
        interval_ns = min(elapsed, self._max_ns) if elapsed > 0 else self._period_ns
        bound: np.ndarray = self.slew * (interval_ns * 1e-9)
        return bound

    def serve(self, tau: np.ndarray, stamp_ns: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(published torque, clamped joints, slew-limited joints) for a model torque."""
        limit = self.limit
        over = np.abs(tau) > limit
        out = np.clip(tau, -limit, limit)
        slewed = np.zeros(len(tau), dtype=bool)
        last = self.last
        if last is not None:
            beyond = np.abs(last) > limit  # the limit was lowered: to it at once, then slewed
            if beyond.any():
                over = over | beyond
                last = np.clip(last, -limit, limit)
            bound = self._bound(stamp_ns)
            step = out - last
            slewed = np.abs(step) > bound
            if slewed.any():
                out = np.clip(last + np.clip(step, -bound, bound), -limit, limit)
        self.last = np.array(out, dtype=float)
        self._last_stamp_ns = stamp_ns
        return self.last, over, slewed

    def hold(self, target: np.ndarray | None, stamp_ns: int) -> np.ndarray | None:
        """The last torque moved towards ``target`` within the slew bound; None before any.

        Within the limit in force either way (without a target, the last torque clamped to it).
        """
        if self.last is None:
            return None
        if target is not None:
            self.serve(np.asarray(target, dtype=float), stamp_ns)
        else:
            self.last = np.clip(self.last, -self.limit, self.limit)
            self._last_stamp_ns = stamp_ns
        return self.last
