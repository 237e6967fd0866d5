"""Training runs on short twin bags: data handling, run files, artifacts and their refusals."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest
import yaml
from support import REPO, twin_config

from id_learning.dataset.inputs import InputDefinition
from id_learning.dataset.preprocess import PreprocessConfig, lowpass, prepare_dataset
from id_learning.dataset.recording import load_recording
from id_learning.errors import CheckpointError, ConfigError
from id_learning.models.registry import load_model
from id_learning.robot import load_robot_config
from id_learning.training import (
    bag_sha256,
    combine_datasets,
    data_sha256,
    evaluate_run,
    load_datasets,
    measure_inference,
    train_run,
)
from id_learning.twin import simulate, write_twin_output

FAST = {'mlp': {'max_epochs': 2}}


@pytest.fixture(scope='module')
def bags(tmp_path_factory):
    """Two 51.5 s default twin recordings with different seeds (different excitations).

    Long enough to fit through the 0.3 Hz label filter, which reads 11 s on either side.
    """
    folder = tmp_path_factory.mktemp('bags')
    paths = []
    for seed in (11, 12):
        config = twin_config(60.0, seed=seed)
        paths.append(write_twin_output(simulate(config), config, folder / f'twin_{seed}'))
    return paths


@pytest.fixture(scope='module')
def run(bags, mabi, tmp_path_factory):
    out = tmp_path_factory.mktemp('run') / 'run'
    return train_run(
        bags, mabi, 'motor', ['rnea_lq', 'mlp'], out, hyper=FAST, progress=False, device='cpu'
    )


def test_each_bag_is_filtered_on_its_own_and_training_parts_come_first(bags, mabi):
    config = PreprocessConfig()
    separate = [prepare_dataset(load_recording(b, mabi), mabi, config) for b in bags]
    combined = combine_datasets(load_datasets(bags, mabi, config, progress=False))
    first, second = separate
    assert first.n_train > 1000
    assert combined.n_train == first.n_train + second.n_train
    expected_q = np.concatenate(
        [
            first.q[: first.n_train],
            second.q[: second.n_train],
            first.q[first.n_train :],
            second.q[second.n_train :],
        ]
    )
    np.testing.assert_array_equal(combined.q, expected_q)
    segments = combined.extra['segments']
    assert [s['train'] for s in segments] == [
        [0, first.n_train],
        [first.n_train, combined.n_train],
    ]
    second_test = segments[1]['test']
    np.testing.assert_array_equal(
        combined.tau[second_test[0] : second_test[1]], second.tau[second.n_train :]
    )
    # The label scaler sees both training parts, and only them.
    np.testing.assert_array_equal(
        combined.target_scaler.high_,
        np.maximum(first.tau[: first.n_train].max(0), second.tau[: second.n_train].max(0)),
    )


def test_a_run_writes_metrics_with_per_joint_errors_and_timings(run, mabi):
    metrics = json.loads((run.out / 'metrics.json').read_text())
    assert list(metrics['models']) == ['rnea_lq', 'mlp']
    scale = np.asarray(metrics['target_scale_nm'])
    np.testing.assert_array_equal(scale, run.dataset.target_scaler.scale())
    test_rows = sum(b - a for a, b in (s['test'] for s in run.dataset.extra['segments']))
    assert metrics['n_samples'] == test_rows
    for entry in metrics['models'].values():
        assert len(entry['rmse_nm']) == mabi.n_joints
        np.testing.assert_allclose(
            entry['rmse_normalised'], np.asarray(entry['rmse_nm']) / scale, rtol=1e-12
        )
        assert entry['train_seconds'] > 0
        assert entry['inference_seconds_per_sample'] > 0
        assert 0 < entry['latency_single_sample_median_s'] <= entry['latency_single_sample_p99_s']
    assert metrics['models']['mlp']['history']['epochs'] == 2
    assert metrics['findings'][0]['holds'] is None  # two models cannot decide the findings
    report = (run.out / 'report.md').read_text()
    assert '| RNEA+LQ |' in report
    assert '| MLP |' in report


def test_metrics_score_through_the_filter_against_labels_and_the_twins_truth(run, bags, mabi):
    """Each bag scored independently: scipy's filter over the whole recording, its test part."""
    metrics = json.loads((run.out / 'metrics.json').read_text())
    model = load_model(run.out / 'models/rnea_lq', mabi)
    sums = {key: np.zeros(mabi.n_joints) for key in ('label', 'truth', 'raw', 'floor', 'study')}
    count = 0
    for bag in bags:
        dataset = prepare_dataset(load_recording(bag, mabi), mabi)
        with np.load(bag / 'ground_truth.npz') as arrays:
            clean = arrays['tau_u_clean'].astype(float)
        motion, test = dataset.controller, slice(dataset.n_train, None)
        torque = model.predict(motion.q, motion.v, motion.a)
        cutoff, period = dataset.cutoff_hz, dataset.period_s
        filtered, clean_filtered = (lowpass(x, cutoff, period) for x in (torque, clean))
        study = model.predict(*(getattr(dataset.study, k)[test] for k in ('q', 'v', 'a')))
        errors = {
            'label': filtered[test] - dataset.tau[test],
            'truth': filtered[test] - clean_filtered[test],
            'raw': torque[test] - clean[test],
            'floor': dataset.tau[test] - clean_filtered[test],
            'study': study - dataset.tau[test],
        }
        for key, error in errors.items():
            sums[key] += np.sum(error**2, axis=0)
        count += len(dataset.tau) - dataset.n_train
    rms = {key: np.sqrt(value / count) for key, value in sums.items()}
    entry = metrics['models']['rnea_lq']

    np.testing.assert_allclose(entry['rmse_through_filter_nm'], rms['label'], rtol=1e-9)
    np.testing.assert_allclose(entry['rmse_nm'], rms['label'], rtol=1e-9)
    np.testing.assert_allclose(entry['rmse_true_through_filter_nm'], rms['truth'], rtol=1e-6)
    np.testing.assert_allclose(entry['rmse_true_nm'], rms['raw'], rtol=1e-6)
    np.testing.assert_allclose(metrics['label_noise_floor_nm'], rms['floor'], rtol=1e-6)
    np.testing.assert_allclose(
        entry['rmse_through_filter_over_floor'], rms['label'] / rms['floor'], rtol=1e-6
    )
    np.testing.assert_allclose(entry['study_way']['rmse_nm'], rms['study'], rtol=1e-9)
    assert metrics['inputs']['name'] == 'controller'
    assert metrics['label_filter']['cutoff_hz'] == [1.2, 0.3, 0.3, 0.7, 0.5, 0.7]


def test_artifacts_carry_preprocessing_data_hashes_and_metrics(run, bags):
    document = json.loads((run.out / 'models/mlp/model.json').read_text())
    assert document['preprocessing']['target'] == 'motor'
    assert document['preprocessing']['mode'] == 'through_filter'
    assert document['preprocessing']['cutoff_hz'] == [1.2, 0.3, 0.3, 0.7, 0.5, 0.7]
    assert document['preprocessing']['train_fraction'] == 0.7
    inputs = InputDefinition.from_dict(document['preprocessing']['inputs'])
    assert inputs == InputDefinition.controller(np.full(6, 10.0))
    assert document['preprocessing']['fitting_inputs'] == document['preprocessing']['inputs']
    training = document['training_data']
    assert [b['sha256'] for b in training['bags']] == [bag_sha256(b) for b in bags]
    assert training['data_sha256'] == data_sha256(run.dataset)
    assert document['metrics']['rmse_nm'] == run.metrics['models']['mlp']['rmse_nm']
    assert document['train_history']['epochs'] == 2
    run_document = json.loads((run.out / 'run.json').read_text())
    assert run_document['robot_config'] == str((REPO / 'config/mabi_max100.yaml').resolve())


def test_saved_models_load_back_and_predict_exactly_the_same(run, mabi):
    ds = run.dataset
    test = slice(ds.n_train, None)
    for kind, result in run.models.items():
        loaded = load_model(run.out / 'models' / kind, mabi)
        assert loaded.kind == kind
        np.testing.assert_allclose(
            loaded.predict(ds.q[test], ds.v[test], ds.a[test]),
            result.model.predict(ds.q[test], ds.v[test], ds.a[test]),
            rtol=0,
            atol=0,
        )


def reordered_mabi(folder: Path) -> Path:
    """A MABI config copy that lists the same joints in reverse order."""
    data = yaml.safe_load((REPO / 'config/mabi_max100.yaml').read_text())
    data['urdf'] = str(REPO / 'urdf/mabi_max100.urdf')
    data['joints'] = list(reversed(data['joints']))
    path = folder / 'mabi_reordered.yaml'
    path.write_text(yaml.safe_dump(data))
    return path


def test_loading_for_another_robot_or_another_joint_order_is_refused(run, tmp_path):
    folder = run.out / 'models/rnea_lq'
    with pytest.raises(CheckpointError, match='do not match robot ur5'):
        load_model(folder, load_robot_config(REPO / 'config/ur5.yaml'))
    reordered = load_robot_config(reordered_mabi(tmp_path))
    with pytest.raises(CheckpointError, match='names and order must agree'):
        load_model(folder, reordered)
    with pytest.raises(CheckpointError, match='do not match robot'):
        evaluate_run(run.out, [], reordered, tmp_path / 'eval', progress=False)


@pytest.fixture
def artifact_copy(run, tmp_path):
    folder = tmp_path / 'mlp'
    shutil.copytree(run.out / 'models/mlp', folder)
    return folder


def test_a_tampered_weights_file_is_refused(artifact_copy, mabi):
    weights = artifact_copy / 'weights.safetensors'
    data = bytearray(weights.read_bytes())
    data[-1] ^= 0x01
    weights.write_bytes(bytes(data))
    with pytest.raises(CheckpointError, match='do not match the hash'):
        load_model(artifact_copy, mabi)


@pytest.mark.parametrize(
    ('edit', 'message'),
    [
        (lambda d: {**d, 'format': 'something.else/1'}, 'format is not'),
        (lambda d: {**d, 'kind': 'rnea_lq'}, 'hyper-parameters do not fit rnea_lq'),
        (lambda d: {**d, 'tensors': {**d['tensors'], 'extra': [1]}}, 'differ from the metadata'),
        (lambda d: {**d, 'units': {**d['units'], 'tau': 'kN*m'}}, 'units'),
    ],
    ids=['format', 'kind', 'tensor-list', 'units'],
)
def test_a_model_json_that_is_not_what_it_claims_is_refused(artifact_copy, mabi, edit, message):
    meta = artifact_copy / 'model.json'
    meta.write_text(json.dumps(edit(json.loads(meta.read_text()))))
    with pytest.raises(CheckpointError, match=message):
        load_model(artifact_copy, mabi)


def test_a_model_json_that_is_not_json_is_refused(artifact_copy, mabi):
    (artifact_copy / 'model.json').write_text('weights: pickled\n')
    with pytest.raises(CheckpointError, match='not valid JSON'):
        load_model(artifact_copy, mabi)


def test_evaluate_takes_the_test_part_of_a_training_bag_and_all_of_a_new_one(
    run, bags, mabi, tmp_path
):
    config = twin_config(30.0, seed=21)
    new_bag = write_twin_output(simulate(config), config, tmp_path / 'new')
    result = evaluate_run(run.out, [bags[0], new_bag], mabi, tmp_path / 'eval', progress=False)
    first = prepare_dataset(load_recording(bags[0], mabi), mabi)
    new = prepare_dataset(load_recording(new_bag, mabi), mabi)
    expected = (len(first.q) - first.n_train) + len(new.q)
    assert result.metrics['n_samples'] == expected
    assert 'test part only' in result.metrics['evaluated_on']
    assert 'whole recording' in result.metrics['evaluated_on']
    # Errors are normalised with the run's training scaler, so they read like the run's own.
    assert result.metrics['target_scale_nm'] == run.metrics['target_scale_nm']
    # The test part of a training bag is scored exactly as the run scored it: the filtered
    # torque of its whole recording, not of the test part alone.
    alone = evaluate_run(run.out, [bags[0]], mabi, tmp_path / 'eval_first', progress=False)
    model = run.models['rnea_lq'].model
    torque = model.predict(first.controller.q, first.controller.v, first.controller.a)
    filtered = lowpass(torque, first.cutoff_hz, first.period_s)
    test = slice(first.n_train, None)
    expected = np.sqrt(np.mean((filtered[test] - first.tau[test]) ** 2, axis=0))
    np.testing.assert_allclose(alone.metrics['models']['rnea_lq']['rmse_nm'], expected, rtol=1e-9)
    assert (tmp_path / 'eval/report.md').is_file()
    assert set(result.metrics['models']) == {'rnea_lq', 'mlp'}


def test_unknown_kinds_and_hyper_parameters_are_refused_before_any_bag_is_read(mabi, tmp_path):
    missing = [tmp_path / 'no_such_bag']
    with pytest.raises(ConfigError, match='known kinds'):
        train_run(missing, mabi, 'motor', ['mlp', 'gpr'], tmp_path / 'r', progress=False)
    with pytest.raises(ConfigError, match='unknown hyper-parameter'):
        train_run(missing, mabi, 'motor', ['mlp'], tmp_path / 'r', hyper={'mlp': {'widht': 3}})
    with pytest.raises(ConfigError, match='not trained'):
        train_run(missing, mabi, 'motor', ['mlp'], tmp_path / 'r', hyper={'lnn': {}})


def test_inference_timing_reports_batched_and_one_sample_latency(run):
    ds, model = run.dataset, run.models['mlp'].model
    timing = measure_inference(model, ds.q[:500], ds.v[:500], ds.a[:500], calls=20, repeats=1)
    assert timing['inference_seconds_per_sample'] > 0
    assert timing['latency_window_samples'] == 1
    assert timing['latency_single_sample_median_s'] > 0
    assert timing['latency_threads'] == 1
