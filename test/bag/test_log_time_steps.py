"""A clock step on the recorder: log times step back, header stamps advance.

rosbag2 readers return messages in log-time order, so the samples logged after the recorder's
clock stepped back come before or among earlier ones. The header stamp is the sample's time:
such a topic is read in header-stamp order, with a warning naming the topic, the sample and the
step, and inspect reports the step instead of backward stamps. Header stamps a sender stepped
back (log times advancing) are refused as before, and so are repeated stamps.
"""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st
from support import sine_recording

from id_learning.bag import JOINT_STATE, BagWriter, encode_joint_state, read_joint_states
from id_learning.bag.messages import clock_step
from id_learning.dataset.inspect import inspect_bag
from id_learning.dataset.recording import Recording, load_recording
from id_learning.errors import DatasetError

PERIOD_NS = 8_000_000
LATENCY_NS = 1_000_000


def write_bag(path: Path, recording: Recording, log_ns: np.ndarray) -> Path:
    """The recording's samples in their order, each logged at the given time on both topics."""
    empty = np.empty(0)
    with BagWriter(path) as writer:
        for topic in ('/joint_states', '/motor_currents'):
            writer.add_topic(topic, JOINT_STATE)
        for k, stamp in enumerate(recording.stamps_ns.tolist()):
            js = encode_joint_state(
                stamp, recording.joints, recording.position[k], recording.velocity[k], empty
            )
            mc = encode_joint_state(stamp, recording.joints, empty, empty, recording.current[k])
            writer.write('/joint_states', int(log_ns[k]), js)
            writer.write('/motor_currents', int(log_ns[k]), mc)
    return path


def stepped_logs(stamps: np.ndarray, at: int, step_ns: int) -> np.ndarray:
    """Log times a recorder gives when its clock steps back by step_ns before sample ``at``."""
    logs = stamps + LATENCY_NS
    logs[at:] -= step_ns
    return logs


@pytest.mark.parametrize(
    ('n', 'at', 'step_ns'),
    [
        (1500, 900, 10_000_000_000),  # the later samples interleave with earlier ones
        (500, 300, 10_000_000_000),  # the later samples all come first in log-time order
        (500, 250, 100_000_000),  # a step of 12.5 periods
    ],
)
def test_a_clock_step_on_the_recorder_is_read_in_header_stamp_order(
    tmp_path: Path, mabi, caplog: pytest.LogCaptureFixture, n: int, at: int, step_ns: int
) -> None:
    recording = sine_recording(n)
    bag = write_bag(tmp_path / 'bag', recording, stepped_logs(recording.stamps_ns, at, step_ns))
    # as read: the header stamps go back where the log times interleave
    stamps, _ = read_stamps_in_log_order(bag)
    assert (np.diff(stamps) < 0).any()

    with caplog.at_level(logging.WARNING, logger='id_learning.bag.reader'):
        loaded = load_recording(bag, mabi)
    np.testing.assert_array_equal(loaded.stamps_ns, recording.stamps_ns)
    np.testing.assert_array_equal(loaded.position, recording.position)
    np.testing.assert_array_equal(loaded.current, recording.current)
    warnings = [r.getMessage() for r in caplog.records if 'clock step' in r.getMessage()]
    assert len(warnings) == 2  # once per topic
    for topic, warning in zip(('/joint_states', '/motor_currents'), warnings, strict=True):
        assert f'{topic}: the log times step back by {step_ns * 1e-9:.3f} s at sample {at} ' in (
            warning
        )
        assert 'a clock step on the recording machine' in warning
        assert warning.endswith('read in header-stamp order')

    series = read_joint_states(bag, '/joint_states')
    np.testing.assert_array_equal(series.log_ns, stepped_logs(recording.stamps_ns, at, step_ns))


def read_stamps_in_log_order(bag: Path) -> tuple[np.ndarray, np.ndarray]:
    from id_learning.bag import decode_joint_state, iter_raw

    pairs = [(decode_joint_state(d).stamp_ns, t) for _, t, d in iter_raw(bag, ['/joint_states'])]
    stamps, logs = zip(*pairs, strict=True)
    return np.array(stamps), np.array(logs)


def test_inspect_names_the_log_time_step_not_backward_stamps(tmp_path: Path, mabi) -> None:
    recording = sine_recording(1500)
    logs = stepped_logs(recording.stamps_ns, 900, 10_000_000_000)
    report = inspect_bag(write_bag(tmp_path / 'bag', recording, logs), mabi)
    for name in ('/joint_states', '/motor_currents'):
        timing = report.topic(name).timing
        assert (timing.backward_count, timing.gap_count, timing.repeated_count) == (0, 0, 0)
        assert report.topic(name).contradictions == 0
    assert report.contract.is_met
    lines = [line for line in report.problems if 'clock step' in line]
    assert len(lines) == 2
    assert lines[0].startswith('/joint_states: the log times step back by 10.000 s at sample 900')
    assert 'timed here in header-stamp order' in lines[0]
    assert f'the header stamps span {1499 * PERIOD_NS * 1e-9:.3f} s' in lines[0]


@pytest.mark.parametrize(
    'back_ns',
    [
        1_003_000_000,  # off the grid: header-stamp order would interleave the two runs
        1_000_000_000,  # on the grid: header-stamp order would repeat stamps
        3_600_000_000_000,  # an hour: header-stamp order would leave a gap
    ],
)
def test_header_stamps_a_sender_stepped_back_are_still_refused(
    tmp_path: Path, mabi, back_ns: int
) -> None:
    recording = sine_recording(600)
    stamps = recording.stamps_ns.copy()
    stamps[400:] -= back_ns
    logs = recording.stamps_ns + LATENCY_NS  # the recorder's clock runs on
    assert clock_step(stamps, logs) is None
    sent = Recording(
        recording.joints, stamps, recording.position, recording.velocity, recording.current, None
    )
    bag = write_bag(tmp_path / 'bag', sent, logs)
    with pytest.raises(
        DatasetError, match=r'/joint_states: time stamp goes backwards at sample 400'
    ):
        load_recording(bag, mabi)


def test_a_clock_step_with_a_repeated_header_stamp_is_still_refused(tmp_path: Path, mabi) -> None:
    recording = sine_recording(1500)
    stamps = recording.stamps_ns.copy()
    stamps[1200] = stamps[1199]
    logs = stepped_logs(recording.stamps_ns, 900, 10_000_000_000)
    assert clock_step(stamps, logs) is None
    sent = Recording(
        recording.joints, stamps, recording.position, recording.velocity, recording.current, None
    )
    with pytest.raises(DatasetError, match='time stamp'):
        load_recording(write_bag(tmp_path / 'bag', sent, logs), mabi)


@settings(max_examples=40, deadline=None)
@given(
    n=st.integers(20, 400),
    share=st.floats(0.05, 0.95),
    periods=st.integers(2, 2000),
)
def test_clock_step_recovers_the_write_order(n: int, share: float, periods: int) -> None:
    """Any step back of two periods or more, anywhere, is found, sized and undone.

    Except a step back by the whole recording's length: the log times then run on without a
    break from the last sample to the first, as if the sender had stamped the later samples
    back: the data cannot tell, and the stamps are refused (the test below).
    """
    stamps = 10**18 + np.arange(n, dtype=np.int64) * PERIOD_NS
    at = min(max(1, round(share * n)), n - 1)
    assume(abs(periods - n) > 1)
    logs = stepped_logs(stamps, at, periods * PERIOD_NS)
    read = np.argsort(logs, kind='stable')  # what a reader returns: log-time order
    step = clock_step(stamps[read], logs[read])
    assert step is not None
    np.testing.assert_array_equal(stamps[read][step.order], stamps)
    assert (step.sample, step.step_ns, step.steps) == (at, periods * PERIOD_NS, 1)


@pytest.mark.parametrize('k', [1, 100, 198])
def test_one_sample_out_of_place_is_left_to_be_refused(k: int) -> None:
    """A swapped pair fits a sender's stamp as well as a recorder's clock: not reordered."""
    stamps = 10**18 + np.arange(200, dtype=np.int64) * PERIOD_NS
    logs = stamps + LATENCY_NS
    stamps[[k, k + 1]] = stamps[[k + 1, k]]
    assert clock_step(stamps, logs) is None


def test_a_step_back_by_the_recordings_length_is_left_to_be_refused() -> None:
    """Log times that run on without a break fit a sender's stamps as well: not reordered."""
    stamps = 10**18 + np.arange(20, dtype=np.int64) * PERIOD_NS
    logs = stepped_logs(stamps, 10, 20 * PERIOD_NS)
    read = np.argsort(logs, kind='stable')
    assert clock_step(stamps[read], logs[read]) is None
