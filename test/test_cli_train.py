"""``id-learning train`` and ``evaluate`` end to end, run as a user would (subprocesses, files)."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from support import REPO, run_cli, twin_config

from id_learning.cli.main import _without_ros_arguments
from id_learning.dataset.preprocess import lowpass, prepare_dataset
from id_learning.dataset.recording import load_recording
from id_learning.models.registry import STUDY_MODELS, load_model
from id_learning.twin import simulate, write_twin_output

pytestmark = pytest.mark.slow  # trains all seven study models in subprocesses

# Tiny budgets: this checks the plumbing of all seven models, not their accuracy.
ONE_EPOCH = [
    item
    for kind in STUDY_MODELS
    if kind != 'rnea_lq'
    for item in ('--hyper', f'{kind}.max_epochs=1')
]


@pytest.fixture(scope='module')
def twin_bags(tmp_path_factory):
    folder = tmp_path_factory.mktemp('cli_train')
    paths = []
    # The training bag lasts 51.5 s: fitting through the 0.3 Hz label filter reads 11 s each side.
    for seed, duration in ((5, 60.0), (6, 30.0)):
        config = twin_config(duration, seed=seed)
        paths.append(write_twin_output(simulate(config), config, folder / f'twin_{seed}'))
    return paths


@pytest.fixture(scope='module')
def trained(twin_bags, tmp_path_factory):
    out = tmp_path_factory.mktemp('cli_run') / 'run'
    result = run_cli(
        'train',
        '--bag',
        str(twin_bags[0]),
        '--robot',
        str(REPO / 'config/mabi_max100.yaml'),
        '--target',
        'motor',
        '--models',
        ','.join(STUDY_MODELS),
        '--out',
        str(out),
        '--device',
        'cpu',
        '--max-seconds-per-model',
        '30',
        '--quiet',
        *ONE_EPOCH,
    )
    assert result.returncode == 0, result.stderr
    return out, result.stdout


def test_train_writes_metrics_report_and_one_artifact_per_model(trained):
    out, stdout = trained
    metrics = json.loads((out / 'metrics.json').read_text())
    assert list(metrics['models']) == list(STUDY_MODELS)
    for kind, entry in metrics['models'].items():
        assert len(entry['rmse_nm']) == 6, kind
        assert np.all(np.isfinite(entry['rmse_nm'])), kind
        assert (out / 'models' / kind / 'weights.safetensors').is_file()
        assert (out / 'models' / kind / 'model.json').is_file()
    assert metrics['models']['lstm']['latency_window_samples'] == 20
    report = (out / 'report.md').read_text()
    assert '| LNN+MLP |' in report
    assert "## (e) Do the study's findings hold on this data?" in report
    assert f'report: {out / "report.md"}' in stdout
    assert 'RNEA+MLP' in stdout  # the printed RMSE table


def test_every_trained_model_loads_back_and_predicts_exactly_the_same(trained, twin_bags, mabi):
    out, _ = trained
    dataset = prepare_dataset(load_recording(twin_bags[0], mabi), mabi)
    test = slice(dataset.n_train, None)
    metrics = json.loads((out / 'metrics.json').read_text())
    for kind in STUDY_MODELS:
        model = load_model(out / 'models' / kind, mabi)
        again = load_model(out / 'models' / kind, mabi)
        prediction = model.predict(dataset.q[test], dataset.v[test], dataset.a[test])
        np.testing.assert_allclose(
            prediction,
            again.predict(dataset.q[test], dataset.v[test], dataset.a[test]),
            rtol=0,
            atol=0,
        )
        # The loaded model reproduces the run's own test RMSE, scored independently: through
        # the label filter (its torque along the whole recording on the controller's inputs,
        # low-passed with scipy) and the study's way (on its low-passed inputs, as is).
        motion = dataset.controller
        along = model.predict(motion.q, motion.v, motion.a)
        filtered = lowpass(along, dataset.cutoff_hz, dataset.period_s, dataset.filter_order)
        rmse = np.sqrt(np.mean((filtered[test] - dataset.tau[test]) ** 2, axis=0))
        entry = metrics['models'][kind]
        np.testing.assert_allclose(rmse, entry['rmse_through_filter_nm'], rtol=1e-6)
        np.testing.assert_allclose(rmse, entry['rmse_nm'], rtol=1e-6)
        study = dataset.study.take(test)
        study_error = model.predict(study.q, study.v, study.a) - dataset.tau[test]
        study_rmse = np.sqrt(np.mean(study_error**2, axis=0))
        np.testing.assert_allclose(study_rmse, entry['study_way']['rmse_nm'], rtol=1e-6)


def test_evaluate_writes_the_same_metrics_and_report_for_another_recording(
    trained, twin_bags, tmp_path
):
    out, _ = trained
    result = run_cli(
        'evaluate',
        '--run',
        str(out),
        '--bag',
        str(twin_bags[1]),
        '--out',
        str(tmp_path),
        '--quiet',
    )
    assert result.returncode == 0, result.stderr
    metrics = json.loads((tmp_path / 'metrics.json').read_text())
    assert metrics['kind'] == 'evaluation'
    assert 'whole recording' in metrics['evaluated_on']
    assert list(metrics['models']) == list(STUDY_MODELS)
    assert (tmp_path / 'report.md').is_file()
    assert (tmp_path / 'abs_error_boxplot.png').stat().st_size > 20_000


def test_an_unknown_model_kind_exits_with_status_two_and_lists_the_known_ones(tmp_path):
    result = run_cli(
        'train', '--bag', str(tmp_path), '--models', 'mlp,gpr', '--out', str(tmp_path / 'r')
    )
    assert result.returncode == 2
    assert result.stderr.startswith('id-learning train: error: --models: unknown model kind')
    assert 'rnea_lq, rnea_mlp, delan, lnn, lnn_mlp, mlp, lstm' in result.stderr


def test_a_malformed_hyper_parameter_is_refused(tmp_path):
    result = run_cli(
        'train', '--bag', str(tmp_path), '--hyper', 'max_epochs=3', '--out', str(tmp_path / 'r')
    )
    assert result.returncode == 2
    assert 'expected KIND.KEY=VALUE' in result.stderr


def test_the_ros2_run_entry_point_drops_ros_arguments():
    argv = ['--bag', 'b', '--ros-args', '-r', '__node:=x', '--', '--out', 'o', '--ros-args']
    assert _without_ros_arguments(argv) == ['--bag', 'b', '--out', 'o']


def test_the_train_console_script_runs_train_and_ignores_ros_arguments(tmp_path):
    """The installed ``train`` script, as ``ros2 run id_learning train`` starts it."""
    script = Path(sys.executable).parent / 'train'
    if not script.exists():
        pytest.skip(f'the package is not installed next to {sys.executable} (make venv does)')
    missing = tmp_path / 'no_such_bag'
    result = subprocess.run(
        [str(script), '--bag', str(missing), '--out', str(tmp_path / 'run'),
         '--ros-args', '-r', '__node:=train', '--'],
        capture_output=True, text=True, timeout=120, check=False,
    )  # fmt: skip
    assert result.returncode == 2, result.stderr
    (line,) = result.stderr.strip().splitlines()
    assert line.startswith('id-learning train: error:')
    assert f'{missing}: no such bag' in line
