"""benchmarks/delan_character.py: the reference's metric, strict flags, skip, a tiny run."""

from __future__ import annotations

import importlib
import json

import numpy as np
import pytest
from support import REPO


@pytest.fixture
def bench(monkeypatch):
    monkeypatch.syspath_prepend(str(REPO / 'benchmarks'))
    return importlib.import_module('delan_character')


def test_metric_sums_over_joints_and_averages_over_samples(bench):
    predicted = np.zeros((4, 2))
    target = np.array([[1.0, 2.0], [0.0, 0.0], [1.0, 0.0], [0.0, 1.0]])
    assert bench.mse_sum_joints(predicted, target) == pytest.approx((5 + 0 + 1 + 1) / 4)
    assert bench.mse_sum_joints(predicted, target) == pytest.approx(2 * np.mean(target**2))


def test_flags_only_where_strictly_better(bench):
    reference = bench.REFERENCE['lnn']
    level, wall = reference['test_mse_sum_joints_median'], reference['timed_run']['wall_s']

    def runs(mse, seconds):
        return [
            {
                'test_mse_sum_joints': m,
                'test_mse_per_joint': [m / 2, m / 2],
                'wall_s': seconds,
                'cpu_s': seconds,
                'train_loss_normalised': 0.0,
            }
            for m in mse
        ]

    worse = bench.summarise('lnn', runs([0.5 * level, 1.5 * level, 2 * level], wall), [0, 1, 2])
    assert worse['test_mse_sum_joints_median'] == pytest.approx(1.5 * level)
    assert not worse['beats_reference_mse']
    assert not worse['beats_reference_time']
    equal = bench.summarise('lnn', runs([level], wall), [0])
    assert not equal['beats_reference_mse']
    better = bench.summarise('lnn', runs([0.9 * level] * 5, 0.5 * wall), list(range(5)))
    assert better['beats_reference_mse']
    assert better['beats_reference_time']


@pytest.mark.parametrize('epochs', range(1, 40))
def test_schedule_spends_every_epoch(bench, epochs):
    steps = bench.schedule(3e-3, epochs)
    assert sum(n for _, n in steps) == epochs
    assert all(n > 0 for _, n in steps)
    assert [rate for rate, _ in steps] == sorted((rate for rate, _ in steps), reverse=True)


def test_skips_without_data(bench, tmp_path, capsys):
    assert bench.main(['--data', str(tmp_path)]) == 0
    assert 'skipped' in json.loads(capsys.readouterr().out)


def test_tiny_run_reports_per_seed_and_median(bench, tmp_path, capsys):
    rng = np.random.default_rng(0)
    labels = np.array(['a', 'b', 'e', 'q', 'v'])
    lengths = np.full(5, 8)
    n = int(lengths.sum())
    arrays = {key: rng.normal(size=(n, 2)) for key in ('qp', 'qv', 'qa', 'tau')}
    np.savez(tmp_path / bench.DATA_FILE, labels=labels, lengths=lengths, **arrays)
    argv = ['--data', str(tmp_path), '--seeds', '2', '--delan-epochs', '2', '--lnn-epochs', '2']
    argv += ['--no-results']
    assert bench.main(argv) == 0
    result = json.loads(capsys.readouterr().out)
    assert result['test_samples'] == 24
    for kind in ('delan', 'lnn'):
        model = result['models'][kind]
        assert len(model['test_mse_sum_joints_per_seed']) == 2
        assert model['test_mse_sum_joints_median'] == pytest.approx(
            np.median(model['test_mse_sum_joints_per_seed'])
        )
