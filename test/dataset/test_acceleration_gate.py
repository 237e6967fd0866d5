"""The predictor's acceleration gate where a recording is read: train refuses, inspect lists.

The predictor rejects a sample whose acceleration exceeds ``ACCELERATION_FACTOR`` x its limit;
the accelerations it is sent are the controller inputs' (velocities smoothed at the robot's
``input_smoothing_hz``, differentiated). A recording whose controller accelerations break the
gate is refused by ``load_recording`` and listed by ``inspect``, naming joint and sample.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from support import sine_recording, write_contract_bag

from id_learning.dataset.accelerations import (
    acceleration_excess,
    check_controller_accelerations,
    controller_accelerations,
)
from id_learning.dataset.inspect import inspect_bag
from id_learning.dataset.plausibility import ACCELERATION_FACTOR
from id_learning.dataset.recording import load_recording
from id_learning.errors import DatasetError
from id_learning.robot import RobotConfig

PERIOD_S = 0.008
N = 1500  # 12 s


def with_acceleration_limits(robot: RobotConfig, limits: np.ndarray) -> RobotConfig:
    return replace(robot, limits=replace(robot.limits, acceleration=np.asarray(limits, float)))


joint_motion = st.tuples(
    st.floats(0.05, 0.3),  # amplitude [rad]
    st.floats(0.2, 1.0),  # frequency [Hz]
    st.one_of(st.floats(0.2, 0.8), st.floats(1.3, 4.0)),  # peak over the gate
)


@settings(max_examples=30)
@given(motions=st.lists(joint_motion, min_size=6, max_size=6))
def test_the_gate_refuses_exactly_the_joints_whose_peak_lies_beyond(mabi, motions) -> None:
    """Sines whose true peak acceleration lies clearly below or above the gate, per joint."""
    amplitude, frequency, over = (np.array(x) for x in zip(*motions, strict=True))
    peak = amplitude * (2 * np.pi * frequency) ** 2
    robot = with_acceleration_limits(mabi, peak / (ACCELERATION_FACTOR * over))
    t = np.arange(N) * PERIOD_S
    phase = 2 * np.pi * frequency * t[:, None]
    q, v = amplitude * np.sin(phase), amplitude * 2 * np.pi * frequency * np.cos(phase)
    stamps = 1_767_225_600_000_000_000 + np.round(t * 1e9).astype(np.int64)

    excess = acceleration_excess(robot, stamps, controller_accelerations(robot, stamps, q, v))

    beyond = over > 1.0
    assert [e is not None for e in excess] == beyond.tolist()
    for j, e in enumerate(excess):
        if e is not None:
            assert e.peak == pytest.approx(peak[j], rel=0.05)
            assert e.limit == robot.limits.acceleration[j]
    if not beyond.any():
        check_controller_accelerations(robot, stamps, q, v, where='w')
        return
    with pytest.raises(
        DatasetError, match=r'^w: sample \d+ \(stamp \d+ ns\), joint joint_'
    ) as err:
        check_controller_accelerations(robot, stamps, q, v, where='w')
    assert 'the predictor rejects such samples' in str(err.value)
    assert 'deg/s^2' not in str(err.value)  # differentiated from checked velocities: no unit issue


def test_gaps_and_bad_rows_are_not_differentiated_across(mabi) -> None:
    """A stretch ends at a gap and at a non-finite row; one too short for the filter is NaN."""
    recording = sine_recording(600)
    stamps = recording.stamps_ns.copy()
    stamps[300:] += 10 * 8_000_000  # a 10-period gap: a jump no arm makes within one step
    q, v = recording.position.copy(), recording.velocity.copy()
    q[300:] += 0.5
    v[100] = np.nan
    a = controller_accelerations(mabi, stamps, q, v)
    assert np.isnan(a[100]).all()
    assert np.isfinite(a[:100]).all()
    assert np.isfinite(a[101:]).all()
    assert np.abs(a[290:310]).max() < ACCELERATION_FACTOR * mabi.limits.acceleration.min()
    assert np.isnan(controller_accelerations(mabi, stamps[:5], q[:5], v[:5])).all()


@pytest.fixture(scope='module')
def sines(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return write_contract_bag(tmp_path_factory.mktemp('sines') / 'bag', sine_recording(3000))


def test_train_refuses_a_recording_beyond_the_config_s_limits(mabi, sines: Path) -> None:
    tiny = with_acceleration_limits(mabi, np.full(6, 0.01))
    with pytest.raises(DatasetError, match=r'/joint_states: sample \d+ .*acceleration') as err:
        load_recording(sines, tiny)
    assert 'check limits.acceleration in the robot config' in str(err.value)
    assert load_recording(sines, mabi).n_samples == 3000


def test_inspect_lists_each_joint_beyond_naming_its_first_sample(mabi, sines: Path) -> None:
    tiny = with_acceleration_limits(mabi, np.full(6, 0.01))
    lines = [p for p in inspect_bag(sines, tiny).problems if 'acceleration beyond' in p]
    assert len(lines) == 6
    assert lines[0].startswith('/joint_states: joint_1 acceleration beyond 2 x its limit 0.01 ')
    assert 'the first at sample' in lines[0]
    assert 'train and the replay refuse the bag' in lines[0]
    assert not [p for p in inspect_bag(sines, mabi).problems if 'acceleration' in p]
