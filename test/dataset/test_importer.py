"""Importing CSV and NPZ logs into bags of the bag contract."""

from __future__ import annotations

import logging
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import pytest

from id_learning.bag import read_joint_states
from id_learning.dataset.importer import (
    DEFAULT_START_NS,
    ColumnSpec,
    ImportMapping,
    JointColumns,
    import_log,
    load_import_mapping,
)
from id_learning.dataset.recording import load_recording
from id_learning.errors import ConfigError, DatasetError
from id_learning.robot import RobotConfig, load_robot_config

REPO = Path(__file__).resolve().parents[2]
ROBOT_YAML = REPO / 'config/mabi_max100.yaml'
EXAMPLE_MAPPING = REPO / 'config/import_example.yaml'
PERIOD_NS = 8_000_000
RNG_SEED = 20240611


@pytest.fixture(scope='module')
def robot() -> RobotConfig:
    return load_robot_config(ROBOT_YAML)


def write_csv(
    path: Path,
    header: Sequence[str] | None,
    rows: np.ndarray | Sequence[Sequence[object]],
    *,
    delimiter: str = ',',
    preamble: Sequence[str] = (),
) -> Path:
    """Write a CSV with exact float text (repr), optional comment preamble and header."""
    lines = list(preamble)
    if header is not None:
        lines.append(delimiter.join(header))
    lines += [
        delimiter.join(repr(float(v)) if _is_real(v) else str(v) for v in row) for row in rows
    ]
    path.write_text('\n'.join(lines) + '\n', encoding='utf-8')
    return path


def _is_real(value: object) -> bool:
    return isinstance(value, (int, float, np.floating, np.integer))


def simple_mapping(n_joints: int = 2, **options: object) -> ImportMapping:
    """Time in ms in column 't'; joint j's position in 'q<j>' [rad], velocity in 'v<j>' [rad/s]."""
    joints = tuple(
        JointColumns(
            name=f'joint_{j}',
            position=ColumnSpec(f'q{j}', 'rad'),
            velocity=ColumnSpec(f'v{j}', 'rad/s'),
        )
        for j in range(1, n_joints + 1)
    )
    settings: dict[str, object] = {'time': ColumnSpec('t', 'ms'), **options}
    return ImportMapping(joints=joints, **settings)  # type: ignore[arg-type]


def simple_csv(path: Path, time_ms: np.ndarray, n_joints: int = 2) -> tuple[Path, np.ndarray]:
    """CSV for simple_mapping with distinct values per joint; returns the (N, 2n) q|v block."""
    n = len(time_ms)
    values = np.arange(n)[:, None] * 0.01 + np.arange(2 * n_joints)[None, :]
    header = ['t'] + [f'q{j}' for j in range(1, n_joints + 1)]
    header += [f'v{j}' for j in range(1, n_joints + 1)]
    return write_csv(path, header, np.column_stack([time_ms, values])), values


# -- round trips ----------------------------------------------------------------------------------
def test_example_mapping_round_trips_a_deg_ms_trace_to_si_through_the_bag(
    tmp_path: Path, robot: RobotConfig
) -> None:
    mapping = load_import_mapping(EXAMPLE_MAPPING)
    assert mapping.time == ColumnSpec('time_ms', 'ms')
    assert [joint.name for joint in mapping.joints] == list(robot.joints)
    for joint in mapping.joints:
        assert joint.velocity is not None
        assert joint.current is not None
        assert (joint.position.unit, joint.velocity.unit, joint.current.unit) == (
            'deg',
            'deg/s',
            'A',
        )
        assert joint.torque is None
    rng = np.random.default_rng(RNG_SEED)
    n = 40
    lower, upper = robot.limits.position_lower, robot.limits.position_upper
    # One motion the arm can make: poses inside the limits, velocities their derivative.
    centre = np.degrees(rng.uniform(0.5 * lower, 0.5 * upper, 6))
    phase = 2.0 * np.pi * 1.5 * 0.008 * np.arange(n)[:, None] + rng.uniform(0, 6.28, 6)
    q_deg = centre + 2.0 * np.sin(phase)  # 3.1 rad/s^2 at most: within every joint's gate
    v_deg_s = 2.0 * 2.0 * np.pi * 1.5 * np.cos(phase)
    i_a = rng.uniform(-5.0, 5.0, (n, 6))
    time_ms = 1234.5 + 8.0 * np.arange(n)
    header = ['time_ms']
    columns = [time_ms]
    for j, joint in enumerate(mapping.joints):
        for spec, values in (
            (joint.position, q_deg),
            (joint.velocity, v_deg_s),
            (joint.current, i_a),
        ):
            assert spec is not None
            header.append(str(spec.column))
            columns.append(values[:, j])
    csv = write_csv(
        tmp_path / 'trace.csv', header, np.column_stack(columns), preamble=['# trace export']
    )

    report = import_log(csv, mapping, tmp_path / 'bag', robot=robot)
    recording = load_recording(tmp_path / 'bag', robot)

    assert report.n_rows_read == report.n_rows_written == n
    assert (report.n_snapped, report.n_gaps, report.dropped_rows) == (0, 0, [])
    assert report.velocity_source == 'column'
    assert report.period_s == pytest.approx(robot.ipo_period_s, rel=0, abs=1e-15)
    np.testing.assert_array_equal(recording.stamps_ns, DEFAULT_START_NS + PERIOD_NS * np.arange(n))
    np.testing.assert_allclose(recording.position, q_deg * np.pi / 180.0, rtol=1e-12, atol=0)
    np.testing.assert_allclose(recording.velocity, v_deg_s * np.pi / 180.0, rtol=1e-12, atol=0)
    assert recording.current is not None
    np.testing.assert_allclose(recording.current, i_a, rtol=1e-12, atol=0)
    assert recording.joint_torque is None


def test_headerless_whitespace_csv_is_read_by_index_with_scale_and_offset(tmp_path: Path) -> None:
    n = 12
    q_mrad = np.linspace(-500.0, 500.0, n)
    v_rpm = np.linspace(3.0, -3.0, n)
    q2_rad = np.linspace(0.1, 0.2, n)
    rows = np.column_stack([q_mrad, v_rpm, q2_rad, -v_rpm])
    csv = write_csv(tmp_path / 'log.txt', None, rows, delimiter='   ', preamble=['# rt log'])
    mapping = ImportMapping(
        period_s=0.004,
        joints=(
            JointColumns('a', ColumnSpec(0, 'mrad'), ColumnSpec(1, 'rpm')),
            JointColumns('b', ColumnSpec(2, 'rad', scale=-1.0, offset=0.5), ColumnSpec(3, 'rpm')),
        ),
    )

    report = import_log(csv, mapping, tmp_path / 'bag', start_ns=0)
    states = read_joint_states(tmp_path / 'bag', '/joint_states')

    assert report.n_rows_written == n
    assert report.row_label == 'line'
    assert states.names == ('a', 'b')
    np.testing.assert_array_equal(states.stamps_ns, 4_000_000 * np.arange(n))
    assert states.position is not None
    assert states.velocity is not None
    np.testing.assert_allclose(states.position[:, 0], q_mrad * 1e-3, rtol=1e-12, atol=0)
    np.testing.assert_allclose(states.position[:, 1], 0.5 - q2_rad, rtol=1e-12, atol=0)
    rpm = 2.0 * np.pi / 60.0
    np.testing.assert_allclose(states.velocity, np.column_stack([v_rpm, -v_rpm]) * rpm, rtol=1e-12)


def test_npz_with_2d_arrays_round_trips_torque_and_current_to_si(
    tmp_path: Path, robot: RobotConfig
) -> None:
    rng = np.random.default_rng(RNG_SEED)
    n = 30
    phase = 2.0 * 0.008 * np.arange(n)[:, None] + rng.uniform(0, 6.28, 6)  # one motion
    arrays = {
        't': 100.0 + 0.008 * np.arange(n),
        'q': 0.2 * np.sin(phase),
        'qd_rpm': 0.4 * np.cos(phase) * 60 / (2 * np.pi),
        'i_ma': rng.uniform(-4000.0, 4000.0, (n, 6)),
        'tau_knm': rng.uniform(-0.5, 0.5, (n, 6)),  # within the MABI torque limits
        'meta': np.array([1.0, 2.0]),  # unused arrays of other lengths are ignored
    }
    np.savez(tmp_path / 'log.npz', **arrays)
    mapping = ImportMapping(
        time=ColumnSpec('t', 's'),
        joints=tuple(
            JointColumns(
                name,
                position=ColumnSpec('q', 'rad', index=j),
                velocity=ColumnSpec('qd_rpm', 'rpm', index=j),
                current=ColumnSpec('i_ma', 'mA', index=j),
                torque=ColumnSpec('tau_knm', 'kNm', index=j),
            )
            for j, name in enumerate(robot.joints)
        ),
    )

    report = import_log(tmp_path / 'log.npz', mapping, tmp_path / 'bag', robot=robot)
    recording = load_recording(tmp_path / 'bag', robot)

    assert report.row_label == 'row'
    assert report.n_rows_written == n
    np.testing.assert_array_equal(recording.stamps_ns, DEFAULT_START_NS + PERIOD_NS * np.arange(n))
    np.testing.assert_allclose(recording.position, arrays['q'], rtol=1e-12, atol=0)
    np.testing.assert_allclose(recording.velocity, arrays['qd_rpm'] * np.pi / 30.0, rtol=1e-12)
    assert recording.current is not None
    assert recording.joint_torque is not None
    np.testing.assert_allclose(recording.current, arrays['i_ma'] * 1e-3, rtol=1e-12, atol=0)
    np.testing.assert_allclose(recording.joint_torque, arrays['tau_knm'] * 1e3, rtol=1e-12, atol=0)


def test_npz_2d_array_without_index_is_refused(tmp_path: Path) -> None:
    np.savez(tmp_path / 'log.npz', t=np.arange(5.0), q=np.zeros((5, 2)), v=np.zeros((5, 2)))
    mapping = ImportMapping(
        time=ColumnSpec('t', 's'),
        joints=(JointColumns('a', ColumnSpec('q', 'rad'), ColumnSpec('v', 'rad/s', index=0)),),
    )
    with pytest.raises(
        ConfigError, match=r"column 'q' \(joint a position\).*shape \(5, 2\).*index"
    ):
        import_log(tmp_path / 'log.npz', mapping, tmp_path / 'bag')


# -- time stamps ----------------------------------------------------------------------------------
def test_jittered_stamps_are_snapped_onto_the_grid_and_reported(tmp_path: Path) -> None:
    jitter_ms = np.zeros(20)
    jitter_ms[[3, 7, 12]] = [0.5, -1.2, 0.9]
    csv, _ = simple_csv(tmp_path / 'log.csv', 8.0 * np.arange(20) + jitter_ms)

    report = import_log(csv, simple_mapping(), tmp_path / 'bag')
    states = read_joint_states(tmp_path / 'bag', '/joint_states')

    assert report.period_s == pytest.approx(0.008, rel=0, abs=1e-15)
    assert report.n_snapped == 3
    assert report.max_jitter_s == pytest.approx(1.2e-3, rel=1e-6)
    assert report.n_gaps == 0
    assert '3 stamps snapped' in report.summary()
    np.testing.assert_array_equal(states.stamps_ns, DEFAULT_START_NS + PERIOD_NS * np.arange(20))


@pytest.mark.parametrize(('unit', 'per_ms'), [('s', 1e-3), ('ms', 1.0), ('us', 1e3), ('ns', 1e6)])
def test_every_time_unit_gives_the_same_stamps(tmp_path: Path, unit: str, per_ms: float) -> None:
    time_ms = 1e5 + 8.0 * np.arange(6)
    csv, _ = simple_csv(tmp_path / 'log.csv', time_ms * per_ms)

    report = import_log(csv, simple_mapping(time=ColumnSpec('t', unit)), tmp_path / 'bag')
    states = read_joint_states(tmp_path / 'bag', '/joint_states')

    assert report.n_snapped == 0
    np.testing.assert_array_equal(states.stamps_ns, DEFAULT_START_NS + PERIOD_NS * np.arange(6))


def test_a_jittered_first_stamp_does_not_shift_the_grid(tmp_path: Path) -> None:
    jitter_ms = np.zeros(10)
    jitter_ms[0] = 1.5
    csv, _ = simple_csv(tmp_path / 'log.csv', 8.0 * np.arange(10) + jitter_ms)

    report = import_log(csv, simple_mapping(), tmp_path / 'bag')

    assert report.n_snapped == 1
    assert report.max_jitter_s == pytest.approx(1.5e-3, rel=1e-6)


def test_jitter_beyond_the_tolerance_is_refused_naming_the_line(tmp_path: Path) -> None:
    time_ms = 8.0 * np.arange(10)
    time_ms[4] += 3.0  # 0.375 periods, beyond the default 0.25
    csv, _ = simple_csv(tmp_path / 'log.csv', time_ms)  # header on line 1: row 4 is line 6
    with pytest.raises(
        DatasetError, match=r'log\.csv: line 6: time stamp is \+3 ms off.*tolerance'
    ):
        import_log(csv, simple_mapping(), tmp_path / 'bag')
    assert not (tmp_path / 'bag').exists()


def test_a_repeated_stamp_is_refused_naming_both_lines(tmp_path: Path) -> None:
    time_ms = 8.0 * np.arange(10)
    time_ms[5] = time_ms[4]
    csv, _ = simple_csv(tmp_path / 'log.csv', time_ms)
    with pytest.raises(DatasetError, match='line 7 repeats the time of line 6'):
        import_log(csv, simple_mapping(), tmp_path / 'bag')


def test_time_going_backwards_is_refused_naming_the_lines(tmp_path: Path) -> None:
    time_ms = 8.0 * np.arange(10)
    time_ms[6] = 20.0
    csv, _ = simple_csv(tmp_path / 'log.csv', time_ms)
    with pytest.raises(DatasetError, match='line 8 goes back in time by 20 ms from line 7'):
        import_log(csv, simple_mapping(), tmp_path / 'bag')


def test_missing_grid_slots_are_counted_as_gaps_not_filled(tmp_path: Path) -> None:
    time_ms = np.delete(8.0 * np.arange(12), [4, 8, 9])
    csv, _ = simple_csv(tmp_path / 'log.csv', time_ms)

    report = import_log(csv, simple_mapping(), tmp_path / 'bag')
    states = read_joint_states(tmp_path / 'bag', '/joint_states')

    assert report.n_gaps == 3
    assert report.n_rows_written == 9
    slots = (states.stamps_ns - DEFAULT_START_NS) // PERIOD_NS
    np.testing.assert_array_equal(slots, [0, 1, 2, 3, 5, 6, 7, 10, 11])


def test_period_is_the_robots_ipo_period_when_the_median_step_is_close(
    tmp_path: Path, robot: RobotConfig
) -> None:
    mapping = ImportMapping(
        time=ColumnSpec('t', 'ms'),
        joints=tuple(JointColumns(name, ColumnSpec(name, 'rad')) for name in robot.joints),
    )
    n = 10
    time_ms = 8.3 * np.arange(n)  # 0.1 ms rounding would give 8.3 ms; the robot says 8 ms
    rows = np.column_stack([time_ms, np.outer(np.arange(n), np.full(6, 0.002))])  # a slow ramp
    csv = write_csv(tmp_path / 'log.csv', ['t', *robot.joints], rows)
    without_robot = import_log(csv, mapping, tmp_path / 'plain')
    with_robot = import_log(csv, mapping, tmp_path / 'bag', robot=robot)

    assert without_robot.period_s == pytest.approx(0.0083, rel=0, abs=1e-15)
    assert with_robot.period_s == pytest.approx(robot.ipo_period_s, rel=0, abs=1e-15)
    recording = load_recording(tmp_path / 'bag', robot, require_current=False)
    np.testing.assert_array_equal(np.diff(recording.stamps_ns), PERIOD_NS)


# -- NaN policy -----------------------------------------------------------------------------------
def nan_csv(path: Path) -> Path:
    """10 rows of simple_csv; line 5 has an empty q2 cell, line 9 a 'nan' v1 and an 'inf' q1."""
    n = 10
    header = ['t', 'q1', 'q2', 'v1', 'v2']
    rows: list[list[object]] = [[8.0 * k, 0.1 * k, 0.2 * k, 1.0, 2.0] for k in range(n)]
    rows[3][2] = ''  # line 5 (header on line 1)
    rows[7][3] = 'nan'  # line 9
    rows[7][1] = 'inf'
    return write_csv(path, header, rows)


def test_nan_cells_are_refused_naming_file_line_column_and_joint(tmp_path: Path) -> None:
    csv = nan_csv(tmp_path / 'log.csv')
    with pytest.raises(
        DatasetError, match=r"log\.csv: line 5, column 'q2' \(joint joint_2 position\).*2 rows"
    ):
        import_log(csv, simple_mapping(), tmp_path / 'bag')


def test_nan_rows_are_dropped_and_reported_under_drop(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    csv = nan_csv(tmp_path / 'log.csv')

    with caplog.at_level(logging.INFO, logger='id_learning.dataset.importer'):
        report = import_log(csv, simple_mapping(nan_policy='drop'), tmp_path / 'bag')
    states = read_joint_states(tmp_path / 'bag', '/joint_states')

    assert [position for position, _ in report.dropped_rows] == [5, 9]
    assert "column 'q2' (joint joint_2 position)" in report.dropped_rows[0][1]
    assert "'q1'" in report.dropped_rows[1][1]
    assert "'v1'" in report.dropped_rows[1][1]
    assert (report.n_rows_read, report.n_rows_written, report.n_gaps) == (10, 8, 2)
    assert '2 rows dropped: lines 5, 9' in report.summary()
    assert '2 rows dropped: lines 5, 9' in caplog.text
    assert states.position is not None
    assert np.isfinite(states.position).all()
    slots = (states.stamps_ns - DEFAULT_START_NS) // PERIOD_NS
    np.testing.assert_array_equal(slots, [0, 1, 2, 4, 5, 6, 8, 9])


def test_dropped_rows_leave_gaps_in_a_fixed_period_time_base(tmp_path: Path) -> None:
    csv = nan_csv(tmp_path / 'log.csv')
    mapping = simple_mapping(time=None, period_s=0.008, nan_policy='drop')

    report = import_log(csv, mapping, tmp_path / 'bag', start_ns=0)
    states = read_joint_states(tmp_path / 'bag', '/joint_states')

    assert report.n_gaps == 2
    np.testing.assert_array_equal(states.stamps_ns // PERIOD_NS, [0, 1, 2, 4, 5, 6, 8, 9])


def test_text_in_a_number_column_is_refused_naming_line_and_value(tmp_path: Path) -> None:
    rows: list[list[object]] = [[8.0 * k, 0.1 * k, 0.0, 1.0, 2.0] for k in range(5)]
    rows[2][4] = 'err'
    csv = write_csv(tmp_path / 'log.csv', ['t', 'q1', 'q2', 'v1', 'v2'], rows)
    with pytest.raises(
        DatasetError, match=r"line 4, column 'v2' \(joint joint_2 velocity\): 'err'"
    ):
        import_log(csv, simple_mapping(nan_policy='drop'), tmp_path / 'bag')


# -- mapping errors -------------------------------------------------------------------------------
MAPPING_YAML = """
time: {column: t, unit: ms}
joints:
  - name: joint_1
    position: {column: q1, unit: deg}
    velocity: {column: v1, unit: deg/s}
"""


def test_a_missing_column_is_named_with_the_mapping_file_and_existing_columns(
    tmp_path: Path,
) -> None:
    path = tmp_path / 'mapping.yaml'
    path.write_text(MAPPING_YAML.replace('column: v1', 'column: qd1'), encoding='utf-8')
    mapping = load_import_mapping(path)
    csv = write_csv(
        tmp_path / 'log.csv', ['t', 'q1', 'v1'], [[8.0 * k, 0.0, 0.0] for k in range(5)]
    )
    with pytest.raises(
        ConfigError,
        match=r"mapping\.yaml: column 'qd1' .* not found in .*log\.csv.*\['t', 'q1', 'v1'\]",
    ):
        import_log(csv, mapping, tmp_path / 'bag')


def test_mapping_yaml_loads_into_the_mapping_built_in_code(tmp_path: Path) -> None:
    path = tmp_path / 'mapping.yaml'
    path.write_text(MAPPING_YAML, encoding='utf-8')
    expected = ImportMapping(
        time=ColumnSpec('t', 'ms'),
        joints=(JointColumns('joint_1', ColumnSpec('q1', 'deg'), ColumnSpec('v1', 'deg/s')),),
    )
    assert load_import_mapping(path) == expected


def test_an_unknown_unit_is_refused_naming_the_key_and_the_allowed_units(tmp_path: Path) -> None:
    path = tmp_path / 'mapping.yaml'
    path.write_text(MAPPING_YAML.replace('unit: deg}', 'unit: grad}'), encoding='utf-8')
    with pytest.raises(
        ConfigError,
        match=r'mapping\.yaml: joints\[0\] \(joint_1\)\.position\.unit: unknown position unit '
        r"'grad'; allowed: \['rad', 'deg', 'mrad'\]",
    ):
        load_import_mapping(path)


@pytest.mark.parametrize(
    ('replace', 'by', 'key'),
    [
        ('time:', 'delimeter: ","\ntime:', 'delimeter'),
        ('name: joint_1', 'name: joint_1\n    torq: {column: x, unit: Nm}', 'torq'),
        ('{column: t, unit: ms}', '{column: t, unit: ms, offest: 1.0}', 'offest'),
    ],
)
def test_an_unknown_key_is_refused_naming_it_and_the_file(
    tmp_path: Path, replace: str, by: str, key: str
) -> None:
    path = tmp_path / 'mapping.yaml'
    text = MAPPING_YAML.replace(replace, by)
    assert text != MAPPING_YAML
    path.write_text(text, encoding='utf-8')
    with pytest.raises(ConfigError, match=rf"mapping\.yaml.*unknown key\(s\) \['{key}'\]"):
        load_import_mapping(path)


def test_time_column_and_period_together_are_refused(tmp_path: Path) -> None:
    path = tmp_path / 'mapping.yaml'
    path.write_text(MAPPING_YAML + 'period_s: 0.008\n', encoding='utf-8')
    with pytest.raises(ConfigError, match=r'exactly one of time .* and period_s'):
        load_import_mapping(path)


def test_current_mapped_for_only_some_joints_is_refused() -> None:
    joints = (
        JointColumns('a', ColumnSpec('qa', 'rad'), current=ColumnSpec('ia', 'A')),
        JointColumns('b', ColumnSpec('qb', 'rad')),
    )
    with pytest.raises(
        ConfigError, match=r"current is mapped for joints \['a'\] but not for \['b'\]"
    ):
        ImportMapping(period_s=0.008, joints=joints)


# -- joints and velocity --------------------------------------------------------------------------
def test_joints_are_reordered_to_the_robot_order(tmp_path: Path, robot: RobotConfig) -> None:
    reversed_joints = tuple(reversed(robot.joints))
    mapping = ImportMapping(
        period_s=robot.ipo_period_s,
        joints=tuple(
            JointColumns(name, ColumnSpec(f'q_{name}', 'rad'), ColumnSpec(f'v_{name}', 'rad/s'))
            for name in reversed_joints
        ),
    )
    assert [joint.name for joint in mapping.joints] != list(robot.joints)
    n = 8
    # joint_k moves at k / 10 rad/s from k / 10 rad: each value tells its joint (and the rows
    # are one motion the arm can make).
    number = {name: 0.1 * float(name.removeprefix('joint_')) for name in robot.joints}
    header = [f'q_{name}' for name in reversed_joints] + [f'v_{name}' for name in reversed_joints]
    rows = [
        [number[name] * (1 + 0.008 * k) for name in reversed_joints]
        + [number[name] for name in reversed_joints]
        for k in range(n)
    ]
    csv = write_csv(tmp_path / 'log.csv', header, rows)

    import_log(csv, mapping, tmp_path / 'bag', robot=robot, velocity_from_position=False)
    states = read_joint_states(tmp_path / 'bag', robot.topics.joint_states)

    assert states.names == robot.joints
    assert states.position is not None
    assert states.velocity is not None
    expected_position = np.array(
        [[number[name] * (1 + 0.008 * k) for name in robot.joints] for k in range(n)]
    )
    np.testing.assert_allclose(states.position, expected_position, rtol=1e-12, atol=0)
    np.testing.assert_array_equal(states.velocity[0], [number[name] for name in robot.joints])


def test_joint_names_other_than_the_robots_are_refused_listing_both(
    robot: RobotConfig, tmp_path: Path
) -> None:
    mapping = ImportMapping(
        period_s=0.008,
        joints=tuple(JointColumns(f'axis_{j}', ColumnSpec(j, 'rad')) for j in range(6)),
    )
    with pytest.raises(
        ConfigError, match=r"\['axis_0'.*are not the joints of robot mabi_max100 \['joint_1'"
    ):
        import_log(tmp_path / 'unused.csv', mapping, tmp_path / 'bag', robot=robot)


def test_missing_velocity_is_differentiated_from_position(tmp_path: Path) -> None:
    amplitude, omega, dt = 0.7, 2.0 * np.pi * 0.5, 0.008
    t = dt * np.arange(250)
    rows = np.column_stack(
        [1e3 * t, amplitude * np.sin(omega * t), -amplitude * np.sin(omega * t)]
    )
    csv = write_csv(tmp_path / 'log.csv', ['t', 'q1', 'q2'], rows)
    mapping = ImportMapping(
        time=ColumnSpec('t', 'ms'),
        joints=(
            JointColumns('a', ColumnSpec('q1', 'rad')),
            JointColumns('b', ColumnSpec('q2', 'rad')),
        ),
    )

    report = import_log(csv, mapping, tmp_path / 'bag')
    states = read_joint_states(tmp_path / 'bag', '/joint_states')

    assert report.velocity_source == 'differentiated'
    assert states.velocity is not None
    truth = amplitude * omega * np.cos(omega * t)
    # Central differences err by A w^3 dt^2 / 6 inside, one-sided ones by A w^2 dt / 2 at the ends.
    inner_error = amplitude * omega**3 * dt**2 / 6
    np.testing.assert_allclose(
        states.velocity[1:-1, 0], truth[1:-1], rtol=0, atol=1.1 * inner_error
    )
    np.testing.assert_allclose(
        states.velocity[1:-1, 1], -truth[1:-1], rtol=0, atol=1.1 * inner_error
    )
    edge_error = amplitude * omega**2 * dt / 2
    np.testing.assert_allclose(
        states.velocity[[0, -1], 0], truth[[0, -1]], rtol=0, atol=1.1 * edge_error
    )


def test_missing_velocity_without_differentiation_is_refused(tmp_path: Path) -> None:
    mapping = ImportMapping(period_s=0.008, joints=(JointColumns('a', ColumnSpec(0, 'rad')),))
    with pytest.raises(ConfigError, match=r'no velocity columns.*velocity_from_position'):
        import_log(
            tmp_path / 'unused.csv', mapping, tmp_path / 'bag', velocity_from_position=False
        )


# -- CSV dialects ---------------------------------------------------------------------------------
@pytest.mark.parametrize('delimiter', [';', '\t', ','])
def test_delimiter_and_header_are_detected(tmp_path: Path, delimiter: str) -> None:
    time_ms = 8.0 * np.arange(6)
    values = np.arange(24.0).reshape(6, 4) / 7
    header = ['t', 'q1', 'q2', 'v1', 'v2']
    csv = write_csv(
        tmp_path / 'log.csv', header, np.column_stack([time_ms, values]), delimiter=delimiter
    )

    import_log(csv, simple_mapping(), tmp_path / 'bag')
    states = read_joint_states(tmp_path / 'bag', '/joint_states')

    assert states.position is not None
    np.testing.assert_allclose(states.position, values[:, :2], rtol=1e-12, atol=0)


def test_a_current_no_drive_can_carry_is_refused_at_import(tmp_path: Path, robot: RobotConfig):
    mapping = ImportMapping(
        period_s=robot.ipo_period_s,
        joints=tuple(
            JointColumns(
                name,
                ColumnSpec(f'q_{name}', 'rad'),
                ColumnSpec(f'v_{name}', 'rad/s'),
                current=ColumnSpec(f'i_{name}', 'A'),
            )
            for name in robot.joints
        ),
    )
    n = 20
    rows = np.hstack([np.zeros((n, 12)), np.ones((n, 6))])
    rows[7, 12 + 2] = -1e300
    header = [f'{key}_{name}' for key in ('q', 'v', 'i') for name in robot.joints]
    csv = write_csv(tmp_path / 'log.csv', header, rows.tolist())
    with pytest.raises(
        DatasetError, match=r"line 9, column 'i_joint_3' \(joint joint_3 current\): -1e\+300 A"
    ):
        import_log(csv, mapping, tmp_path / 'bag', robot=robot, velocity_from_position=False)
    assert not (tmp_path / 'bag').exists()


def positions_and_velocities(robot: RobotConfig) -> ImportMapping:
    """A mapping of columns q_<joint> [rad] and v_<joint> [rad/s] for every robot joint."""
    return ImportMapping(
        period_s=robot.ipo_period_s,
        joints=tuple(
            JointColumns(name, ColumnSpec(f'q_{name}', 'rad'), ColumnSpec(f'v_{name}', 'rad/s'))
            for name in robot.joints
        ),
    )


@pytest.mark.parametrize(
    ('scale', 'message'),
    [
        (180.0 / np.pi, r"line 2, column 'q_joint_1' .* read as degrees .* set its unit: deg"),
        (1e306, r"line 2, column 'q_joint_1' \(joint joint_1 position\): -1.2e\+306 rad"),
    ],
    ids=['degrees-mapped-as-radians', 'absurd-values'],
)
def test_motion_no_arm_can_have_is_refused_and_nothing_is_written(
    tmp_path: Path, robot: RobotConfig, scale: float, message: str
) -> None:
    mapping = positions_and_velocities(robot)
    n = 40
    swing = np.linspace(-1.2, 1.2, n)[:, None] * np.ones(6)  # rad, inside every joint's limits
    rows = np.hstack([swing * scale, np.zeros((n, 6))]).tolist()
    header = [f'q_{name}' for name in robot.joints] + [f'v_{name}' for name in robot.joints]
    csv = write_csv(tmp_path / 'log.csv', header, rows)
    with pytest.raises(DatasetError, match=message):
        import_log(csv, mapping, tmp_path / 'bag', robot=robot, velocity_from_position=False)
    assert not (tmp_path / 'bag').exists()


def test_a_log_whose_positions_jump_is_refused_at_import_naming_the_sample(
    tmp_path: Path, robot: RobotConfig
) -> None:
    mapping = positions_and_velocities(robot)
    header = [f'q_{name}' for name in robot.joints] + [f'v_{name}' for name in robot.joints]
    rows = [[0.1 + (0.5 if k >= 12 and j == 4 else 0.0) for j in range(6)] + [0.0] * 6
            for k in range(30)]  # fmt: skip
    csv = write_csv(tmp_path / 'log.csv', header, rows)
    with pytest.raises(DatasetError, match=r'log\.csv: sample 12 .* position of joint_5'):
        import_log(csv, mapping, tmp_path / 'bag', robot=robot, velocity_from_position=False)
    assert not (tmp_path / 'bag').exists()  # nothing written
