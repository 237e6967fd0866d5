"""A step back of the stamps restarts the rate estimate (``stamp_rate``): the probe's B69.

A replay looping a 0.5 s span steps its stamps back every 0.5 s; read across those steps, the
stamps hardly advance against the receive clock ('a replay at rate 0'). Generated streams (those
of ``test_stamp_rate``: jitter, stalls, holes, drift, any offset) folded into loops of any span
never warn at real time; a loop at twice real time still warns once a span holds a window.
"""

from __future__ import annotations

from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from predictor.test_stamp_rate import MS, WINDOW_S, S, changes, paced, real_time_streams

from id_learning.predictor.stamp_rate import StampRate


def looped(samples: list[tuple[int, int]], span_ns: int, rate: float = 1.0):
    """The stamps folded into a loop of ``span_ns``: each loop starts at the first stamp."""
    first = samples[0][0]
    return [(first + round((s - first) * rate) % span_ns, r) for s, r in samples]


@settings(max_examples=100, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(real_time_streams(), st.integers(50 * MS, 8 * S))
def test_a_loop_of_any_span_at_real_time_never_warns(stream, span_ns):
    samples, _ = stream
    monitor = StampRate(window_s=WINDOW_S)
    assert changes(monitor, looped(samples, span_ns)) == []
    assert not monitor.is_off
    assert monitor.ratio is None or abs(monitor.ratio - 1.0) < 0.05


def test_a_loop_of_half_a_second_says_no_rate():
    monitor = StampRate(window_s=WINDOW_S)
    assert changes(monitor, looped(paced(1.0, 10.0, send_ms=8.0), S // 2)) == []
    assert monitor.ratio is None  # no window without a step back: nan on /diagnostics
    assert 'stepped back' in monitor.line()[1]


def test_a_loop_at_twice_real_time_warns_and_a_step_back_clears_it():
    monitor = StampRate(window_s=WINDOW_S)
    samples = looped(paced(2.0, 8.0), 12 * S)  # the step back after 6 s of receive time
    said = changes(monitor, samples)
    assert [is_off for _, is_off, _ in said] == [True, False]
    assert said[1][0] == samples[1500][1]  # cleared at the step back itself
    assert monitor.line() == (False, monitor.line()[1])
    assert 'measured afresh' in monitor.line()[1]
