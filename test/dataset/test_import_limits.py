"""Import of values beyond the robot's limits: limit questions, degrees, beyond_limits_policy."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import yaml

from id_learning.dataset.import_mapping import load_import_mapping
from id_learning.dataset.importer import ColumnSpec, ImportMapping, JointColumns, import_log
from id_learning.dataset.recording import load_recording
from id_learning.errors import ConfigError, DatasetError
from id_learning.robot import RobotConfig, load_robot_config

REPO = Path(__file__).resolve().parents[2]
N_ROWS = 400
GARBAGE_A = 45.0  # past the gate (2 x 10 A), under the implausible level (10 x 10 A)


@pytest.fixture(scope='module')
def panda() -> RobotConfig:
    """Franka Panda: joint 1 within +-2.8973 rad; currents of 10 A give its 87 N*m limit."""
    return load_robot_config(REPO / 'config/panda.yaml')


def motion(robot: RobotConfig) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Stamps [s] on the 1 ms grid, positions [rad] around mid-range and currents [A] of 2 A."""
    t = np.arange(N_ROWS) * robot.ipo_period_s
    limits = robot.limits
    middle = 0.5 * (limits.position_lower + limits.position_upper)
    phase = 2 * np.pi * 0.5 * t[:, None] + np.arange(len(robot.joints))
    return t, middle + 0.2 * np.sin(phase), 2.0 * np.cos(phase)


def write_log(path: Path, t: np.ndarray, q: np.ndarray, i: np.ndarray | None = None) -> Path:
    """CSV with header t_s, q1..qn (and i1..in), exact float text (repr)."""
    n = q.shape[1]
    header = ['t_s'] + [f'q{j}' for j in range(1, n + 1)]
    blocks = [t, q]
    if i is not None:
        header += [f'i{j}' for j in range(1, n + 1)]
        blocks.append(i)
    lines = [','.join(header)]
    lines += [','.join(repr(float(x)) for x in row) for row in np.column_stack(blocks)]
    path.write_text('\n'.join(lines) + '\n', encoding='utf-8')
    return path


def mapping_for(robot: RobotConfig, currents: bool = False, **options: object) -> ImportMapping:
    """Positions in rad (velocity differentiated), currents in A when ``currents``."""
    joints = tuple(
        JointColumns(
            name,
            ColumnSpec(f'q{j}', 'rad'),
            current=ColumnSpec(f'i{j}', 'A') if currents else None,
        )
        for j, name in enumerate(robot.joints, start=1)
    )
    return ImportMapping(joints=joints, time=ColumnSpec('t_s', 's'), **options)  # type: ignore[arg-type]


def test_a_radians_column_2_percent_past_a_limit_is_a_limit_question_not_degrees(
    tmp_path: Path, panda: RobotConfig
) -> None:
    t, q, _ = motion(panda)
    upper = panda.limits.position_upper[0]
    joint_range = upper - panda.limits.position_lower[0]
    q[:, 0] = np.linspace(2.5, upper + 0.02 * joint_range, N_ROWS)  # rad, ends 2 % past
    first = int(np.argmax(q[:, 0] > upper + 0.05))  # the gate allows 0.05 rad
    assert 0 < first < N_ROWS - 1
    log = write_log(tmp_path / 'panda.csv', t, q)
    with pytest.raises(DatasetError) as caught:
        import_log(log, mapping_for(panda), tmp_path / 'bag', robot=panda)
    text = str(caught.value)
    assert text.startswith(f'{log}: line {first + 2}, ')  # header is line 1
    assert "column 'q1' (joint panda_joint1 position)" in text
    assert f'{q[first, 0]:.6g} rad' in text
    assert 'beyond the upper limit 2.8973 rad' in text
    share = 100 * (q[first, 0] - upper) / joint_range
    assert f"{share:.3g} % of the joint's range" in text
    assert 'the farthest value of this column lies 2 % beyond' in text  # the log's 2 %
    assert 'limit question' in text
    assert 'URDF' in text
    assert 'encoder offset' in text
    assert 'degrees' not in text
    assert 'set its unit' not in text
    assert not (tmp_path / 'bag').exists()


def test_a_degrees_column_mapped_as_radians_still_gets_the_degrees_hint(
    tmp_path: Path, panda: RobotConfig
) -> None:
    t, q, _ = motion(panda)
    q[:, 0] = np.linspace(0.0, 150.0, N_ROWS)  # degrees; joint 1 spans +-2.9 rad
    assert np.ptp(q[:, 0]) > 2 * 2 * 2.8973
    log = write_log(tmp_path / 'panda.csv', t, q)
    with pytest.raises(
        DatasetError,
        match=r"column 'q1' \(joint panda_joint1 position\): .* read as degrees every value "
        r"fits the limits, and in radians the values span over 2 x the joint's range: set its "
        r'unit: deg',
    ):
        import_log(log, mapping_for(panda), tmp_path / 'bag', robot=panda)


def garbage_log(path: Path, robot: RobotConfig, rows: np.ndarray, amps: float) -> Path:
    """A log whose joint 3 current is ``amps`` in ``rows``."""
    t, q, i = motion(robot)
    i[rows, 2] = amps
    return write_log(path, t, q, i)


def test_rows_between_the_gate_and_implausible_are_refused_by_default_naming_them(
    tmp_path: Path, panda: RobotConfig
) -> None:
    rows = np.array([40, 170, 171, 300])
    log = garbage_log(tmp_path / 'ur.csv', panda, rows, GARBAGE_A)
    with pytest.raises(DatasetError) as caught:
        import_log(log, mapping_for(panda, currents=True), tmp_path / 'bag', robot=panda)
    text = str(caught.value)
    assert text.startswith(f'{log}: line 42, ')
    assert (
        "column 'i3' (joint panda_joint3 current): 45 A is 25 A beyond 2 x its limit 10 A" in text
    )
    assert '(4 rows past the plausibility gate)' in text
    assert 'set beyond_limits_policy: drop' in text
    assert not (tmp_path / 'bag').exists()


def test_rows_between_the_gate_and_implausible_are_dropped_and_reported_under_drop(
    tmp_path: Path, panda: RobotConfig
) -> None:
    rows = np.array([40, 170, 171, 300])
    log = garbage_log(tmp_path / 'ur.csv', panda, rows, GARBAGE_A)
    mapping = mapping_for(panda, currents=True, beyond_limits_policy='drop')
    report = import_log(log, mapping, tmp_path / 'bag', robot=panda)
    assert [line for line, _ in report.dropped_rows] == list(rows + 2)
    for _, reason in report.dropped_rows:
        assert reason.startswith(
            "beyond the limits, column 'i3' (joint panda_joint3 current): 45 A"
        )
    summary = report.summary()
    assert '4 rows dropped: lines 42, 172, 173, 302' in summary
    assert "first of 4: line 42, beyond the limits, column 'i3'" in summary
    recording = load_recording(tmp_path / 'bag', panda)
    assert recording.n_samples == N_ROWS - len(rows)
    assert recording.current is not None
    assert np.abs(recording.current).max() <= 2.0


def test_more_than_half_of_the_rows_to_drop_are_refused_whatever_the_policies(
    tmp_path: Path, panda: RobotConfig
) -> None:
    beyond = np.arange(0, N_ROWS, 5)  # 20 %
    log = garbage_log(tmp_path / 'few.csv', panda, beyond, GARBAGE_A)
    mapping = mapping_for(
        panda, currents=True, beyond_limits_policy='drop', implausible_policy='drop'
    )
    report = import_log(log, mapping, tmp_path / 'few', robot=panda)
    assert len(report.dropped_rows) == len(beyond)

    many = np.flatnonzero(np.arange(N_ROWS) % 5 < 3)  # 60 %
    log = garbage_log(tmp_path / 'many.csv', panda, many, GARBAGE_A)
    with pytest.raises(DatasetError, match=r'240 of 400 rows .* too many to drop'):
        import_log(log, mapping, tmp_path / 'many', robot=panda)
    assert not (tmp_path / 'many').exists()

    t, q, i = motion(panda)  # 30 % implausible and 30 % beyond: 60 % to drop in all
    i[np.arange(N_ROWS) % 10 < 3, 2] = 1e3
    i[np.arange(N_ROWS) % 10 >= 7, 2] = GARBAGE_A
    log = write_log(tmp_path / 'both.csv', t, q, i)
    with pytest.raises(DatasetError, match=r'240 of 400 rows .* too many to drop'):
        import_log(log, mapping, tmp_path / 'both', robot=panda)


def test_beyond_limits_policy_is_read_from_the_mapping_yaml_and_checked(
    tmp_path: Path, panda: RobotConfig
) -> None:
    spec = {
        'time': {'column': 't_s', 'unit': 's'},
        'beyond_limits_policy': 'drop',
        'joints': [
            {'name': name, 'position': {'column': f'q{j}', 'unit': 'rad'}}
            for j, name in enumerate(panda.joints, start=1)
        ],
    }
    path = tmp_path / 'mapping.yaml'
    path.write_text(yaml.safe_dump(spec), encoding='utf-8')
    assert load_import_mapping(path).beyond_limits_policy == 'drop'
    assert load_import_mapping(REPO / 'config/import_example.yaml').beyond_limits_policy == (
        'refuse'
    )
    spec['beyond_limits_policy'] = 'keep'
    path.write_text(yaml.safe_dump(spec), encoding='utf-8')
    with pytest.raises(ConfigError, match="beyond_limits_policy must be 'refuse' or 'drop'"):
        load_import_mapping(path)
