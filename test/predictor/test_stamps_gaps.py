"""Every IPO cycle from the first stamp seen to the last is a sample received or a skipped cycle,
across rejections, resyncs, history resets and stale periods; a step of the sender's clock is no
cycles. Invalid header stamps are named."""

from __future__ import annotations

import numpy as np
import pytest
from predictor.test_feedforward import PERIOD_NS, LinearModel, sample

from id_learning.predictor import FeedForwardPredictor, GuardConfig
from id_learning.predictor.guards import stamp_problem
from id_learning.predictor.outcome import Reject
from id_learning.predictor.stamps import StampClock

STALE_NS = 5 * PERIOD_NS
START_NS = 1_000_000_000


def all_skipped(core: FeedForwardPredictor) -> int:
    """What the node reports as skipped_cycles: the core's count and the time base's holes."""
    return core.counters.skipped_cycles + core._clock.hole_cycles


def burst_stream(bursts: int, size: int = 50, early: int = 3, kept: int = 10):
    """(k, receive_ns) of what a predictor with a 10-deep queue takes from bursts of ``size``
    references, all published at once every ``size`` periods: the first few, taken while the
    burst is still being published, and the ``kept`` newest the queue held."""
    for j in range(bursts):
        arrival = 5_000_000_000 + j * size * PERIOD_NS
        for k in [*range(early), *range(size - kept, size)]:
            yield j * size + k, arrival + k * 50_000  # 50 us apart: far faster than the stamps


def test_a_burst_stream_is_counted_cycle_by_cycle_across_resyncs_resets_and_stale_periods(mabi):
    core = FeedForwardPredictor(LinearModel(mabi), mabi.limits.torque, GuardConfig())
    seen = []
    for k, receive_ns in burst_stream(8):
        if seen and k - seen[-1] > 20:  # the watchdog runs between bursts: the stream is stale
            core.check_stale(receive_ns - 100_000_000)
        core.step(sample(k), receive_ns)
        seen.append(k)
    counters = core.counters
    # The bursts run ahead of the time base: refused, resynchronised, reset, stale in between.
    assert counters.rejects[Reject.FUTURE_STAMP] > 0
    assert counters.resyncs >= 1
    assert counters.history_resets >= 1
    assert counters.stale_episodes >= 7
    grid = seen[-1] - seen[0] + 1
    assert counters.received == len(seen) < grid / 3
    assert counters.received + all_skipped(core) == grid
    assert core._clock.hole_cycles > counters.skipped_cycles  # most were lost in the holes


def test_a_sample_refused_by_its_joints_is_counted_received_and_its_cycle_skipped(mabi):
    core = FeedForwardPredictor(LinearModel(mabi), mabi.limits.torque, GuardConfig())
    for k in range(5):
        core.step(sample(k), 5_000_000_000 + k * PERIOD_NS)
    assert core.step(sample(5, q=[np.nan] * 6), 5_000_000_000 + 5 * PERIOD_NS).tau is None
    for k in (6, 60, 61):  # a hole of 53 cycles after 6: a sender's pause
        core.step(sample(k), 5_000_000_000 + k * PERIOD_NS)
    assert core.counters.history_resets == 1
    assert core.counters.skipped_cycles == 1  # the refused sample's cycle, as before
    assert core._clock.hole_cycles == 53
    assert core.counters.received + all_skipped(core) == 62 + 1  # the refused one twice


def test_a_restarted_sender_counts_again_from_its_new_stamps(mabi):
    core = FeedForwardPredictor(LinearModel(mabi), mabi.limits.torque, GuardConfig())
    receive = iter(range(5_000_000_000, 10_000_000_000, PERIOD_NS))
    for k in range(100, 110):
        core.step(sample(k), next(receive))
    for k in range(0, 20):  # stamps back by 100 cycles: refused until the time base restarts
        core.step(sample(k), next(receive))
    assert core.counters.resyncs == 1
    assert all_skipped(core) == 0


@pytest.mark.parametrize('max_age_s', [0.1, 0.0])
def test_a_step_of_the_senders_clock_is_no_cycles(mabi, max_age_s):
    core = FeedForwardPredictor(
        LinearModel(mabi), mabi.limits.torque, GuardConfig(max_age_s=max_age_s)
    )
    receive = iter(range(5_000_000_000, 10_000_000_000, PERIOD_NS))
    for k in range(10):
        core.step(sample(k), next(receive))
    step = 3_600 * 125  # an hour of cycles ahead, while only 8 ms pass here
    for k in range(10, 20):
        core.step(sample(k + step), next(receive))
    for k in (21, 22):  # one more cycle lost on the new time base: counted
        core.step(sample(k + step), next(receive))
    assert all_skipped(core) == 1
    assert core.counters.resyncs == (1 if max_age_s else 0)


def test_one_stamp_far_ahead_neither_counts_nor_blinds_the_count(mabi):
    core = FeedForwardPredictor(LinearModel(mabi), mabi.limits.torque, GuardConfig())
    receive = iter(range(5_000_000_000, 10_000_000_000, PERIOD_NS))
    for k in range(5):
        core.step(sample(k), next(receive))
    result = core.step(sample(5, stamp_ns=START_NS + 10**12), next(receive))
    assert result.reject is Reject.FUTURE_STAMP
    for k in (6, 7, 10):  # 8 and 9 never arrive
        core.step(sample(k), next(receive))
    assert all_skipped(core) == 1 + 2  # cycle 5 (its sample was refused) and 8, 9


def test_the_stamp_clock_settles_a_hole_when_it_judges_the_stamp():
    clock = StampClock(max_age_s=0.1, resync_after=5, period_s=PERIOD_NS * 1e-9)
    clock.accept(START_NS, 0)
    clock.newest_ns = START_NS
    stamp = START_NS + 30 * PERIOD_NS
    assert clock.skipped(stamp, STALE_NS, PERIOD_NS * 1e-9) == 0
    assert clock.hole_cycles == 0  # not yet: a leap of the clock would not be cycles
    assert clock.judge(stamp, 30 * PERIOD_NS) is None
    assert clock.hole_cycles == 29


@pytest.mark.parametrize(
    ('sec', 'nanosec', 'problem'),
    [
        (0, 0, None),
        (1_700_000_000, 999_999_999, None),
        (5, 1_500_000_000, 'nanosec 1500000000 is not in [0, 1e9)'),
        (5, 1_000_000_000, 'nanosec 1000000000 is not in [0, 1e9)'),
        (-5, 0, 'sec -5 is negative'),
    ],
)
def test_an_invalid_header_stamp_is_named(sec, nanosec, problem):
    found = stamp_problem(sec, nanosec)
    assert (found is None) == (problem is None)
    if problem is not None:
        assert problem in found
