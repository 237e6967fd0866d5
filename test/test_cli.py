"""The id-learning command line, run as a user would (subprocesses, real files)."""

from __future__ import annotations

import json

import pytest
from support import REPO, run_cli


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


def test_simulate_writes_a_bag_with_ground_truth(twin_bag):
    assert (twin_bag / 'metadata.yaml').is_file()
    truth = json.loads((twin_bag / 'ground_truth.json').read_text())
    assert truth['seed'] == 3
    assert 'viscous_friction' in truth['effects_enabled']


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
    assert '/joint_states' in result.stdout
    assert '/motor_currents' in result.stdout
    assert '125' in result.stdout
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


def test_import_converts_a_csv_log(tmp_path):
    lines = ['t_ms,' + ','.join(f'q{j},v{j},i{j}' for j in range(1, 7))]
    for k in range(100):
        lines.append(f'{8 * k},' + ','.join(f'{0.1 * k + j},{j},{0.5}' for j in range(1, 7)))
    (tmp_path / 'log.csv').write_text('\n'.join(lines) + '\n')
    joints = '\n'.join(
        f'  - name: joint_{j}\n    position: {{column: q{j}, unit: deg}}\n'
        f'    velocity: {{column: v{j}, unit: deg/s}}\n    current: {{column: i{j}, unit: A}}'
        for j in range(1, 7)
    )
    (tmp_path / 'map.yaml').write_text(f'time: {{column: t_ms, unit: ms}}\njoints:\n{joints}\n')
    result = run_cli(
        'import',
        str(tmp_path / 'log.csv'),
        '--mapping',
        str(tmp_path / 'map.yaml'),
        '--out',
        str(tmp_path / 'bag'),
        '--robot',
        str(REPO / 'config/mabi_max100.yaml'),
    )
    assert result.returncode == 0, result.stderr
    assert (tmp_path / 'bag/metadata.yaml').is_file()
