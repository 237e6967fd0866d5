"""Inputs that mix what must not be mixed are refused, naming both sides.

A sweep study holds trials of one kind, target, robot, preprocessing and set of bags; a run's
models predict the run's target; a run.json holds each key once; a fit's time budget is set
once. A trial that fails says so in one line, without Optuna's traceback.
"""

from __future__ import annotations

import json
import logging
import shutil
from pathlib import Path

import optuna
import pytest

from id_learning.cli.main import main as cli
from id_learning.dataset.preprocess import PreprocessConfig
from id_learning.errors import CheckpointError, ConfigError, DatasetError
from id_learning.models.artifact import document_digest
from id_learning.training import evaluate_run, read_run
from id_learning.training import sweep as sweep_module
from id_learning.training.sweep import SETTINGS_ATTR, _claim_study, run_sweep


# -- sweeps --------------------------------------------------------------------------------------
def _sweep(bag: Path, out: Path, storage: str, mabi, kind: str = 'rnea_lq', **extra):
    return run_sweep(
        [bag], mabi, 'motor', kind, out, trials=1, storage=storage, study_name='shared',
        progress=False, seed=0, max_seconds_per_trial=2.0, **extra,
    )  # fmt: skip


def test_a_study_refuses_a_sweep_of_another_kind_bag_or_preprocessing_naming_both(
    bags, tmp_path, mabi
):
    storage = f'sqlite:///{tmp_path / "shared.db"}'
    first = _sweep(bags[0], tmp_path / 'k1', storage, mabi)
    assert first.finished == 1
    with pytest.raises(ConfigError, match=r"for model kind 'rnea_lq'; this sweep is for 'mlp'"):
        _sweep(bags[0], tmp_path / 'k2', storage, mabi, kind='mlp')
    with pytest.raises(ConfigError, match=r'for bags \[SHA-256 \w{12}\]; this sweep is for '):
        _sweep(bags[1], tmp_path / 'k3', storage, mabi)
    with pytest.raises(
        ConfigError,
        match=r"for preprocessing \{'mode': 'through_filter'\}; this sweep is for \{'mode': "
        r"'study'\}",
    ):
        _sweep(bags[0], tmp_path / 'k4', storage, mabi, preprocess=PreprocessConfig(mode='study'))
    # The same settings join the study; its best is still a trial of its kind.
    again = _sweep(bags[0], tmp_path / 'k5', storage, mabi)
    assert again.finished == 2
    assert set(again.best_params) <= set(sweep_module.SEARCH_SPACES['rnea_lq'])
    study = optuna.load_study(study_name='shared', storage=storage)
    assert study.user_attrs[SETTINGS_ATTR]['kind'] == 'rnea_lq'


def test_a_study_recorded_for_another_target_or_robot_is_refused_naming_both():
    study = optuna.create_study()
    ours = {'kind': 'mlp', 'target': 'motor', 'robot': {'name': 'mabi', 'urdf_sha256': 'a' * 64}}
    _claim_study(study, ours, 'memory')
    _claim_study(study, ours, 'memory')  # the same settings again
    with pytest.raises(ConfigError, match=r"target 'motor'; this sweep is for 'joint'"):
        _claim_study(study, {**ours, 'target': 'joint'}, 'memory')
    other = {**ours, 'robot': {'name': 'ur5', 'urdf_sha256': 'b' * 64}}
    with pytest.raises(
        ConfigError, match=r"robot 'mabi' \(URDF a{12}\); this sweep is for 'ur5' \(URDF b{12}\)"
    ):
        _claim_study(study, other, 'memory')


def test_a_study_with_trials_but_no_record_of_their_settings_is_refused(bags, tmp_path, mabi):
    storage = f'sqlite:///{tmp_path / "old.db"}'
    old = optuna.create_study(study_name='shared', storage=storage)
    old.add_trial(optuna.trial.create_trial(value=1.0))
    with pytest.raises(ConfigError, match=r'holds 1 trial\(s\) but no record of the kind'):
        _sweep(bags[0], tmp_path / 'out', storage, mabi)


def test_a_failed_trial_is_one_line_without_optunas_traceback(
    bags, tmp_path, mabi, monkeypatch, capfd
):
    def fails(model, data):
        raise DatasetError(f'{bags[0]}: the validation part is too short')

    monkeypatch.setattr(sweep_module, 'validation_error', fails)
    seen: list[logging.LogRecord] = []
    handler = logging.Handler()
    handler.emit = seen.append  # type: ignore[method-assign]
    logging.getLogger('optuna').addHandler(handler)
    try:
        code = cli([
            'sweep', '--bag', str(bags[0]), '--model', 'rnea_lq', '--trials', '2',
            '--out', str(tmp_path / 'out'), '--quiet',
        ])  # fmt: skip
    finally:
        logging.getLogger('optuna').removeHandler(handler)
    err = capfd.readouterr().err
    assert code == 2
    assert 'Traceback' not in err
    assert 'Trial 0 failed' not in err
    assert not [r for r in seen if 'failed' in r.getMessage()]
    lines = [line for line in err.splitlines() if line.strip()]
    assert lines[-1] == (
        f'id-learning sweep: error: sweep: trial 0 failed: {bags[0]}: the validation part is '
        'too short'
    )
    assert not [line for line in lines if 'rial' in line and not line.startswith('id-learning')]
    # The filter is gone after the sweep: Optuna's own reports reach its handlers again.
    assert not logging.getLogger('optuna.study._optimize').filters


# -- a run's documents ---------------------------------------------------------------------------
def _copy_run(run, tmp_path: Path) -> Path:
    folder = tmp_path / 'run'
    shutil.copytree(run.out, folder)
    return folder


def test_a_model_of_another_target_than_its_run_is_refused_naming_both(run, bags, mabi, tmp_path):
    folder = _copy_run(run, tmp_path)
    meta = folder / 'models' / 'mlp' / 'model.json'
    document = json.loads(meta.read_text())
    document['preprocessing']['target'] = 'joint'
    document['artifact_sha256'] = document_digest(document)
    meta.write_text(json.dumps(document, indent=1))
    with pytest.raises(
        CheckpointError,
        match=r"models/mlp: its model\.json says the model predicts the 'joint' torque, but "
        r"the run's preprocessing\.target is 'motor'",
    ):
        evaluate_run(folder, bags[:1], mabi, tmp_path / 'eval', progress=False)


def test_a_run_json_with_a_key_twice_is_refused_naming_file_and_key(run, tmp_path):
    folder = _copy_run(run, tmp_path)
    path = folder / 'run.json'
    text = path.read_text()
    path.write_text(text.replace('{', '{\n "status": "complete",', 1))
    with pytest.raises(CheckpointError, match=r"run\.json: key 'status' appears twice"):
        read_run(folder)


# -- one budget ----------------------------------------------------------------------------------
def test_a_kinds_max_seconds_beside_another_max_seconds_per_model_is_refused(
    bags, tmp_path, capfd
):
    """On the command line both are the user's: neither silently wins. (In code a kind's own
    budget is the more specific one: the demo gives the physics kinds longer.)"""
    code = cli([
        'train', '--bag', str(bags[0]), '--models', 'mlp', '--hyper', 'mlp.max_seconds=100',
        '--max-seconds-per-model', '1', '--out', str(tmp_path / 'r'), '--quiet',
    ])  # fmt: skip
    assert code == 2
    assert (
        'error: --hyper mlp.max_seconds=100 contradicts --max-seconds-per-model 1: both set '
        'the time budget of each mlp fit; give one'
    ) in capfd.readouterr().err
    hyper_file = tmp_path / 'best.yaml'
    hyper_file.write_text('mlp:\n  max_seconds: 5\n')
    code = cli([
        'train', '--bag', str(bags[0]), '--models', 'mlp', '--hyper-file', str(hyper_file),
        '--max-seconds-per-model', '1', '--out', str(tmp_path / 'r'), '--quiet',
    ])  # fmt: skip
    assert code == 2
    assert f'--hyper-file {hyper_file} (mlp.max_seconds: 5) contradicts' in capfd.readouterr().err
    assert not (tmp_path / 'r').exists()
