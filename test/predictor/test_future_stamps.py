"""Stamps ahead of the stream's time base: refused beyond one IPO period, taken within it; the
published stamps rise, and a resync (the only place they may step back) is always flagged."""

from __future__ import annotations

from dataclasses import replace
from itertools import pairwise

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st
from predictor.test_stream_properties import PERIOD_NS, fed, motion, predictor_for

from id_learning.predictor import ReferenceSample, Reject
from id_learning.predictor.stamps import StampClock, future_tolerance_ns

JOINTS = tuple(f'joint_{j}' for j in range(1, 7))


def stepped(predictor, stream):
    return [predictor.step(sample, receive) for sample, receive in stream]


def output_stamps(results) -> list[int]:
    return [r.stamp_ns for r in results if r.tau is not None]


def test_a_sample_stamped_50_ms_ahead_is_refused_and_the_next_valid_one_is_served(mabi):
    # The probe's P12: inside max_age_s (0.1 s), six periods ahead of the stream.
    predictor = predictor_for(mabi)
    results = stepped(predictor, fed(['valid'] * 20 + ['lead'] + ['valid'] * 20, 0.4))
    ahead = results[20]
    assert ahead.reject is Reject.FUTURE_STAMP
    assert ahead.tau is None
    assert '50.0 ms ahead of its time base' in ahead.detail
    assert '8 ms allowed (one IPO period)' in ahead.detail
    assert all(r.reject is None for r in results[:20] + results[21:])
    counters = predictor.counters
    assert counters.rejects[Reject.FUTURE_STAMP] == 1
    assert counters.rejects[Reject.STAMP_ORDER] == 0
    assert counters.resyncs == 0
    stamps = output_stamps(results)
    assert len(stamps) == 40
    assert all(b > a for a, b in pairwise(stamps))


def test_a_lead_under_one_period_is_taken_and_refuses_no_valid_sample_after_it(mabi):
    predictor = predictor_for(mabi)
    results = stepped(predictor, fed(['valid'] * 20 + ['nudge'] + ['valid'] * 20, 0.4))
    assert all(r.reject is None for r in results)
    stamps = output_stamps(results)
    assert all(b > a for a, b in pairwise(stamps))


def test_the_future_tolerance_is_one_period_or_max_age_where_shorter():
    assert future_tolerance_ns(0.1, 0.008) == 8_000_000
    assert future_tolerance_ns(0.005, 0.008) == 5_000_000
    assert future_tolerance_ns(0.0, 0.008) == 0  # max_age_s 0: neither age nor lead checked


def test_the_sender_stepping_its_clock_ahead_is_refused_until_the_resync_then_served(mabi):
    predictor = predictor_for(mabi)
    stream = fed(['valid'] * 60, 0.4)
    step_ns = 10 * PERIOD_NS  # from sample 20 on, every stamp 80 ms ahead: a clock step
    stream = [
        (ReferenceSample(s.stamp_ns + (step_ns if i >= 20 else 0), s.names, s.q, s.v, s.a), r)
        for i, (s, r) in enumerate(stream)
    ]
    results = stepped(predictor, stream)
    resync_after = predictor.config.resync_after
    refused = results[20 : 20 + resync_after - 1]
    assert all(r.reject is Reject.FUTURE_STAMP for r in refused)
    assert results[20 + resync_after - 1].resynced
    served_from = 20 + predictor.recovery_samples
    assert all(r.reject is None for r in results[served_from:])
    stamps = output_stamps(results)
    assert all(b > a for a, b in pairwise(stamps))  # the step was ahead


def test_a_resync_is_flagged_and_says_why_whatever_the_sample_gets(mabi):
    # With the consistency gate the resync sample re-arms (a hold output): still flagged, so
    # that the node says it; and only there may the published stamps step back.
    predictor = predictor_for(mabi)
    results = stepped(predictor, fed(['valid'] * 20 + ['back'] * 10, 0.4))
    flagged = [k for k, r in enumerate(results) if r.resynced]
    assert flagged == [20 + predictor.config.resync_after - 1]
    resync = results[flagged[0]]
    assert resync.reject is Reject.REARMING
    assert resync.is_held
    assert 'later than its time base says' in resync.detail
    assert 'consistent sample 1 of 2' in resync.detail
    stamps = [(k, r.stamp_ns) for k, r in enumerate(results) if r.tau is not None]
    back = [k for (_, a), (k, b) in pairwise(stamps) if b <= a]
    assert back == flagged


def test_with_max_age_off_a_lead_is_taken_and_the_stamps_step_back_only_at_the_resync(mabi):
    predictor = predictor_for(mabi)
    predictor.update_config(replace(predictor.config, max_age_s=0.0))
    results = stepped(predictor, fed(['valid'] * 20 + ['lead'] + ['valid'] * 30, 0.4))
    assert results[20].reject is None  # not checked
    order = [r for r in results[21:] if r.reject is Reject.STAMP_ORDER]
    assert len(order) == predictor.config.resync_after - 1
    resynced = [k for k, r in enumerate(results) if r.resynced]
    assert len(resynced) == 1
    stamps = [(k, r.stamp_ns) for k, r in enumerate(results) if r.tau is not None]
    back = [k for (_, a), (k, b) in pairwise(stamps) if b <= a]
    assert back == resynced


def test_consecutive_floods_lead_by_less_than_a_period_each_and_are_served(mabi):
    # Arrivals 1 us apart, stamps a period apart: each leads the one before by just under it.
    predictor = predictor_for(mabi)
    stream = []
    for k in range(40):
        q, v, a = motion(k, 0.4)
        receive = 5 * 10**9 + (k * PERIOD_NS if k < 10 else 10 * PERIOD_NS + (k - 10) * 1000)
        stream.append((ReferenceSample(10**9 + k * PERIOD_NS, JOINTS, q, v, a), receive))
    results = stepped(predictor, stream)
    assert all(r.reject is None for r in results), {r.detail for r in results if r.reject}
    assert np.isfinite([r.tau for r in results]).all()


def test_a_refused_sample_in_a_draining_backlog_moves_the_time_base_along(mabi):
    """After a 40 ms stall the queue drains at once; a sample the plausibility gate refuses in
    it is still the stream's stamp: the valid ones after it lead by less than a period."""
    predictor = predictor_for(mabi)
    stream = fed(['valid'] * 40, 0.4)
    drained = stream[29][1] - 1_000_000  # samples 20-29 arrive at once, 0.1 ms apart
    for k in range(20, 30):
        sample, _ = stream[k]
        if k == 26:  # a velocity no arm has: the gate refuses it (no model torque)
            sample = replace(sample, v=np.full(6, 50.0))
        stream[k] = (sample, drained + (k - 20) * 100_000)
    results = stepped(predictor, stream)
    assert results[26].reject is Reject.IMPOSSIBLE
    others = [r for k, r in enumerate(results) if k != 26]
    assert all(r.reject is None for r in others), [(r.reject, r.detail) for r in others]
    assert predictor.counters.resyncs == 0


@settings(max_examples=200, deadline=None)
@given(
    delays=st.lists(st.floats(0.0, 0.099), min_size=2, max_size=300),
    transport=st.integers(0, 10**12),
    spacing=st.integers(0, 2_000_000),
)
def test_a_periodic_stream_delivered_in_order_within_max_age_is_never_refused_for_time(
    delays, transport, spacing
):
    # The invariant a loaded machine relies on (a stalled sender or receiver, then a burst):
    # whatever each sample's extra delay up to max_age_s (0.1 s), in arrival order, at least
    # ``spacing`` apart, no sample is too old, ahead of its time base or out of order.
    clock = StampClock(0.1, 5, PERIOD_NS * 1e-9)
    arrival = 0
    for k, delay in enumerate(delays):
        stamp = k * PERIOD_NS
        arrival = max(arrival + spacing, stamp + transport + round(delay * 1e9))
        if arrival - stamp - transport > round(0.1 * 1e9):
            break  # the spacing itself made it late: beyond the invariant's premise
        assert clock.judge(stamp, arrival) is None, (k, clock.offset_ns, arrival - stamp)
        clock.accept(stamp, arrival)
