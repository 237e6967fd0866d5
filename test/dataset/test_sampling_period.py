"""A topic sampled at another period than the robot's IPO period: one check for inspect and replay.

It agrees with train's own rule (``preprocess.regularise`` after ``load_recording``): what
``sampling_problem`` names, train refuses, and what it passes, train regularises without refusal.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from support import sine_recording

from id_learning.dataset.inspect import inspect_bag
from id_learning.dataset.preprocess import PreprocessConfig, regularise
from id_learning.dataset.recording import write_recording
from id_learning.dataset.sampling_grid import SAMPLING_TOLERANCE, sampling_problem
from id_learning.errors import DatasetError

PERIOD_S = 0.008
START_NS = 1_767_225_600_000_000_000


def uniform(step_ms: float, n: int = 600) -> np.ndarray:
    return START_NS + np.round(np.arange(n) * step_ms * 1e6).astype(np.int64)


def test_the_tolerance_is_trains() -> None:
    assert PreprocessConfig().jitter_tolerance == SAMPLING_TOLERANCE


@pytest.mark.parametrize('step_ms', [7.0, 7.5, 4.0, 0.5, 9.0, 12.0])
def test_a_bag_off_the_ipo_period_is_named_with_both_periods_where_train_refuses_it(
    step_ms: float,
) -> None:
    stamps = uniform(step_ms)
    line = sampling_problem(stamps, PERIOD_S, '/joint_states')
    assert line is not None
    assert line.startswith(f'/joint_states: sampled every {step_ms:g} ms')
    assert "the robot's IPO period is 8 ms" in line
    recording = replace(sine_recording(len(stamps)), stamps_ns=stamps)
    with pytest.raises(DatasetError, match='IPO'):
        regularise(recording, PERIOD_S)


def test_every_second_ipo_cycle_is_named_as_interpolated_and_long_steps_as_gaps() -> None:
    line = sampling_problem(uniform(16.0), PERIOD_S, '/joint_states')
    assert line is not None
    assert 'one sample every 2 IPO cycles' in line
    line = sampling_problem(uniform(100.0), PERIOD_S, '/joint_states')
    assert line is not None
    assert 'as gaps' in line


@settings(max_examples=60, deadline=None)
@given(
    jitter=st.lists(st.floats(-0.2, 0.2), min_size=50, max_size=300),
    gap_at=st.integers(1, 49),
    gap=st.integers(1, 2),
)
def test_stamps_on_the_grid_within_the_tolerance_pass_as_train_passes_them(
    jitter: list[float], gap_at: int, gap: int
) -> None:
    slots = np.arange(len(jitter))
    slots[gap_at:] += gap - 1  # one step of `gap` whole periods (train refuses over 3)
    stamps = START_NS + np.round((slots + np.array(jitter)) * PERIOD_S * 1e9).astype(np.int64)
    stamps[0] = START_NS  # the grid is laid from the first stamp, as train lays it
    assert sampling_problem(stamps, PERIOD_S, 'x') is None
    recording = replace(sine_recording(len(stamps)), stamps_ns=stamps)
    regularise(recording, PERIOD_S)  # does not raise


def test_inspect_reports_a_4_ms_bag_against_the_8_ms_robot(mabi, tmp_path: Path) -> None:
    recording = sine_recording(1500, period_s=0.004)
    bag = write_recording(recording, tmp_path / 'ipo4')
    problems = inspect_bag(bag, robot=mabi).problems
    for topic in ('/joint_states', '/motor_currents'):
        assert any(
            p.startswith(f'{topic}: sampled every 4 ms') and 'IPO period is 8 ms' in p
            for p in problems
        ), problems
    assert not any('sampled every' in p for p in inspect_bag(bag).problems)  # no robot, no IPO
    clean = write_recording(sine_recording(1500), tmp_path / 'ipo8')
    assert not any('sampled every' in p for p in inspect_bag(clean, robot=mabi).problems)


def test_a_robot_config_at_twice_the_log_s_period_is_named_not_the_log() -> None:
    """An 8 ms log with a 16 ms robot config: both periods and the config named as the remedy."""
    stamps = uniform(8.0)
    recording = replace(sine_recording(len(stamps)), stamps_ns=stamps, source='base')
    with pytest.raises(DatasetError) as err:
        regularise(recording, 0.016)
    said = str(err.value)
    assert said.startswith("base: sampled every 8 ms (median stamp step), the robot's IPO period")
    assert 'is 16 ms' in said
    assert 'give the robot config whose ipo_period_s it has' in said
    assert 'resample the log first' not in said
