"""Messages lost on the way to a subscription, from its publishers' publication sequence numbers.

Each publisher numbers what it publishes, 1, 2, 3, ...: a gap in one publisher's numbers is a
message lost on the way. rclpy (Jazzy) gives a subscription the number but not the publisher's
id, so the numbers of several publishers on a topic are told apart by continuity: a message
continues the publisher whose last number is just below its own (``last + 1``), else the nearest
below it (a gap); a number at or below every publisher's last one is a new publisher's (or a
restarted one's). So is a jump while the graph holds more publishers than numbers seen: a
publisher that was publishing before the subscription matched it.
"""

from __future__ import annotations

import time
from collections.abc import Callable

__all__ = ['STREAM_IDLE_S', 'SequenceGaps']

#: A publisher's numbers are forgotten once it sent nothing this long [s] and the topic has more
#: numbered publishers than the graph holds (it is gone, or restarted under a new id).
STREAM_IDLE_S = 5.0


class SequenceGaps:
    """The publishers of one topic by their sequence numbers, and the gaps in them.

    Args:
        publishers: the topic's publishers in the graph now (``Node.count_publishers``); asked
            only when a message continues no publisher's numbers.
    """

    def __init__(self, publishers: Callable[[], int]) -> None:
        self._publishers = publishers
        #: Per publisher: its last sequence number, and when it came (time.monotonic() [s]).
        self._last: list[int] = []
        self._when: list[float] = []

    def __len__(self) -> int:
        """The publishers told apart so far."""
        return len(self._last)

    def take(self, sequence: int) -> tuple[int, int | None]:
        """Note a message's number: the messages missing before it, and the number it follows.

        Returns:
            (0, None) for a new publisher's first message, else (missing, last).
        """
        now = time.monotonic()
        last = self._last
        nearest = -1
        for k, number in enumerate(last):
            if number == sequence - 1:  # the common case: a continuation
                last[k], self._when[k] = sequence, now
                return 0, number
            if number < sequence and (nearest < 0 or number > last[nearest]):
                nearest = k
        if nearest < 0 or len(last) < self._publishers():
            last.append(sequence)
            self._when.append(now)
            return 0, None
        before = last[nearest]
        last[nearest], self._when[nearest] = sequence, now
        return sequence - before - 1, before

    def forget_idle(self, publishers: int) -> None:
        """Forget publishers idle ``STREAM_IDLE_S`` while more are numbered than ``publishers``."""
        if len(self._last) <= publishers:
            return
        now = time.monotonic()
        kept = [k for k, when in enumerate(self._when) if now - when < STREAM_IDLE_S]
        self._last = [self._last[k] for k in kept]
        self._when = [self._when[k] for k in kept]
