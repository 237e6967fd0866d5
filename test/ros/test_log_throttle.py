"""The node's hand-made log throttle (``nodes.log_throttle``): a period that may change per call.

Pure Python with an injected clock: no rclpy, no sleeps.
"""

from __future__ import annotations

import pytest

from id_learning.nodes.log_throttle import LogThrottle, ThrottledLog

S = 1_000_000_000  # ns


class Clock:
    """A steady clock the test moves."""

    def __init__(self) -> None:
        self.ns = 5 * S

    def __call__(self) -> int:
        return self.ns


class Lines:
    """A logger that keeps its lines, or raises on each when told to."""

    def __init__(self, raises: bool = False) -> None:
        self.lines: list[tuple[str, str]] = []
        self.raises = raises

    def warning(self, message: str) -> None:
        self._line('warning', message)

    def error(self, message: str) -> None:
        self._line('error', message)

    def _line(self, level: str, message: str) -> None:
        if self.raises:
            raise ValueError('Logging filter parameters cannot be changed between calls.')
        self.lines.append((level, message))


def test_a_kind_is_let_through_once_per_period_each_kind_on_its_own():
    clock = Clock()
    throttle = LogThrottle(clock)
    assert throttle.allows('a', 1.0)  # the first line of a kind
    assert not throttle.allows('a', 1.0)
    assert throttle.allows('b', 1.0)  # another kind is not held back by it
    clock.ns += S - 1
    assert not throttle.allows('a', 1.0)
    clock.ns += 1
    assert throttle.allows('a', 1.0)  # one period after the last line let through
    assert not throttle.allows('a', 1.0)


def test_a_changed_period_takes_effect_at_the_next_call_either_way():
    clock = Clock()
    throttle = LogThrottle(clock)
    assert throttle.allows('a', 10.0)
    clock.ns += S // 2
    assert not throttle.allows('a', 10.0)
    assert throttle.allows('a', 0.25)  # shortened: 0.5 s is past it
    clock.ns += S // 2
    assert not throttle.allows('a', 5.0)  # lengthened: 0.5 s is within it
    clock.ns += 5 * S
    assert throttle.allows('a', 5.0)
    for period in (1.0, 0.5, 2.0, 1.0):  # changes between calls never raise
        throttle.allows('a', period)


def test_a_held_back_line_does_not_restart_the_period():
    clock = Clock()
    throttle = LogThrottle(clock)
    assert throttle.allows('a', 1.0)
    for _ in range(9):
        clock.ns += S // 10
        assert not throttle.allows('a', 1.0)
    clock.ns += S // 10
    assert throttle.allows('a', 1.0)


@pytest.mark.parametrize('period_s', [0.0, -1.0])
def test_no_period_lets_every_line_through(period_s):
    throttle = LogThrottle(Clock())
    assert all(throttle.allows('a', period_s) for _ in range(5))


def test_the_throttled_log_reads_the_period_at_each_call():
    clock, lines, period = Clock(), Lines(), [1.0]
    said = ThrottledLog(lines, lambda: period[0], clock)
    assert said.warning('w', 'first')
    assert not said.warning('w', 'held back')
    assert said.error('e', 'an error of another kind')
    clock.ns += S // 5
    period[0] = 0.1  # what a runtime change of log_throttle_s does
    assert said.warning('w', 'after the change')
    assert lines.lines == [
        ('warning', 'first'),
        ('error', 'an error of another kind'),
        ('warning', 'after the change'),
    ]


def test_the_failure_line_never_raises():
    class UnprintableError(Exception):
        def __str__(self) -> str:
            raise RuntimeError('no text')

    said = ThrottledLog(Lines(raises=True), lambda: 1.0, Clock())
    with pytest.raises(ValueError, match='cannot be changed'):
        said.error('e', 'a plain error raises what the logger raises')
    assert not said.failure('f', 'reference callback', ValueError('x'))  # dropped, not raised
    lines = Lines()
    said = ThrottledLog(lines, lambda: 1.0, Clock())
    assert not said.failure('f', 'reference callback', UnprintableError())
    assert said.failure('g', 'reference callback', KeyError('joint_7'))
    assert lines.lines == [('error', "reference callback failed: KeyError: 'joint_7'")]
