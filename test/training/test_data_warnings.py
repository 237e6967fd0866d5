"""What loading a recording warns of reaches the run: its datasets, run.json and report.md."""

from __future__ import annotations

import logging
import re
from dataclasses import replace

import numpy as np
from support import sine_recording, write_contract_bag

from id_learning.dataset.preprocess import PreprocessConfig
from id_learning.dataset.recording import Recording
from id_learning.evaluation.report import _data_warnings
from id_learning.physics.rigid_body import RigidBodyDynamics
from id_learning.robot.drives import current_from_motor_torque
from id_learning.training.datasets import DATA_WARNINGS, combine_datasets, load_datasets


def gravity_recording(robot, n_samples: int = 4000) -> Recording:
    """The sines' motion with the currents its URDF gravity torque and friction need."""
    recording = sine_recording(n_samples)
    friction = 0.02 * robot.limits.torque * recording.velocity  # viscous: no flat tops
    tau = RigidBodyDynamics.from_config(robot).gravity(recording.position) + friction
    return replace(recording, current=current_from_motor_torque(tau, robot.drives))


def _with_still_joint(recording: Recording, joint: int) -> Recording:
    position, velocity = recording.position.copy(), recording.velocity.copy()
    position[:, joint], velocity[:, joint] = 0.2, 0.0
    return Recording(recording.joints, recording.stamps_ns, position, velocity,
                     recording.current, None, source=recording.source)  # fmt: skip


def test_a_still_joint_is_carried_into_the_datasets_and_the_report(tmp_path, mabi):
    still = write_contract_bag(tmp_path / 'still', _with_still_joint(sine_recording(4000), 5))
    clean = write_contract_bag(tmp_path / 'clean', sine_recording(4000))

    datasets = load_datasets([still, clean], mabi, PreprocessConfig(), progress=False)
    combined = combine_datasets(datasets)

    # (The sines' currents also contradict the URDF's gravity: warned of too, not counted here.)
    warned = [w for w in combined.extra[DATA_WARNINGS] if 'does not move' in w]
    assert len(warned) == 1
    assert warned[0].startswith(f'{still}: joint_6 does not move')
    assert not any('does not move' in w for w in datasets[1].extra[DATA_WARNINGS])
    lines = _data_warnings(combined)
    assert lines[0].startswith('**Data warnings**')
    assert f'- {warned[0]}' in lines


def test_a_recording_without_findings_adds_nothing_to_the_report(tmp_path, mabi):
    bag = write_contract_bag(tmp_path / 'clean', gravity_recording(mabi, 16_000))  # 128 s

    combined = combine_datasets(load_datasets([bag], mabi, PreprocessConfig(), progress=False))

    assert combined.extra[DATA_WARNINGS] == []
    assert _data_warnings(combined) == []
    assert np.isfinite(combined.tau).all()


def test_a_short_test_part_is_said_with_the_length_to_record(tmp_path, mabi, caplog):
    # Probe 15 (A73): train on a 26 s bag reported test RMSEs without a caveat.
    bag = write_contract_bag(tmp_path / 'short', gravity_recording(mabi))  # 32 s, 30 % test
    with caplog.at_level(logging.WARNING):
        combined = combine_datasets(load_datasets([bag], mabi, PreprocessConfig(), progress=False))
    (note,) = combined.extra[DATA_WARNINGS]
    assert re.search(r'the test part holds \d\.\d s of motion, less than 30 s', note)
    assert 'record longer (at 30% for the test part, 100 s or more)' in note
    assert note in caplog.text
    assert any(note in line for line in _data_warnings(combined))
