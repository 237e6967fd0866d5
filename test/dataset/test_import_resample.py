"""Importing logs that are not on the controller's grid: resampling, segments, several files."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import yaml

from id_learning.bag import bag_info
from id_learning.dataset.import_mapping import ResamplePolicy, load_import_mapping
from id_learning.dataset.importer import (
    SEGMENT_SEPARATION_S,
    ColumnSpec,
    ImportMapping,
    JointColumns,
    import_log,
    import_logs,
)
from id_learning.dataset.preprocess import PreprocessConfig
from id_learning.dataset.recording import SEGMENTS_KEY, load_recording
from id_learning.errors import ConfigError, DatasetError
from id_learning.robot import RobotConfig, load_robot_config
from id_learning.training.datasets import combine_datasets, load_datasets

REPO = Path(__file__).resolve().parents[2]
FREQUENCIES_HZ = np.array([0.3, 0.45, 0.6, 0.8, 0.9, 1.1])
AMPLITUDE_RAD = 0.3  # the fastest joint (1.1 Hz) stays below 2 x its acceleration limit
CURRENT_HZ, NOISE_HZ = 2.0, 200.0


@pytest.fixture(scope='module')
def robot() -> RobotConfig:
    return load_robot_config(REPO / 'config/mabi_max100.yaml')


def motion(t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Closed-form q [rad], v [rad/s] and currents [A]: a 2 Hz wave plus a 200 Hz ripple."""
    phase = 2 * np.pi * FREQUENCIES_HZ[None, :] * t[:, None]
    q = AMPLITUDE_RAD * np.sin(phase)
    v = AMPLITUDE_RAD * 2 * np.pi * FREQUENCIES_HZ * np.cos(phase)
    i = (
        np.sin(2 * np.pi * CURRENT_HZ * t)[:, None]
        + 0.5 * np.sin(2 * np.pi * NOISE_HZ * t)[:, None]
    )
    return q, v, np.repeat(i, 6, axis=1)


def write_log(path: Path, t: np.ndarray, robot: RobotConfig) -> Path:
    q, v, i = motion(t)
    header = ['t_s'] + [f'{k}{j}' for k in ('q', 'v', 'i') for j in range(1, 7)]
    lines = [','.join(header)]
    lines += [','.join(repr(float(x)) for x in row) for row in np.column_stack([t, q, v, i])]
    path.write_text('\n'.join(lines) + '\n', encoding='utf-8')
    return path


def mapping_for(robot: RobotConfig, **options: object) -> ImportMapping:
    joints = tuple(
        JointColumns(
            name,
            ColumnSpec(f'q{j}', 'rad'),
            ColumnSpec(f'v{j}', 'rad/s'),
            current=ColumnSpec(f'i{j}', 'A'),
        )
        for j, name in enumerate(robot.joints, start=1)
    )
    return ImportMapping(joints=joints, time=ColumnSpec('t_s', 's'), **options)  # type: ignore[arg-type]


INTERPOLATE = ResamplePolicy(method='interpolate')


@pytest.mark.parametrize('step_ms', [10.0, 12.0])
def test_a_10_or_12_ms_log_is_resampled_onto_the_8_ms_grid(
    tmp_path: Path, robot: RobotConfig, step_ms: float
) -> None:
    t = np.arange(0.0, 6.0, step_ms * 1e-3)
    log = write_log(tmp_path / 'log.csv', t, robot)
    with pytest.raises(DatasetError, match=r'IPO period .* is 8 ms.*resample: \{method: interp'):
        import_log(log, mapping_for(robot), tmp_path / 'refused', robot=robot)
    report = import_log(
        log, mapping_for(robot, resample=INTERPOLATE), tmp_path / 'bag', robot=robot
    )
    recording = load_recording(tmp_path / 'bag', robot)
    grid_t = (recording.stamps_ns - recording.stamps_ns[0]) * 1e-9
    np.testing.assert_allclose(np.diff(recording.stamps_ns), 8_000_000)
    assert grid_t[-1] == pytest.approx(np.floor(t[-1] / 0.008) * 0.008)
    q, v, _ = motion(grid_t)
    assert np.abs(recording.position - q).max() < 2e-5  # cubic spline of a smooth motion
    assert np.abs(recording.velocity - v).max() < 2e-4
    assert report.method == 'interpolate'
    assert report.n_segments == 1
    assert report.grid is not None
    assert report.grid.source_step_s == pytest.approx(step_ms * 1e-3)
    assert f'median step of {step_ms:g} ms' in report.summary()


def test_a_1_khz_log_with_jitter_and_drift_is_resampled_and_anti_aliased(
    tmp_path: Path, robot: RobotConfig
) -> None:
    # 20,544 samples in 21.0 s: a logger nominally at 1 kHz whose clock runs 2.2 % slow,
    # each stamp jittered by up to +-0.3 ms.
    n = 20_544
    rng = np.random.default_rng(7)
    t = np.linspace(0.0, 21.0, n) + rng.uniform(-3e-4, 3e-4, n)
    t[0], t[-1] = 0.0, 21.0
    log = write_log(tmp_path / 'log.csv', t, robot)
    with pytest.raises(DatasetError, match=r'steps 1\.022 ms .*resample: \{method: interpolate\}'):
        import_log(log, mapping_for(robot), tmp_path / 'refused', robot=robot)
    report = import_log(
        log, mapping_for(robot, resample=INTERPOLATE), tmp_path / 'bag', robot=robot
    )
    recording = load_recording(tmp_path / 'bag', robot)
    assert recording.n_samples == round(21.0 / 0.008) + 1
    grid_t = (recording.stamps_ns - recording.stamps_ns[0]) * 1e-9
    q, v, _ = motion(grid_t)
    assert np.abs(recording.position - q).max() < 1e-4
    assert np.abs(recording.velocity - v).max() < 2e-3
    # The 200 Hz ripple, above the 62.5 Hz Nyquist frequency of the grid, is filtered out rather
    # than folded onto 75 Hz -> 50 Hz; the 2 Hz current is kept. Edges aside (filter start-up).
    inner = slice(50, -50)
    wave = np.sin(2 * np.pi * CURRENT_HZ * grid_t)
    residual = recording.current[inner, 0] - wave[inner]
    # Sampled straight from the log, the ripple would fold in at full amplitude (RMS 0.35 A);
    # what is left is the log's own jitter acting on the ripple.
    assert np.sqrt(np.mean(residual**2)) < 0.02
    assert report.grid is not None
    assert report.grid.mean_step_s == pytest.approx(21.0 / (n - 1), rel=1e-6)
    assert 'mean 1.022 ms' in report.summary()


def test_holes_are_bridged_and_long_pauses_split_segments_that_training_keeps_apart(
    tmp_path: Path, robot: RobotConfig
) -> None:
    t = np.arange(0.0, 40.0, 0.004)
    hole = (t > 5.0) & (t < 5.015)  # 15 ms without samples: bridged
    pause = (t > 20.0) & (t < 22.0)  # a 2 s pause: ends the first segment
    t = t[~hole & ~pause]
    log = write_log(tmp_path / 'log.csv', t, robot)
    policy = ResamplePolicy(method='interpolate', max_gap_s=0.05)
    report = import_log(log, mapping_for(robot, resample=policy), tmp_path / 'bag', robot=robot)
    assert report.grid is not None
    assert [h[:2] for h in report.grid.holes] == [(1252, 1253)]  # CSV lines around the hole
    assert report.grid.n_filled == 1
    ((before, after, seconds),) = report.grid.breaks
    assert (before, after) == (5000 - 3 + 2, 5000 - 3 + 3)
    assert seconds == pytest.approx(2.0, abs=0.005)
    assert '1 pauses that end a segment: lines ' in report.summary()
    info = bag_info(tmp_path / 'bag')
    recording = load_recording(tmp_path / 'bag', robot)
    starts = json.loads(info.custom_data[SEGMENTS_KEY])
    assert len(starts) == 2
    assert recording.segment_starts[0] == 0
    assert starts[1] == int(recording.stamps_ns[recording.segment_starts[1]])
    assert (
        recording.stamps_ns[recording.segment_starts[1]]
        - recording.stamps_ns[recording.segment_starts[1] - 1]
        > 1.9e9
    )
    config = PreprocessConfig(target='motor', cutoff_hz=(2.0,) * 6)
    datasets = load_datasets([tmp_path / 'bag'], robot, config, progress=False)
    assert [len(d.q) for d in datasets] == [len(s.stamps_ns) for s in recording.segments()]
    combined = combine_datasets(datasets)
    assert [s['bag'] for s in combined.extra['segments']] == [str(tmp_path / 'bag')] * 2
    assert len(combined.recording_rows()) == 2


def test_several_files_and_a_folder_become_one_bag_with_one_segment_each(
    tmp_path: Path, robot: RobotConfig
) -> None:
    folder = tmp_path / 'logs'
    folder.mkdir()
    for k in range(2):
        write_log(folder / f'run_{k}.csv', np.arange(0.0, 3.0, 0.008) + 100.0 * k, robot)
    (folder / 'notes.md').write_text('not a log\n', encoding='utf-8')
    # Another stretch of the motion: a file that repeats rows of another is refused.
    extra = write_log(tmp_path / 'extra.csv', np.arange(0.0, 2.0, 0.008) + 50.0, robot)
    reports = import_logs([folder, extra], mapping_for(robot), tmp_path / 'bag', robot=robot)
    assert [r.source.name for r in reports] == ['run_0.csv', 'run_1.csv', 'extra.csv']
    recording = load_recording(tmp_path / 'bag', robot)
    assert len(recording.segment_starts) == 3
    lengths = [s.n_samples for s in recording.segments()]
    assert lengths == [r.n_rows_written for r in reports] == [375, 375, 250]
    seams = np.diff(recording.stamps_ns)[np.array(recording.segment_starts[1:]) - 1]
    assert (seams >= SEGMENT_SEPARATION_S * 1e9).all()
    with pytest.raises(DatasetError, match='no log files'):
        import_logs([tmp_path / 'bag'], mapping_for(robot), tmp_path / 'other', robot=robot)


def test_files_on_different_grids_are_refused_naming_each(
    tmp_path: Path, robot: RobotConfig
) -> None:
    a = write_log(tmp_path / 'a.csv', np.arange(0.0, 1.0, 0.008), robot)
    b = write_log(tmp_path / 'b.csv', np.arange(0.0, 1.0, 0.004), robot)
    with pytest.raises(
        DatasetError, match=r'different sampling grids .*a\.csv: 8 ms.*b\.csv: 4 ms'
    ):
        import_logs([a, b], mapping_for(robot), tmp_path / 'bag')


def test_garbage_rows_are_refused_naming_line_and_column_or_dropped_by_policy(
    tmp_path: Path, robot: RobotConfig
) -> None:
    t = np.arange(0.0, 2.0, 0.008)
    log = write_log(tmp_path / 'log.csv', t, robot)
    lines = log.read_text(encoding='utf-8').splitlines()
    for k in (1, 2):  # a logger's first lines, filled with garbage
        cells = lines[k].split(',')
        cells[8] = '1.4e306'  # v2
        lines[k] = ','.join(cells)
    log.write_text('\n'.join(lines) + '\n', encoding='utf-8')
    with pytest.raises(
        DatasetError, match=r"line 2, column 'v2' \(joint joint_2 velocity\): 1\.4e\+306 rad/s"
    ):
        import_log(log, mapping_for(robot), tmp_path / 'refused', robot=robot)
    assert not (tmp_path / 'refused').exists()
    with pytest.raises(DatasetError, match=r"line 2, column 'v2'.*: 1\.4e\+306 rad/s is outside"):
        import_log(log, mapping_for(robot), tmp_path / 'refused')  # no robot: magnitude bounds
    report = import_log(
        log, mapping_for(robot, implausible_policy='drop'), tmp_path / 'bag', robot=robot
    )
    assert [row for row, _ in report.dropped_rows] == [2, 3]
    assert 'implausible' in report.dropped_rows[0][1]
    assert load_recording(tmp_path / 'bag', robot).n_samples == len(t) - 2


def test_motor_side_signals_of_a_coupled_wrist_come_out_joint_side(
    tmp_path: Path, robot: RobotConfig
) -> None:
    t = np.arange(0.0, 2.0, 0.008)
    q, v, _ = motion(t)
    gear = np.array([120.0, 120.0, 100.0, 80.0, 80.0, 50.0])
    kt = np.array([2.0, 2.0, 1.5, 0.8, 0.8, 0.5])
    coupling = np.eye(6)
    coupling[5, 4] = 0.8  # the wrist's last motor also turns with joint 5
    reduction = gear[:, None] * coupling
    tau = 50.0 * np.sin(2 * np.pi * 0.5 * t)[:, None] * np.ones(6)
    motor_current = np.linalg.solve(reduction.T, tau.T).T / kt  # tau = K^T (kt * i)
    header = ['t_s'] + [f'{k}{j}' for k in ('q', 'v', 'i') for j in range(1, 7)]
    rows = np.column_stack([t, q @ reduction.T, v @ reduction.T, motor_current])
    lines = [','.join(header)] + [','.join(repr(float(x)) for x in row) for row in rows]
    (tmp_path / 'log.csv').write_text('\n'.join(lines) + '\n', encoding='utf-8')
    spec = {
        'time': {'column': 't_s', 'unit': 's'},
        'motors': {
            'gear_ratio': gear.tolist(),
            'torque_constant': kt.tolist(),
            'coupling': coupling.tolist(),
            'signals': ['position', 'velocity', 'current'],
        },
        'joints': [
            {
                'name': name,
                'position': {'column': f'q{j}', 'unit': 'rad'},
                'velocity': {'column': f'v{j}', 'unit': 'rad/s'},
                'current': {'column': f'i{j}', 'unit': 'A'},
            }
            for j, name in enumerate(robot.joints, start=1)
        ],
    }
    (tmp_path / 'mapping.yaml').write_text(yaml.safe_dump(spec), encoding='utf-8')
    mapping = load_import_mapping(tmp_path / 'mapping.yaml')
    import_log(tmp_path / 'log.csv', mapping, tmp_path / 'bag', robot=robot)
    recording = load_recording(tmp_path / 'bag', robot)
    np.testing.assert_allclose(recording.position, q, atol=1e-12)
    np.testing.assert_allclose(recording.velocity, v, atol=1e-12)
    assert recording.current is not None
    tau_u = recording.current * robot.drives.gear_ratio * robot.drives.torque_constant
    np.testing.assert_allclose(tau_u, tau, rtol=1e-9, atol=1e-9)
    with pytest.raises(ConfigError, match='pass --robot'):
        import_log(tmp_path / 'log.csv', mapping, tmp_path / 'no_robot')


@pytest.mark.parametrize(
    ('extra', 'message'),
    [
        ({'resample': {'method': 'spline'}}, "resample.method must be 'snap' or 'interpolate'"),
        ({'resample': {'max_gap_s': -1}}, 'resample.max_gap_s must be a positive number'),
        ({'resample': {'window': 3}}, r"unknown key\(s\) \['window'\]"),
        ({'implausible_policy': 'keep'}, "implausible_policy must be 'refuse' or 'drop'"),
        ({'motors': {'gear_ratio': [1.0], 'torque_constant': [1.0]}}, 'needs 2 non-zero numbers'),
        (
            {
                'motors': {
                    'gear_ratio': [1.0, 1.0],
                    'torque_constant': [1.0, 1.0],
                    'coupling': [[1.0, 2.0], [0.5, 1.0]],
                }
            },
            'motors.coupling is singular',
        ),
    ],
)
def test_bad_resample_and_motor_settings_name_the_key(
    tmp_path: Path, extra: dict[str, object], message: str
) -> None:
    spec = {
        'time': {'column': 't', 'unit': 's'},
        'joints': [
            {'name': f'j{j}', 'position': {'column': f'q{j}', 'unit': 'rad'}} for j in (1, 2)
        ],
        **extra,
    }
    (tmp_path / 'mapping.yaml').write_text(yaml.safe_dump(spec), encoding='utf-8')
    with pytest.raises(ConfigError, match=message):
        load_import_mapping(tmp_path / 'mapping.yaml')


def test_a_bag_whose_segment_metadata_is_broken_is_refused(
    tmp_path: Path, robot: RobotConfig
) -> None:
    log = write_log(tmp_path / 'log.csv', np.arange(0.0, 1.0, 0.008), robot)
    import_log(log, mapping_for(robot), tmp_path / 'bag', robot=robot)
    meta = tmp_path / 'bag' / 'metadata.yaml'
    data = yaml.safe_load(meta.read_text(encoding='utf-8'))
    data['rosbag2_bagfile_information']['custom_data'][SEGMENTS_KEY] = '[12]'
    meta.write_text(yaml.safe_dump(data), encoding='utf-8')
    with pytest.raises(DatasetError, match=f'custom_data {SEGMENTS_KEY} lists segment starts'):
        load_recording(tmp_path / 'bag', robot)


def test_settings_that_would_write_an_unloadable_bag_are_refused(
    tmp_path: Path, robot: RobotConfig
) -> None:
    log = write_log(tmp_path / 'log.csv', np.arange(0.0, 1.0, 0.008), robot)
    snap_long_gap = mapping_for(robot, resample=ResamplePolicy(max_gap_s=0.05))
    with pytest.raises(ConfigError, match=r'max_gap_s 0.05 s: pauses are left unfilled'):
        import_log(log, snap_long_gap, tmp_path / 'a', robot=robot)
    other_grid = mapping_for(robot, resample=ResamplePolicy(method='interpolate', period_s=0.004))
    with pytest.raises(ConfigError, match=r'period_s 0.004 s is not the IPO period 0.008 s'):
        import_log(log, other_grid, tmp_path / 'b', robot=robot)
    assert not (tmp_path / 'a').exists()
    assert not (tmp_path / 'b').exists()


def test_a_log_slower_than_three_grid_periods_is_resampled_not_cut_at_every_step(
    tmp_path: Path, robot: RobotConfig
) -> None:
    log = write_log(tmp_path / 'log.csv', np.arange(0.0, 4.0, 0.030), robot)
    report = import_log(
        log, mapping_for(robot, resample=INTERPOLATE), tmp_path / 'bag', robot=robot
    )
    assert report.n_segments == 1
    last_t = 0.030 * 133  # the log's last stamp
    assert report.n_rows_written == int(np.floor(last_t / 0.008 + 1e-9)) + 1


def test_a_shuffled_split_draws_each_segment_of_a_bag_on_its_own(
    tmp_path: Path, robot: RobotConfig
) -> None:
    folder = tmp_path / 'logs'
    folder.mkdir()
    for k in range(2):
        # Two runs of their own (the same rows twice are refused): the second starts later.
        write_log(folder / f'run_{k}.csv', np.arange(0.0, 12.0, 0.008) + 100.0 * k, robot)
    import_logs([folder], mapping_for(robot), tmp_path / 'bag', robot=robot)
    config = PreprocessConfig(target='motor', cutoff_hz=(2.0,) * 6, split='shuffled')
    first, second = load_datasets([tmp_path / 'bag'], robot, config, progress=False)
    assert first.train_mask is not None
    assert second.train_mask is not None
    assert len(first.train_mask) == len(second.train_mask)
    assert not np.array_equal(first.train_mask, second.train_mask)


def test_a_segment_too_short_for_the_filter_names_the_remedy(
    tmp_path: Path, robot: RobotConfig
) -> None:
    write_log(tmp_path / 'long.csv', np.arange(0.0, 12.0, 0.008), robot)
    write_log(tmp_path / 'short.csv', np.arange(0.0, 0.5, 0.008) + 50.0, robot)
    import_logs(
        [tmp_path / 'long.csv', tmp_path / 'short.csv'], mapping_for(robot), tmp_path / 'bag'
    )
    config = PreprocessConfig(target='motor', cutoff_hz=(2.0,) * 6)
    with pytest.raises(DatasetError, match=r'segment 2 of 2.*too short.*min_segment_s'):
        load_datasets([tmp_path / 'bag'], robot, config, progress=False)
