"""The sender's time base as the predictor sees it: age, future stamps, order, resynchronisation.

A reference's stamps are the sender's clock; the predictor's clock is another one (its receive
time, or the ROS clock where the caller passes one). Their offset, ``receive - stamp``, is the
transport delay plus the difference of the clocks. The time base keeps its smallest recent value,

    offset_k = min(receive_k - stamp_k, offset_(k-1) + DRIFT * (stamp_k - stamp_(k-1))),

so a sample's lateness ``receive - stamp - offset`` is how much longer than the quickest delivery
it took, whatever the clocks' difference (no shared time base needed). ``DRIFT`` lets the offset
grow by up to the stamps' own advance: a sender whose stamps run at half this clock's rate or
faster (a replay at ``rate`` 0.5; a faster one while its stamps gain less than one period per
sample, see below; ``stamp_rate`` notices both) is followed, while a delivery that stalls by
more than ``max_age_s`` beyond that is caught. With ``max_age_s`` > 0, such a sample is too
old, and one whose stamp leads the time base by more than the future tolerance, one IPO period
(or ``max_age_s`` where that is shorter), is a future stamp (a slower sender needs ``max_age_s``
0, which turns both checks off); any sample not after the last accepted is out of order.

Why one period: a stream whose stamps advance by one period per sample leads the sample before
it by the period less the time between their arrivals, so under one period whatever the
delivery (floods included, each arrival after the one before), and the time base is the
quickest delivery seen, which a sample can lead only by less. A sample accepted with a lead
under one period is stamped before the next valid one: no valid sample is refused as out of
order after it, and the published stamps keep increasing. A longer lead (the sample stamped
50 ms ahead) would be taken as the newest stamp, so that the valid samples after it were refused
as out of order until a resync, the outputs' stamps stepping back there.

A time base that no longer holds (the sender's clock stepped, a replay restarted) never locks the
stream out: after ``resync_after`` such rejections in a row the next sample starts a new time
base. Only there may the stamps of what is published step back (the warning says so).

Gaps: the IPO cycles between consecutive stamps seen (refused samples are seen) are counted,
whatever happens between them (rejections, resyncs, history resets, stale periods), so that every
cycle from the first stamp to the last is a sample received or a cycle skipped. ``skipped``
returns those of a gap within the stale threshold (a few samples lost or overwritten); those of a
longer gap (a hole: a burst that overflowed the input queue, a sender that paused) go to
``hole_cycles``, since a hole is also a stale episode. A stamp that leaps more than ``MAX_LEAP_S``
ahead of the time base is a step of the sender's clock, not cycles: its gap is not counted, and
counting goes on from it once the time base takes it (accepted, or at a resync).
"""

from __future__ import annotations

from id_learning.predictor.outcome import Reject

__all__ = ['DRIFT', 'MAX_LEAP_S', 'StampClock', 'future_tolerance_ns']

#: How fast the offset may grow between a sender's clock and ours (share of the stamps' advance).
DRIFT = 1.0
#: The furthest a stamp may run ahead of the time base across a hole and still be counted as
#: cycles [s]: a burst of queued references runs ahead by its length; a clock step by more.
MAX_LEAP_S = 1.0


def future_tolerance_ns(max_age_s: float, period_s: float) -> int:
    """The furthest a stamp may lead its time base [ns]; 0: no check (``max_age_s`` 0).

    One IPO period, or ``max_age_s`` where that is shorter.
    """
    return round(min(max_age_s, period_s) * 1e9) if max_age_s > 0 else 0


class StampClock:
    """The time base of one reference stream.

    Args:
        max_age_s: the largest lateness accepted [s]; 0: neither lateness nor leads are checked
            (the order still is).
        resync_after: rejections for time in a row after which a sample starts a new time base.
        period_s: the IPO period [s]: the largest lead accepted (``future_tolerance_ns``).
    """

    def __init__(self, max_age_s: float, resync_after: int, period_s: float) -> None:
        self.max_age_ns = 0
        self.future_ns = 0
        self.resync_after = resync_after
        self.configure(max_age_s, resync_after, period_s)
        self.offset_ns: int | None = None
        self.last_stamp_ns: int | None = None
        #: Rejections for time since the last accepted sample.
        self.rejections = 0
        #: The newest stamp seen, refused or not [ns].
        self.newest_ns: int | None = None
        #: IPO cycles in holes (gaps beyond the stale threshold) between the stamps seen.
        self.hole_cycles = 0
        #: The hole the last stamp passed to ``skipped`` ends: (stamp, its cycles, the newest
        #: stamp before it); ``judge`` counts it or, for a leap of the clock, not.
        self._hole: tuple[int, int, int] | None = None

    def configure(self, max_age_s: float, resync_after: int, period_s: float) -> None:
        """New limits for the samples to come (the time base is kept)."""
        self.max_age_ns = round(max_age_s * 1e9)
        self.future_ns = future_tolerance_ns(max_age_s, period_s)
        self.resync_after = resync_after

    def skipped(self, stamp_ns: int, stale_after_ns: int, period_s: float) -> int:
        """IPO cycles skipped since the newest stamp seen (refused samples are seen).

        Returns those of a gap within the stale threshold: what a queue overwrote or the sender
        never sent. A longer gap is a hole (also a stale episode): ``judge``, called next with the
        same stamp, adds its cycles to ``hole_cycles`` unless the stamp leapt ahead.
        """
        newest = self.newest_ns
        self._hole = None
        if newest is not None and stamp_ns <= newest:
            return 0
        self.newest_ns = stamp_ns
        if newest is None:
            return 0
        cycles = max(round((stamp_ns - newest) * 1e-9 / period_s) - 1, 0)
        if stamp_ns - newest > stale_after_ns:
            self._hole = (stamp_ns, cycles, newest)
            return 0
        return cycles

    def judge(self, stamp_ns: int, now_ns: int) -> tuple[Reject, str] | None:
        """Why this sample's stamp is refused, or None; settles the hole ``skipped`` found."""
        refused = self._refusal(stamp_ns, now_ns)
        hole, self._hole = self._hole, None
        if hole is not None and hole[0] == stamp_ns:
            _, cycles, before = hole
            leap_ns = 0 if self.offset_ns is None else stamp_ns + self.offset_ns - now_ns
            if leap_ns <= MAX_LEAP_S * 1e9:
                self.hole_cycles += cycles
            elif refused is not None:  # a clock step: counting goes on from the old stamps
                self.newest_ns = before
        return refused

    def _refusal(self, stamp_ns: int, now_ns: int) -> tuple[Reject, str] | None:
        if self.offset_ns is not None and self.max_age_ns > 0:
            late_ns = now_ns - stamp_ns - self.offset_ns
            if late_ns > self.max_age_ns:
                return Reject.TOO_OLD, (
                    f'stamp arrived {late_ns * 1e-6:.1f} ms later than its time base says '
                    f'(max_age_s {self.max_age_ns * 1e-9:g} s)'
                )
            if late_ns < -self.future_ns:
                allowed = 'max_age_s' if self.future_ns == self.max_age_ns else 'one IPO period'
                return Reject.FUTURE_STAMP, (
                    f'stamp is {-late_ns * 1e-6:.1f} ms ahead of its time base (the quickest '
                    f'delivery so far), more than the {self.future_ns * 1e-6:g} ms allowed '
                    f'({allowed})'
                )
        last = self.last_stamp_ns
        if last is not None and stamp_ns <= last:
            return Reject.STAMP_ORDER, (
                f'stamp {stamp_ns} ns is not after the last accepted {last} ns'
            )
        return None

    def should_resync(self) -> bool:
        """Count one rejection for time; True when it is one too many (resynchronise)."""
        self.rejections += 1
        return self.rejections >= self.resync_after

    def accept(self, stamp_ns: int, now_ns: int) -> None:
        """Take this sample into the time base."""
        offset = now_ns - stamp_ns
        if self.offset_ns is not None and self.last_stamp_ns is not None:
            drifted = self.offset_ns + round(DRIFT * max(stamp_ns - self.last_stamp_ns, 0))
            offset = min(offset, drifted)
        self.offset_ns = offset
        self.last_stamp_ns = stamp_ns
        self.rejections = 0

    def resync(self, stamp_ns: int, now_ns: int) -> None:
        """Start a new time base at this sample."""
        self.offset_ns = None
        self.last_stamp_ns = None
        self.newest_ns = stamp_ns
        self.accept(stamp_ns, now_ns)
