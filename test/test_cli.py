"""The id-learning command line, run as a user would (subprocesses, real files)."""

from __future__ import annotations

import json

import numpy as np
import pytest
import yaml
from support import REPO, ground_truth, inspect_topic_rows, run_cli

from id_learning.dataset.recording import load_recording


@pytest.fixture(scope='module')
def twin_bag(tmp_path_factory):
    out = tmp_path_factory.mktemp('cli') / 'twin'
    result = run_cli(
        'simulate',
        '--config',
        str(REPO / 'config/twin_default.yaml'),
        '--out',
        str(out),
        '--duration',
        '40',
        '--seed',
        '3',
        '--quiet',
    )
    assert result.returncode == 0, result.stderr
    return out


def test_simulate_writes_a_bag_with_ground_truth(twin_bag, mabi):
    truth, stamps = ground_truth(twin_bag)
    assert truth['seed'] == 3
    assert 'viscous_friction' in truth['effects_enabled']
    # The bag holds one sample per ground-truth stamp, on the robot's IPO grid.
    recording = load_recording(twin_bag, mabi)
    np.testing.assert_array_equal(recording.stamps_ns, stamps)
    np.testing.assert_array_equal(np.diff(stamps), round(mabi.ipo_period_s * 1e9))
    assert truth['ipo_period_s'] == mabi.ipo_period_s
    assert np.isfinite(recording.current).all()


def test_simulate_records_one_robot_twice_with_robot_seed_and_another_with_another(tmp_path, mabi):
    def simulate(name: str, *seeds: str):
        out = tmp_path / name
        config = str(REPO / 'config/twin_default.yaml')
        result = run_cli('simulate', '--config', config, '--out', str(out), '--duration', '8',
                         *seeds, '--quiet')  # fmt: skip
        assert result.returncode == 0, result.stderr
        return ground_truth(out)[0], load_recording(out, mabi)

    (first, one), (second, two) = (
        simulate(name, '--robot-seed', '5', '--seed', seed)
        for name, seed in (('a', '1'), ('b', '2'))
    )
    other, _ = simulate('c', '--robot-seed', '6', '--seed', '1')
    assert (first['seed'], second['seed'], first['robot_seed'], second['robot_seed']) == (
        1,
        2,
        5,
        5,
    )
    assert first['true'] == second['true']  # the same robot ...
    assert first['excitation'] != second['excitation']  # ... moved differently
    assert not np.array_equal(one.position, two.position)
    assert other['true']['body_masses_kg'] != first['true']['body_masses_kg']
    assert yaml.safe_load((tmp_path / 'a/twin_config.yaml').read_text())['robot_seed'] == 5


def test_inspect_reports_topics_counts_and_rate(twin_bag, tmp_path):
    plot = tmp_path / 'overview.png'
    result = run_cli(
        'inspect',
        str(twin_bag),
        '--robot',
        str(REPO / 'config/mabi_max100.yaml'),
        '--plot',
        str(plot),
    )
    assert result.returncode == 0, result.stderr
    truth, stamps = ground_truth(twin_bag)
    period_s = truth['ipo_period_s']
    n = len(stamps)
    rows = inspect_topic_rows(result.stdout)
    assert set(rows) == {'/joint_states', '/motor_currents'}
    for topic, cells in rows.items():
        kind, count, time_base, rate, period, _, _, _, gaps, repeated, backward = cells
        assert kind == 'sensor_msgs/msg/JointState', topic
        assert (int(count), time_base) == (n, 'header'), topic
        assert float(rate) == pytest.approx(1.0 / period_s, abs=5e-4), topic
        assert float(period) == pytest.approx(period_s * 1e3, abs=5e-4), topic
        assert (gaps, repeated, backward) == ('0', '0', '0'), topic
    assert f'({int(stamps[0])} ns)' in result.stdout.splitlines()[2]  # the start line
    duration = (stamps[-1] - stamps[0]) * 1e-9
    assert f'duration  {duration:.3f} s, {2 * n} messages' in result.stdout
    assert 'problems  none' in result.stdout
    assert plot.read_bytes()[:8] == b'\x89PNG\r\n\x1a\n'


def test_demo_writes_a_summary_with_figures(twin_bag, tmp_path):
    result = run_cli(
        'demo', '--bag', str(twin_bag), '--out', str(tmp_path / 'demo'), '--skip-training'
    )
    assert result.returncode == 0, result.stderr
    summary = json.loads((tmp_path / 'demo/summary.json').read_text())
    assert summary['joints'] == [f'joint_{i}' for i in range(1, 7)]
    assert summary['noise_after_filter_nm'] is not None
    for name in ('torque_timeseries.png', 'torque_shares.png', 'excitation.png'):
        assert (tmp_path / 'demo' / name).stat().st_size > 10_000


def test_errors_exit_with_status_two_and_one_clear_line(tmp_path):
    result = run_cli('demo', '--bag', str(tmp_path / 'missing'), '--out', str(tmp_path / 'x'))
    assert result.returncode == 2
    assert result.stderr.strip().startswith('id-learning demo: error:')
    assert 'no such bag' in result.stderr
    assert 'Traceback' not in result.stderr


#: A 100-row log of 6 joints at the MABI's 8 ms, in the units a controller log may use.
LOG_ROWS = 100


def log_values() -> dict[str, np.ndarray]:
    """Time [ms], positions [deg], velocities [deg/s] and currents [A] of a seeded log.

    One motion: 40 deg swings (inside every joint's limits) at random phases, the velocities
    their derivative.
    """
    rng = np.random.default_rng(17)
    omega = 2.0 * np.pi * 0.25  # rad/s: at most 63 deg/s
    phase = omega * 0.008 * np.arange(LOG_ROWS)[:, None] + rng.uniform(0.0, 2 * np.pi, 6)
    return {
        't_ms': 5000.0 + 8.0 * np.arange(LOG_ROWS),
        'q_deg': 40.0 * np.sin(phase),
        'v_deg_s': 40.0 * omega * np.cos(phase),
        'i_a': rng.uniform(-5.0, 5.0, (LOG_ROWS, 6)),
    }


def write_log(folder, suffix: str, values: dict[str, np.ndarray]):
    """The log as a CSV (a column per joint and quantity) or an NPZ of 2-D arrays; its mapping."""
    source = folder / f'log.{suffix}'
    spec = {
        'position': ('q_deg', 'deg'),
        'velocity': ('v_deg_s', 'deg/s'),
        'current': ('i_a', 'A'),
    }
    if suffix == 'npz':
        np.savez(source, **values)

        def column(key, j):
            return {'column': key, 'index': j}
    else:
        header = ['t_ms'] + [f'{key}{j}' for key in ('q_deg', 'v_deg_s', 'i_a') for j in range(6)]
        table = np.column_stack(
            [values['t_ms'], values['q_deg'], values['v_deg_s'], values['i_a']]
        )
        lines = [','.join(header)] + [','.join(repr(float(x)) for x in row) for row in table]
        source.write_text('\n'.join(lines) + '\n')

        def column(key, j):
            return {'column': f'{key}{j}'}

    mapping = {
        'time': {'column': 't_ms', 'unit': 'ms'},
        'joints': [
            {
                'name': f'joint_{j + 1}',
                **{field: {**column(key, j), 'unit': unit} for field, (key, unit) in spec.items()},
            }
            for j in range(6)
        ],
    }
    (folder / 'map.yaml').write_text(yaml.safe_dump(mapping, sort_keys=False))
    return source, folder / 'map.yaml'


def test_import_resamples_logs_of_10_and_12_ms_into_one_bag_in_one_command(tmp_path, mabi):
    sources = []
    for step_ms in (10.0, 12.0):
        folder = tmp_path / f'{step_ms:g}ms'
        folder.mkdir()
        t_ms = 5000.0 + step_ms * np.arange(60)
        phase = 2 * np.pi * 0.5 * (t_ms[:, None] * 1e-3) + np.arange(6)
        values = {
            't_ms': t_ms,
            'q_deg': 20.0 * np.sin(phase),
            'v_deg_s': 20.0 * np.pi * np.cos(phase),
            'i_a': np.sin(phase),
        }
        source, mapping = write_log(folder, 'csv', values)
        sources.append(str(source))
    spec = yaml.safe_load(mapping.read_text())
    spec['resample'] = {'method': 'interpolate'}
    mapping.write_text(yaml.safe_dump(spec, sort_keys=False))
    robot = str(REPO / 'config/mabi_max100.yaml')
    result = run_cli(
        'import', *sources, '--mapping', str(mapping), '--out', str(tmp_path / 'bag'),
        '--robot', robot,
    )  # fmt: skip
    assert result.returncode == 0, result.stderr
    assert 'resampled from a median step of 10 ms' in result.stdout
    assert 'resampled from a median step of 12 ms' in result.stdout
    assert 'samples in 2 segments from 2 files' in result.stdout
    recording = load_recording(tmp_path / 'bag', mabi)
    assert len(recording.segment_starts) == 2
    for segment in recording.segments():
        np.testing.assert_array_equal(np.diff(segment.stamps_ns), 8_000_000)


@pytest.mark.parametrize('suffix', ['csv', 'npz'])
def test_import_converts_a_log_to_si_units_on_the_ipo_grid(tmp_path, mabi, suffix):
    values = log_values()
    source, mapping = write_log(tmp_path, suffix, values)
    robot = str(REPO / 'config/mabi_max100.yaml')
    out = str(tmp_path / 'bag')
    result = run_cli(
        'import', str(source), '--mapping', str(mapping), '--out', out, '--robot', robot
    )
    assert result.returncode == 0, result.stderr
    assert f'{LOG_ROWS} samples in 1 segment(s) from {LOG_ROWS} rows, 0 rows dropped' in (
        result.stdout
    )
    recording = load_recording(tmp_path / 'bag', mabi)
    assert recording.joints == mabi.joints
    stamps = recording.stamps_ns - recording.stamps_ns[0]
    np.testing.assert_array_equal(stamps, 8_000_000 * np.arange(LOG_ROWS))
    degree = np.pi / 180.0
    np.testing.assert_allclose(recording.position, values['q_deg'] * degree, rtol=1e-12, atol=0)
    np.testing.assert_allclose(recording.velocity, values['v_deg_s'] * degree, rtol=1e-12, atol=0)
    np.testing.assert_allclose(recording.current, values['i_a'], rtol=1e-12, atol=0)


def test_import_of_a_log_without_a_mapped_column_exits_with_status_two(tmp_path):
    values = log_values()
    source, mapping = write_log(tmp_path, 'csv', values)
    text = mapping.read_text().replace('q_deg3', 'q_deg_missing', 1)
    mapping.write_text(text)
    result = run_cli(
        'import', str(source), '--mapping', str(mapping), '--out', str(tmp_path / 'bag')
    )
    assert result.returncode == 2
    (line,) = result.stderr.strip().splitlines()
    assert line.startswith('id-learning import: error:')
    assert 'q_deg_missing' in line
    assert not (tmp_path / 'bag').exists()


def test_import_inspect_and_train_refuse_a_config_beyond_its_urdf_with_one_message(tmp_path):
    """A velocity limit 0.01 rad/s above the URDF's: every command says so, not train alone."""
    text = (REPO / 'config/mabi_max100.yaml').read_text()
    fast = text.replace('velocity: [1.70, 1.40, 1.45, 2.35, 2.25, 3.45]',
                        'velocity: [1.70, 1.40, 1.45, 2.35, 2.25, 3.51]')  # fmt: skip
    fast = fast.replace('urdf: ../urdf/', f'urdf: {REPO}/urdf/')
    assert fast != text
    robot = tmp_path / 'fast.yaml'
    robot.write_text(fast)
    source, mapping = write_log(tmp_path, 'csv', log_values())
    commands = {
        'import': ['import', str(source), '--mapping', str(mapping), '--out',
                   str(tmp_path / 'bag'), '--robot', str(robot)],
        'inspect': ['inspect', str(REPO / 'bags/default'), '--robot', str(robot)],
        'train': ['train', '--bag', str(REPO / 'bags/default'), '--robot', str(robot),
                  '--models', 'rnea_lq', '--out', str(tmp_path / 'run')],
    }  # fmt: skip
    for name, argv in commands.items():
        result = run_cli(*argv)
        assert result.returncode == 2, (name, result.stdout)
        assert 'limits.velocity of joint_6 (3.51) lies outside the URDF limit 3.5' in result.stderr
    assert not (tmp_path / 'bag').exists()
    assert not (tmp_path / 'run').exists()
