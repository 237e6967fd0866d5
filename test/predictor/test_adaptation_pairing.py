"""Predictions and currents pair by stamp whichever comes first; pairing that fails is said."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from id_learning.predictor.adaptation import (
    UNPAIRED_WARN_AFTER,
    AdaptationConfig,
    AdaptationLoop,
)
from id_learning.predictor.adaptation_pairing import MEASURED_CAPACITY, StampPairing
from id_learning.robot.config import RobotConfig

PERIOD_NS = 8_000_000
START_NS = 1_767_225_600_000_000_000
TOPIC = '/motor_currents'
#: The most cycles a current may come before or after its prediction and still pair: while one
#: waits for its prediction, at most this many later currents can come before that prediction.
JITTER = MEASURED_CAPACITY // 2


def interleaving(jitters: list[int], order: list[int]) -> list[tuple[str, int]]:
    """('prediction' | 'current', cycle) events: cycle k's current moved by jitters[k] cycles.

    ``order`` breaks ties between events at the same place, as two topics may.
    """
    events = [(float(k), order[2 * k], 'prediction', k) for k in range(len(jitters))]
    events += [(k + d + 0.5 * np.sign(d), order[2 * k + 1], 'current', k)
               for k, d in enumerate(jitters)]  # fmt: skip
    return [(side, k) for _, _, side, k in sorted(events)]


@settings(max_examples=300, deadline=None)
@given(
    st.lists(st.integers(-JITTER, JITTER), min_size=1, max_size=60).flatmap(
        lambda jitters: st.tuples(
            st.just(jitters),
            st.permutations(range(2 * len(jitters))),
            st.lists(st.integers(1, 10**9), min_size=len(jitters), max_size=len(jitters)),
        )
    )
)
def test_every_interleaving_within_the_buffers_pairs_every_cycle_with_its_own(case) -> None:
    jitters, order, gaps = case
    stamps = (START_NS + np.cumsum(gaps)).tolist()  # any increasing stamps
    pairing: StampPairing[tuple[str, int], tuple[str, int]] = StampPairing()
    pairs = []
    for side, k in interleaving(jitters, list(order)):
        take = pairing.predicted if side == 'prediction' else pairing.measured
        pair = take(stamps[k], (side, k))
        if pair is not None:
            pairs.append(pair)
    assert sorted(pairs) == [(('prediction', k), ('current', k)) for k in range(len(jitters))]
    assert (pairing.paired, pairing.unpaired, pairing.expired_predictions) == (len(pairs), 0, 0)
    assert pairing.waiting == (0, 0)


@settings(max_examples=300, deadline=None)
@given(
    st.lists(
        st.tuples(st.sampled_from(['prediction', 'current']), st.integers(0, 40)), max_size=200
    ),
    st.integers(1, 6),
    st.integers(1, 6),
)
def test_only_equal_stamps_pair_and_every_entry_pairs_once_at_most(
    events, prediction_capacity, measured_capacity
) -> None:
    pairing: StampPairing[int, int] = StampPairing(prediction_capacity, measured_capacity)
    used: set[tuple[str, int]] = set()
    for index, (side, stamp) in enumerate(events):
        take = pairing.predicted if side == 'prediction' else pairing.measured
        pair = take(stamp, index)
        if pair is None:
            continue
        prediction, current = pair
        assert events[prediction] == ('prediction', stamp)
        assert events[current] == ('current', stamp)
        assert ('p', prediction) not in used
        assert ('c', current) not in used
        used |= {('p', prediction), ('c', current)}
    currents = sum(side == 'current' for side, _ in events)
    assert pairing.paired + pairing.unpaired + pairing.waiting[1] == currents  # each counted once


def test_an_expired_current_is_counted_with_its_offset_to_the_nearest_prediction() -> None:
    pairing: StampPairing[int, int] = StampPairing(prediction_capacity=4, measured_capacity=2)
    for k in range(4):
        assert pairing.predicted(k * PERIOD_NS, k) is None
    assert pairing.offset_ns() is None  # nothing expired yet
    for k in range(3):  # 3 ms late: never equal, the first pushed out by the third
        assert pairing.measured(k * PERIOD_NS + 3_000_000, k) is None
    assert (pairing.unpaired, pairing.unpaired_streak) == (1, 1)
    assert pairing.offset_ns() == 3_000_000
    assert pairing.measured(3 * PERIOD_NS, 9) == (3, 9)
    assert pairing.unpaired_streak == 0
    with pytest.raises(ValueError, match='at least 1'):
        StampPairing(0, 8)


def test_a_time_base_that_steps_back_does_not_starve_the_buffer() -> None:
    """After a replay's loop the new stamps are the smallest: the stale ones go, not them."""
    pairing: StampPairing[int, int] = StampPairing(prediction_capacity=4, measured_capacity=2)
    for k in range(100, 110):  # never answered: the buffer is full of these
        pairing.predicted(k * PERIOD_NS, k)
    for k in range(5):  # the loop starts again at stamp 0
        assert pairing.predicted(k * PERIOD_NS, k) is None
        assert pairing.measured(k * PERIOD_NS, k) == (k, k)


# -- the adaptation loop ------------------------------------------------------------------------
def new_loop(robot: RobotConfig) -> AdaptationLoop:
    return AdaptationLoop.for_robot(robot, robot.joints, AdaptationConfig(time_constant_s=5.0))


def motion(n: int, seed: int = 0):
    rng = np.random.default_rng(seed)
    t = np.arange(n) * 0.008
    speed = rng.uniform(0.3, 0.8, 6)
    q = 0.6 * np.sin(speed * t[:, None])
    v = 0.6 * speed * np.cos(speed * t[:, None])
    model = rng.normal(0.0, 20.0, (n, 6))
    return q, v, model


@pytest.mark.parametrize('currents_first', [False, True])
def test_the_loop_learns_an_offset_whether_currents_come_before_or_after_their_prediction(
    mabi: RobotConfig, currents_first: bool
) -> None:
    """The replay publishes each cycle's currents before its reference: learnt all the same."""
    loop = new_loop(mabi)
    n = 1500
    q, v, model = motion(n)
    extra = np.array([40.0, 0, 0, 0, 0, 0])
    currents = (model + extra) / loop.torque_per_ampere
    served = []
    for k in range(n):
        stamp = START_NS + k * PERIOD_NS
        if currents_first:
            loop.measured_message(stamp, mabi.joints, list(currents[k]), mabi.joints, TOPIC)
        served.append(loop.serve(stamp, (q[k], v[k], np.zeros(6)), model[k]))
        if not currents_first:
            loop.measured_message(stamp, mabi.joints, list(currents[k]), mabi.joints, TOPIC)
    loop.learn_ready()
    assert loop.unpaired == 0
    assert loop.adapter.counters.updates == n
    assert served[-1][0] - model[-1, 0] == pytest.approx(40.0, abs=2.0)
    assert loop.take_reasons() == []


def test_currents_stamped_otherwise_are_said_once_with_the_offset_and_counted(
    mabi: RobotConfig, tmp_path: Path
) -> None:
    loop = new_loop(mabi)
    n = UNPAIRED_WARN_AFTER + MEASURED_CAPACITY + 20
    q, v, model = motion(n)
    said = []
    for k in range(n):
        stamp = START_NS + k * PERIOD_NS
        loop.serve(stamp, (q[k], v[k], np.zeros(6)), model[k])
        effort = list(model[k] / loop.torque_per_ampere)
        loop.measured_message(stamp + 3_000_000, mabi.joints, effort, mabi.joints, TOPIC)
        said += loop.take_reasons()
    assert loop.adapter.counters.updates == 0
    assert loop.unpaired == n - MEASURED_CAPACITY  # the last ones still wait
    assert len(said) == 1
    is_warning, line = said[0]
    assert is_warning
    assert TOPIC in line
    assert 'input_topic' in line
    assert '+3.000 ms' in line
    values = loop.report(mabi.joints)
    assert values['adaptation_unpaired'] == n - MEASURED_CAPACITY
    assert values['adaptation_unpaired_offset_ms'] == pytest.approx(3.0)
    assert values['adaptation_updates'] == 0
    _, line = loop.finish(tmp_path / 'rnea_lq', mabi.joints)
    assert f'{n - MEASURED_CAPACITY} currents unpaired' in line


def test_a_cycle_the_physics_prior_served_takes_its_currents_and_learns_nothing(
    mabi: RobotConfig,
) -> None:
    loop = new_loop(mabi)
    n = UNPAIRED_WARN_AFTER + MEASURED_CAPACITY + 20
    q, v, model = motion(n)
    for k in range(n):
        stamp = START_NS + k * PERIOD_NS
        loop.serve(stamp, (q[k], v[k], np.zeros(6)), model[k], learn=False)
        loop.measured_message(stamp, mabi.joints, [1.0] * 6, mabi.joints, TOPIC)
    assert loop.unpaired == 0
    assert loop.adapter.counters.updates == 0
    assert loop.adapter.counters.frozen == n
    ((is_warning, line),) = loop.take_reasons()
    assert not is_warning  # normal outside the training range: said once at the info level
    assert 'physics prior' in line
