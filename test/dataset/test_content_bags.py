"""What a bag's signals lack, in the words of load_recording (train, diagnose) and inspect."""

from __future__ import annotations

import logging
from dataclasses import replace

import numpy as np
import pytest
from support import sine_recording

from id_learning.dataset.inspect import inspect_bag, render_report
from id_learning.dataset.recording import (
    Recording,
    check_recording_content,
    load_recording,
    write_recording,
)
from id_learning.diagnosis import DiagnosisConfig
from id_learning.diagnosis.problem import as_datasets
from id_learning.errors import DatasetError

N = 500  # 4.0 s at 8 ms


def changed(recording: Recording, **arrays: np.ndarray) -> Recording:
    return replace(recording, **arrays)


def bag_of(tmp_path, recording: Recording, topics=None):
    return write_recording(recording, tmp_path / 'bag', topics)


def test_a_zero_current_of_one_joint_is_refused_and_listed_by_inspect(tmp_path, mabi):
    recording = sine_recording(N)
    current = recording.current.copy()
    current[:, 2] = 0.0
    bag = bag_of(tmp_path, changed(recording, current=current))
    with pytest.raises(DatasetError) as caught:
        load_recording(bag, mabi)
    assert str(caught.value) == (
        f'{bag}: joint_3: motor current is exactly 0 A in every sample (all {N} samples, 4.0 s): '
        'no torque was recorded'
    )
    for robot in (None, mabi):
        problems = inspect_bag(bag, robot).problems
        assert problems == (
            '/motor_currents: joint_3: motor current is exactly 0 A in every sample (all '
            f'{N} samples, 4.0 s): no torque was recorded; train and diagnose refuse the bag',
        )


def test_a_constant_current_is_refused_naming_its_value(tmp_path, mabi):
    recording = sine_recording(N)
    current = recording.current.copy()
    current[:, 5] = 1.25
    with pytest.raises(DatasetError, match=r'joint_6: motor current is 1.25 A in every sample'):
        load_recording(bag_of(tmp_path, changed(recording, current=current)), mabi)


def test_joint_torques_are_the_label_for_the_joint_target(tmp_path, mabi):
    recording = sine_recording(N)
    torque = 100.0 * recording.current
    torque[:, 1] = 0.0
    bag = bag_of(tmp_path, changed(recording, current=None, joint_torque=torque))
    with pytest.raises(DatasetError, match=r'joint_2: joint torque is exactly 0 N\*m in every'):
        load_recording(bag, mabi, require_current=False)
    problems = inspect_bag(bag, mabi).problems
    assert any(
        '/joint_states: joint_2: joint torque is exactly 0 N*m' in line for line in problems
    )


def test_a_joint_that_does_not_move_is_warned_everywhere(tmp_path, mabi, caplog):
    recording = sine_recording(N)
    position, velocity = recording.position.copy(), recording.velocity.copy()
    position[:, 3], velocity[:, 3] = 0.0, 0.0
    bag = bag_of(tmp_path, changed(recording, position=position, velocity=velocity))
    line = (
        'joint_4 does not move: its position spans 0 rad over 4.0 s (less than 0.001 rad), so '
        'its friction and inertia cannot be identified from this recording'
    )
    with caplog.at_level(logging.WARNING, logger='id_learning.dataset.content'):
        loaded = load_recording(bag, mabi)
    assert [record.getMessage() for record in caplog.records] == [f'{bag}: {line}']
    assert loaded.n_samples == N
    assert inspect_bag(bag).problems == (f'/joint_states: {line}',)
    assert f'  - /joint_states: {line}' in render_report(inspect_bag(bag, mabi))


def test_a_recording_where_no_joint_moves_is_refused(tmp_path, mabi):
    recording = sine_recording(N)
    position = np.repeat(recording.position[:1], N, axis=0)
    still = changed(recording, position=position, velocity=np.zeros_like(position))
    bag = bag_of(tmp_path, still)
    with pytest.raises(
        DatasetError, match=r'no joint moves: nothing to identify \(every position'
    ):
        load_recording(bag, mabi)
    (problem,) = inspect_bag(bag).problems
    assert problem.startswith('/joint_states: no joint moves: nothing to identify')
    assert problem.endswith('train and diagnose refuse the bag')
    # Diagnosis refuses it also when handed the recording in code.
    with pytest.raises(DatasetError, match='no joint moves'):
        as_datasets(still, mabi, DiagnosisConfig())


def test_clipped_currents_are_warned_with_joint_value_and_share(tmp_path, mabi, caplog):
    recording = sine_recording(N)
    current = recording.current.copy()
    current[:, 1] = np.clip(current[:, 1], -1.5, 1.5)  # a 2 A sine clipped at 1.5 A
    bag = bag_of(tmp_path, changed(recording, current=current))
    with caplog.at_level(logging.WARNING, logger='id_learning.dataset.content'):
        load_recording(bag, mabi)
    (message,) = [record.getMessage() for record in caplog.records]
    upper, lower = (100 * np.mean(current[:, 1] == level) for level in (1.5, -1.5))
    assert upper > 10
    assert message == (
        f'{bag}: joint_2: motor current sits at 1.5 A in {upper:.3g} % and at -1.5 A in '
        f'{lower:.3g} % of the {N} samples (flat tops at its extremes): clipped by the drive or '
        'the logger, so the label is wrong wherever the torque went beyond'
    )
    (problem,) = inspect_bag(bag).problems
    assert problem.startswith('/motor_currents: joint_2: motor current sits at 1.5 A')


def test_currents_in_milliamperes_are_a_problem_of_inspect_with_a_robot(tmp_path, mabi):
    recording = sine_recording(N)
    bag = bag_of(tmp_path, changed(recording, current=1000.0 * recording.current))
    with pytest.raises(DatasetError, match=r"check the currents' unit \(mA for A\?\)"):
        load_recording(bag, mabi)
    assert inspect_bag(bag).problems == ()  # no drives to compare with
    problems = inspect_bag(bag, mabi).problems
    assert len(problems) == 6
    assert problems[0].startswith(
        '/motor_currents: joint_1 effort beyond 2 x what the torque limit needs in '
    )
    assert "check the currents' unit (A, not mA)" in problems[0]
    text = render_report(inspect_bag(bag, mabi))
    assert 'joint_1  effort' in text


def test_a_twin_recording_passes_without_a_warning(short_twin):
    _, result = short_twin
    assert check_recording_content(result.recording) == ()
    assert check_recording_content(result.recording, 'motor') == ()
