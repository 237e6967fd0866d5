"""How fast a reference's stamps advance against the receive clock: a sender at another rate.

The time base (``predictor.stamps``) follows a sender whose stamps run faster than real time (a
replay at ``rate`` 2, a stamp step of twice the period): each sample leads the one before by less
than its stamp step, so none is refused, and the stream is served without a word. Slower ones
(down to half real time) are followed too. This compares the stamps' advance with the receive
clock's over a window (``window_s``, 2 s) and says when they differ by more than ``tolerance``
(5 %), and again when they agree once more.

The receive-minus-stamp offset of a stream on time is the transport delay: flat at its lower
envelope, however the deliveries jitter; a stream at ``r`` times real time drifts along it at
``1 - r`` per second of receive time. Per block of the window (``blocks``, 8: a quarter second)
the sample with the smallest offset is kept, a point on that envelope; a block starts at a
sample, so a stall that delays a burst leaves the samples before it and the freshest of the burst
in their blocks. The envelope is read at three places, each the lowest of a few points (a quarter
of them at each end, as many around the middle): a block of late samples only (a stall that ends
in a pause of the sender) is outvoted by its neighbours. ``ratio`` is the stamps' advance over the
receive clock's from the first place to the last. ``is_off`` turns on only when both halves of the
window deviate beyond the tolerance, the same way: one step of the offset (a clock step, a replay
restarted, a delivery that stays later, one stamp far ahead) lies in one half only, a rate in
both. It clears when ``ratio`` is within half the tolerance again. O(1) per sample; the estimate is
made once per block, the first once the window and a block have passed (2.25 s).

A stamp before the newest one seen (a replay looping or restarted, a sender's clock set back: what
the time base answers with a resync) starts the estimate afresh, ``ratio`` None and ``is_off``
cleared until a new window has passed: a step back is the stamps' origin moving, no rate, and a
loop of a span shorter than the window would otherwise read as stamps that hardly advance.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Iterable
from itertools import islice

__all__ = ['StampRate']


class StampRate:
    """The stamps' rate against the receive clock over a window.

    Args:
        window_s: the span compared [s] (the first estimate a block after it).
        tolerance: the share by which the rates may differ before ``is_off`` (0.05: 5 %).
        blocks: points on the offset's lower envelope per window (a multiple of 4).
    """

    def __init__(self, window_s: float = 2.0, tolerance: float = 0.05, blocks: int = 8) -> None:
        if window_s <= 0 or tolerance <= 0 or blocks < 4 or blocks % 4:
            raise ValueError(
                f'StampRate: window_s and tolerance must be > 0 and blocks a multiple of 4, got '
                f'{window_s!r}, {tolerance!r}, {blocks!r}'
            )
        self.window_s = window_s
        self.tolerance = tolerance
        self.block_ns = round(window_s / blocks * 1e9)
        #: (receive, stamp) of the quickest delivery of each finished block [ns].
        self.points: deque[tuple[int, int]] = deque(maxlen=blocks + 1)
        #: The block being filled: its start, and its quickest delivery so far (receive, stamp).
        self._start_ns: int | None = None
        self._quickest = (0, 0)
        #: The stamps' advance over the receive clock's across the window; None until one.
        self.ratio: float | None = None
        #: The rates differ by more than the tolerance (in both halves of the window).
        self.is_off = False
        #: The newest stamp seen [ns]: one before it starts the estimate afresh.
        self._newest_ns: int | None = None

    def add(self, stamp_ns: int, receive_ns: int) -> bool:
        """Take one sample; True when ``is_off`` changed with it (say so)."""
        newest = self._newest_ns
        if newest is not None and stamp_ns < newest:
            return self.restart(stamp_ns, receive_ns)
        self._newest_ns = stamp_ns
        start = self._start_ns
        if start is not None and receive_ns - start < self.block_ns:
            quickest = self._quickest
            if receive_ns - stamp_ns < quickest[0] - quickest[1]:
                self._quickest = (receive_ns, stamp_ns)
            return False
        if start is not None:
            self.points.append(self._quickest)
        self._start_ns = receive_ns
        self._quickest = (receive_ns, stamp_ns)
        return self._estimate()

    def restart(self, stamp_ns: int, receive_ns: int) -> bool:
        """Start afresh at this sample (the stamps stepped back); True when ``is_off`` cleared."""
        was_off = self.is_off
        self.points.clear()
        self.ratio, self.is_off = None, False
        self._newest_ns, self._start_ns = stamp_ns, receive_ns
        self._quickest = (receive_ns, stamp_ns)
        return was_off

    def _estimate(self) -> bool:
        points = self.points
        n = points.maxlen or 0
        if len(points) < n:
            return False
        # The lowest offset of a few blocks at each end and in the middle: one block of late
        # samples (a burst whose freshest sample was old) is outvoted by its neighbours.
        each, middle = (n - 1) // 4, (n - 1) // 2
        first = _quickest(islice(points, 0, each))
        centre = _quickest(islice(points, middle - each + 1, middle + each))
        last = _quickest(islice(points, n - each, n))
        self.ratio = _ratio(first, last)
        was_off = self.is_off
        if was_off:
            self.is_off = abs(self.ratio - 1.0) > 0.5 * self.tolerance
        else:
            older, newer = _ratio(first, centre) - 1.0, _ratio(centre, last) - 1.0
            self.is_off = min(abs(older), abs(newer)) > self.tolerance and older * newer > 0
        return self.is_off != was_off

    def line(self) -> tuple[bool, str]:
        """What to say of the rate now: (is a warning, text)."""
        ratio = self.ratio if self.ratio is not None else float('nan')
        over = f'over the last {self.window_s:g} s'
        if self.ratio is None:
            return False, (
                "the reference's stamps stepped back (a replay looped or restarted, a sender's "
                'clock set back): their rate against the receive clock is measured afresh'
            )
        if not self.is_off:
            return False, (
                f"the reference's stamps advance with the receive clock again ({ratio:.3f} "
                f'times its rate {over})'
            )
        return True, (
            f"the reference's stamps advance {ratio:.2f} times as fast as the receive clock "
            f'{over} ({"faster" if ratio > 1 else "slower"} than real time: a replay at rate '
            f'{ratio:.2g}, or a sender whose stamp step is not its send period); served all the '
            'same, with its stamps on tau_u (stamp_rate_ratio on /diagnostics)'
        )


def _quickest(points: Iterable[tuple[int, int]]) -> tuple[int, int]:
    """The point of the smallest offset (receive - stamp)."""
    return min(points, key=lambda point: point[0] - point[1])


def _ratio(older: tuple[int, int], newer: tuple[int, int]) -> float:
    """The stamps' advance over the receive clock's from one point to another."""
    return (newer[1] - older[1]) / max(newer[0] - older[0], 1)
