"""Throttled warnings and errors whose period may change at runtime (``log_throttle_s``).

rclpy's logger fixes a call site's ``throttle_duration_sec`` on its first use and raises
ValueError ('Logging filter parameters cannot be changed between calls') when a later call passes
another, so a period read from a runtime-changeable parameter cannot go to it. Here each kind of
line keeps the time it was last logged on the steady clock and compares it with the period passed
at each call: a change takes effect at once. No rclpy here: the node passes its logger.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Protocol

__all__ = ['LogThrottle', 'Logger', 'ThrottledLog']


class Logger(Protocol):
    """What of a logger (rclpy's, or ``logging``'s) the throttled log calls."""

    def warning(self, message: str) -> object: ...  # noqa: D102

    def error(self, message: str) -> object: ...  # noqa: D102


class LogThrottle:
    """Whether a line of a kind may be logged now: at most once per period per kind.

    Args:
        clock: the steady clock [ns]; injectable for tests.
    """

    def __init__(self, clock: Callable[[], int] = time.monotonic_ns) -> None:
        self.clock = clock
        #: When each kind was last let through [ns].
        self.last_ns: dict[str, int] = {}

    def allows(self, key: str, period_s: float) -> bool:
        """Whether ``key`` may be logged now: not let through within ``period_s`` (now taken).

        The first line of a kind is always let through; ``period_s`` <= 0 lets every line through.
        """
        now = self.clock()
        last = self.last_ns.get(key)
        if last is not None and now - last < period_s * 1e9:
            return False
        self.last_ns[key] = now
        return True


class ThrottledLog:
    """A logger's warnings and errors, each kind at most once per the current period.

    Args:
        logger: where the lines go.
        period_s: the current period [s], read at each call (the node's ``log_throttle_s``).
        clock: the steady clock [ns].
    """

    def __init__(
        self,
        logger: Logger,
        period_s: Callable[[], float],
        clock: Callable[[], int] = time.monotonic_ns,
    ) -> None:
        self.logger = logger
        self.period_s = period_s
        self.throttle = LogThrottle(clock)

    def warning(self, key: str, message: str) -> bool:
        """Log ``message`` as a warning unless a line of ``key`` was within the period."""
        if not self.throttle.allows(key, self.period_s()):
            return False
        self.logger.warning(message)
        return True

    def error(self, key: str, message: str) -> bool:
        """Log ``message`` as an error unless a line of ``key`` was within the period."""
        if not self.throttle.allows(key, self.period_s()):
            return False
        self.logger.error(message)
        return True

    def failure(self, key: str, what: str, err: BaseException) -> bool:
        """Log '<what> failed: <error>' as ``error`` does, but never raise: an except block's word.

        A failure to log (a logger that raises, an error whose text cannot be made) must not end
        the node: the line is dropped, and False returned.
        """
        try:
            return self.error(key, f'{what} failed: {type(err).__name__}: {err}')
        except Exception:  # nothing is left to report it to
            return False
