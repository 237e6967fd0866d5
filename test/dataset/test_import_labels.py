"""The import summary says what train can learn from the bag: a bag without motor currents is
named as such, with the train option that still fits (joint torques) or what to map."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from id_learning.bag import bag_info
from id_learning.dataset.importer import ColumnSpec, ImportMapping, JointColumns, import_log

N_ROWS = 300
JOINTS = ('a', 'b')


def write_log(path: Path) -> Path:
    """CSV with t_s, q1, q2, dq1, dq2, i1, i2, tau1, tau2 on the 8 ms grid."""
    t = np.arange(N_ROWS) * 0.008
    phase = 2 * np.pi * 0.5 * t[:, None] + np.arange(len(JOINTS))
    q, dq = 0.2 * np.sin(phase), 0.2 * np.pi * np.cos(phase)
    header = 't_s,q1,q2,dq1,dq2,i1,i2,tau1,tau2'
    rows = np.column_stack([t, q, dq, 2 * np.cos(phase), 5 * np.cos(phase)])
    lines = [header, *(','.join(repr(float(x)) for x in row) for row in rows)]
    path.write_text('\n'.join(lines) + '\n', encoding='utf-8')
    return path


def mapping(*, velocity: bool, current: bool, torque: bool) -> ImportMapping:
    joints = tuple(
        JointColumns(
            name,
            ColumnSpec(f'q{j}', 'rad'),
            velocity=ColumnSpec(f'dq{j}', 'rad/s') if velocity else None,
            current=ColumnSpec(f'i{j}', 'A') if current else None,
            torque=ColumnSpec(f'tau{j}', 'Nm') if torque else None,
        )
        for j, name in enumerate(JOINTS, start=1)
    )
    return ImportMapping(joints=joints, time=ColumnSpec('t_s', 's'))


@pytest.mark.parametrize('torque', [False, True])
def test_a_bag_without_currents_is_named_with_what_train_can_do(
    tmp_path: Path, torque: bool
) -> None:
    log = write_log(tmp_path / 'log.csv')
    report = import_log(log, mapping(velocity=True, current=False, torque=torque), tmp_path / 'b')
    summary = report.summary()
    first, *notes = summary.splitlines()
    assert first.endswith('; velocities from the mapped columns')  # not cut mid-phrase
    assert [t.name for t in bag_info(tmp_path / 'b').topics] == ['/joint_states']  # it is true
    said = [line for line in notes if 'no motor currents were mapped' in line]
    assert len(said) == 1
    assert 'the bag holds no /motor_currents' in said[0]
    if torque:
        assert 'train with --target joint' in said[0]
    else:
        assert 'no joint torques, so train has no label in it' in said[0]
        assert '--target motor' in said[0]
        assert '--target joint' in said[0]


def test_a_bag_with_currents_says_nothing_of_labels_and_names_differentiated_velocities(
    tmp_path: Path,
) -> None:
    log = write_log(tmp_path / 'log.csv')
    report = import_log(log, mapping(velocity=False, current=True, torque=False), tmp_path / 'b')
    summary = report.summary()
    assert summary.splitlines()[0].endswith('; velocities differentiated from the positions')
    assert 'motor currents' not in summary
    assert report.has_current
    assert not report.has_joint_torque
