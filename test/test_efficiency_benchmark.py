"""benchmarks/efficiency.py end to end on one robot and the cheapest kind, and its page."""

from __future__ import annotations

import importlib
import json
import subprocess
import sys

import pytest
from support import REPO


@pytest.fixture
def bench(monkeypatch):
    monkeypatch.syspath_prepend(str(REPO / 'benchmarks'))
    return importlib.import_module('efficiency')


@pytest.mark.slow  # a twin recording and one fit in a process of its own: about 15 s
def test_one_robot_one_kind_gives_every_figure_and_json_alone_on_stdout(tmp_path):
    result = subprocess.run(
        [sys.executable, 'benchmarks/efficiency.py', '--robots', 'ur5', '--models', 'rnea_lq',
         '--seconds', '8', '--max-seconds-per-model', '5', '--samples', '200', '--warm-up', '20',
         '--no-results', '--out', str(tmp_path)],
        cwd=REPO, capture_output=True, text=True, timeout=120, check=False,
    )  # fmt: skip
    assert result.returncode == 0, result.stderr[-3000:]
    document = json.loads(result.stdout)  # what the fit printed went to stderr
    m = document['robots']['ur5']['models']['rnea_lq']
    assert 'skipped' not in m, m
    assert 0 < m['train_seconds'] <= m['train_run_seconds']
    assert 0 < m['step']['p50_ms'] <= m['step']['p99_ms']
    assert 0 < m['model']['p50_ms'] <= m['model']['p99_ms']
    assert m['served_share'] == 1.0  # the steps timed served the model, none was held
    assert m['peak_growth_mb'] > 0
    assert m['peak_rss_mb'] >= m['rss_before_mb']
    assert m['artifact_kb'] > 0
    assert m['parameters'] == 4 * 6  # rotor inertia, viscous, Coulomb, offset per UR5 joint
    assert '| ur5 | rnea_lq |' in result.stderr
    assert 'wrote ' not in result.stderr  # --no-results: no page


def test_page_names_skips_and_steps_the_model_did_not_serve(bench):
    figures = {
        'train_seconds': 1.0,
        'train_run_seconds': 2.0,
        'stopped_by': None,
        'cut_short': ['the final fit'],
        'step': {'p50_ms': 0.1, 'p99_ms': 0.2},
        'model': {'p50_ms': 0.01, 'p99_ms': 0.02},
        'peak_growth_mb': 100.0,
        'peak_from': 'VmHWM reset before train_run',
        'artifact_kb': 7.0,
        'parameters': 24,
        'served_share': 0.5,
    }
    document = {
        'robots': {
            'ur5': {
                'ipo_period_ms': 8.0,
                'models': {'rnea_lq': figures, 'lstm': {'skipped': 'TrainingError: why'}},
            }
        },
        'twin_seconds': 20.0,
        'seed': 1,
        'device': 'cpu',
        'max_seconds_per_model': 5.0,
        'latency_threads': 1,
        'samples': 10,
        'warm_up': 1,
        'wall_seconds': 3.0,
    }
    lines = bench.report(document, [])
    row = next(line for line in lines if line.startswith('| ur5 |'))
    assert row.split(' | ')[3] == 'time_budget'  # cut short without a loop's own reason
    assert '- ur5, `lstm`: not measured: TrainingError: why' in lines
    assert any('served 50.0% of the timed steps' in line for line in lines)
    assert bench.summary(document['robots']['ur5']['models']['lstm']).startswith('skipped')
