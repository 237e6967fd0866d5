"""Training runs on short twin bags: data handling, run files, artifacts and their refusals."""

from __future__ import annotations

import json
import shutil
from dataclasses import replace
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
import torch
import yaml
from support import FAST_HYPER, REPO, twin_config

from id_learning.dataset.inputs import InputDefinition
from id_learning.dataset.preprocess import PreprocessConfig, lowpass, prepare_dataset
from id_learning.dataset.recording import load_recording
from id_learning.errors import CheckpointError, ConfigError
from id_learning.models.artifact import ARTIFACT_HASH, document_digest
from id_learning.models.registry import load_model
from id_learning.robot import load_robot_config
from id_learning.training import (
    bag_sha256,
    combine_datasets,
    data_sha256,
    evaluate_run,
    load_datasets,
    measure,
    measure_inference,
    train_run,
)
from id_learning.training.measure import LATENCY_CALLS, LATENCY_WARMUP
from id_learning.twin import simulate, write_twin_output


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


def test_a_run_writes_metrics_with_per_joint_errors_and_timings(timed_run, mabi):
    run, fit_seconds, wall_seconds = timed_run
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
        assert entry['latency_single_sample_median_s'] <= entry['latency_single_sample_p99_s']
    # Timings in seconds, each within the run's wall clock: a fit takes at least what fit()
    # took, timed inside it; fits, scoring (each sample predicted twice) and the one-sample calls
    # (half at least as long as the median) follow one another, so together they fit in the run.
    spent = 0.0
    for kind, entry in metrics['models'].items():
        assert fit_seconds[kind] <= entry['train_seconds'] <= wall_seconds, kind
        spent += entry['train_seconds']
        spent += entry['inference_seconds_per_sample'] * 2 * len(run.dataset.tau)
        spent += entry['latency_single_sample_median_s'] * (LATENCY_CALLS // 2)
    assert spent <= wall_seconds
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
    assert document['metrics']['rmse_nm'] == run.metrics['models']['mlp']['rmse_nm']
    assert document['train_history']['epochs'] == 2
    run_document = json.loads((run.out / 'run.json').read_text())
    assert run_document['robot_config'] == str((REPO / 'config/mabi_max100.yaml').resolve())
    # run.json records each saved model's whole-artifact hash (the run's own models).
    assert run_document['artifacts']['mlp'] == document['artifact_sha256']
    assert set(run_document['artifacts']) == set(run_document['kinds'])


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


def test_the_recorded_hashes_identify_the_bag_bytes_and_the_data_a_model_saw(
    run, bags, mabi, tmp_path
):
    training = json.loads((run.out / 'models/mlp/model.json').read_text())['training_data']
    recorded = [bag['sha256'] for bag in training['bags']]
    assert len(set(recorded)) == len(bags)
    for bag, digest in zip(bags, recorded, strict=True):
        # The same bag bytes elsewhere, without the twin's files beside them: the same hash.
        copy = tmp_path / f'copy_of_{bag.name}'
        copy.mkdir()
        for file in bag.iterdir():
            if file.name == 'metadata.yaml' or file.suffix == '.mcap':
                shutil.copy2(file, copy / file.name)
        assert bag_sha256(copy) == digest
        # One flipped bit of the recording: another hash.
        (storage,) = copy.glob('*.mcap')
        data = bytearray(storage.read_bytes())
        data[len(data) // 2] ^= 0x01
        storage.write_bytes(bytes(data))
        assert bag_sha256(copy) != digest
    # The data hash is that of the preprocessed bags rebuilt from scratch, and changes with
    # any label or with the split.
    rebuilt = combine_datasets(load_datasets(bags, mabi, PreprocessConfig(), progress=False))
    assert data_sha256(rebuilt) == training['data_sha256']
    tau = rebuilt.tau.copy()
    tau[-1, 0] += 1e-9
    assert data_sha256(replace(rebuilt, tau=tau)) != training['data_sha256']
    assert data_sha256(replace(rebuilt, n_train=rebuilt.n_train - 1)) != training['data_sha256']


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


@pytest.mark.parametrize('rehash', [True, False])
def test_a_weights_file_with_nan_is_refused_naming_the_nan_with_or_without_a_new_hash(
    artifact_copy, mabi, rehash
):
    import hashlib
    import json

    from safetensors.numpy import load_file, save_file

    weights, meta = artifact_copy / 'weights.safetensors', artifact_copy / 'model.json'
    tensors = load_file(str(weights))
    name = sorted(tensors)[0]
    tensors[name] = tensors[name].copy()
    tensors[name].flat[2] = np.nan
    save_file(tensors, str(weights))
    if rehash:
        data = json.loads(meta.read_text())
        data['weights_sha256'] = hashlib.sha256(weights.read_bytes()).hexdigest()
        meta.write_text(json.dumps(data))
    with pytest.raises(CheckpointError, match=rf'tensor {name} holds 1 non-finite.*index 2'):
        load_model(artifact_copy, mabi)


@pytest.mark.parametrize(
    ('edit', 'message'),
    [
        (lambda d: {**d, 'format': 'something.else/1'}, 'format is not'),
        (lambda d: {**d, 'kind': 'rnea_lq'}, 'hyper-parameters do not fit rnea_lq'),
        (lambda d: {**d, 'tensors': {**d['tensors'], 'extra': [1]}}, 'differ from the metadata'),
        (lambda d: {**d, 'units': {**d['units'], 'tau': 'kN*m'}}, 'units'),
        (
            lambda d: {
                **d,
                'fitted': {
                    **d['fitted'],
                    'input_scaler': {
                        **d['fitted']['input_scaler'],
                        'low': [float('nan'), *d['fitted']['input_scaler']['low'][1:]],
                    },
                },
            },
            r'fitted\.input_scaler\.low\[0\] is nan',
        ),
    ],
    ids=['format', 'kind', 'tensor-list', 'units', 'nan-in-a-scaler'],
)
def test_a_model_json_that_is_not_what_it_claims_is_refused(artifact_copy, mabi, edit, message):
    # Re-hashed: a file a faulty writer made consistent is still refused, naming its fault.
    meta = artifact_copy / 'model.json'
    edited = edit(json.loads(meta.read_text()))
    meta.write_text(json.dumps({**edited, ARTIFACT_HASH: document_digest(edited)}))
    with pytest.raises(CheckpointError, match=message):
        load_model(artifact_copy, mabi)


@pytest.mark.parametrize(
    'edit',
    [
        lambda d: {**d, 'hyperparameters': {**d['hyperparameters'], 'width': 7}},
        lambda d: {
            **d,
            'fitted': {
                **d['fitted'],
                'input_scaler': {
                    **d['fitted']['input_scaler'],
                    'low': [-1e3, *d['fitted']['input_scaler']['low'][1:]],
                },
            },
        },
        lambda d: {**d, 'weights_sha256': '0' * 64},
    ],
    ids=['hyper-parameter', 'finite-scaler-value', 'weights-hash'],
)
def test_a_model_json_changed_after_writing_is_refused(artifact_copy, mabi, edit):
    meta = artifact_copy / 'model.json'
    meta.write_text(json.dumps(edit(json.loads(meta.read_text()))))
    changed = r'model\.json: its contents do not match its artifact_sha256|the hash in model\.json'
    with pytest.raises(CheckpointError, match=changed):
        load_model(artifact_copy, mabi)


def test_an_artifact_from_before_the_whole_artifact_hash_loads_with_a_warning(
    artifact_copy, mabi, caplog
):
    meta = artifact_copy / 'model.json'
    data = json.loads(meta.read_text())
    del data[ARTIFACT_HASH]
    meta.write_text(json.dumps(data))
    with caplog.at_level('WARNING'):
        model = load_model(artifact_copy, mabi)
    assert model.kind == data['kind']
    assert 'only the weights are verified' in caplog.text


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


def test_a_run_in_the_out_folder_is_kept_unless_force_is_given(bags, mabi, tmp_path):
    out = tmp_path / 'run'
    first = train_run(bags[:1], mabi, 'motor', ['rnea_lq'], out, progress=False)
    before = {p.name: p.read_bytes() for p in out.iterdir() if p.is_file()}
    with pytest.raises(ConfigError, match=r'holds a train run already.*--force'):
        train_run(bags[1:], mabi, 'motor', ['rnea_lq'], out, progress=False)
    assert {p.name: p.read_bytes() for p in out.iterdir() if p.is_file()} == before
    second = train_run(bags[1:], mabi, 'motor', ['rnea_lq'], out, progress=False, overwrite=True)
    assert second.metrics['bags'] != first.metrics['bags']


def test_unknown_kinds_and_hyper_parameters_are_refused_before_any_bag_is_read(mabi, tmp_path):
    missing = [tmp_path / 'no_such_bag']
    with pytest.raises(ConfigError, match='known kinds'):
        train_run(missing, mabi, 'motor', ['mlp', 'gpr'], tmp_path / 'r', progress=False)
    with pytest.raises(ConfigError, match='unknown hyper-parameter'):
        train_run(missing, mabi, 'motor', ['mlp'], tmp_path / 'r', hyper={'mlp': {'widht': 3}})
    with pytest.raises(ConfigError, match='not trained'):
        train_run(missing, mabi, 'motor', ['mlp'], tmp_path / 'r', hyper={'lnn': {}})


class ClockedModel:
    """A stand-in model whose predictions take set times on a fake perf_counter."""

    is_sequence_model = False

    def __init__(self, batched_s: list[float], one_sample_s: list[float]) -> None:
        self.now = 0.0
        self.batched_s = iter(batched_s)
        self.one_sample_s = iter(one_sample_s)
        self.one_sample_threads: set[int] = set()

    def perf_counter(self) -> float:
        return self.now

    def predict(self, q, v, a):
        if len(q) == 1:
            self.now += next(self.one_sample_s)
            self.one_sample_threads.add(torch.get_num_threads())
        else:
            self.now += next(self.batched_s)
        return np.zeros_like(q)


def test_inference_timing_reports_batched_and_one_sample_latency(monkeypatch):
    n, calls = 500, 20
    # A first call and the warm-up calls take a second each: none of them may count.
    warm_up = [1.0] * (1 + LATENCY_WARMUP)
    model = ClockedModel([3e-3, 2e-3, 2.5e-3], warm_up + [(k + 1) * 1e-5 for k in range(calls)])
    monkeypatch.setattr(measure, 'time', SimpleNamespace(perf_counter=model.perf_counter))
    q = np.zeros((n, 6))
    threads = torch.get_num_threads()
    timing = measure_inference(model, q, q, q, calls=calls, repeats=3, latency_threads=1)
    # The fastest batched call per sample; the median and 99th percentile (linear between the
    # 19th and 20th of the 20 sorted times) of the timed one-sample calls.
    assert timing['inference_seconds_per_sample'] == pytest.approx(2e-3 / n, rel=1e-9)
    assert timing['latency_single_sample_median_s'] == pytest.approx(10.5e-5, rel=1e-9)
    assert timing['latency_single_sample_p99_s'] == pytest.approx(19.81e-5, rel=1e-9)
    assert timing['latency_window_samples'] == 1
    assert next(model.one_sample_s, None) is None  # every one-sample call was made
    # The one-sample calls ran on one thread; the caller's thread count is back afterwards.
    assert timing['latency_threads'] == 1
    assert model.one_sample_threads == {1}
    assert timing['batched_threads'] == threads
    assert torch.get_num_threads() == threads


def test_inference_timing_without_repeats_has_no_batched_time(monkeypatch):
    model = ClockedModel([], [1.0] * (1 + LATENCY_WARMUP) + [4e-5, 2e-5, 3e-5])
    monkeypatch.setattr(measure, 'time', SimpleNamespace(perf_counter=model.perf_counter))
    q = np.zeros((50, 6))
    timing = measure_inference(model, q, q, q, calls=3, repeats=0)
    assert 'inference_seconds_per_sample' not in timing
    assert timing['latency_single_sample_median_s'] == pytest.approx(3e-5, rel=1e-9)


@pytest.fixture(scope='module')
def short_bag(tmp_path_factory):
    """26 s: long enough for RNEA+LQ, too short for a network's validation windows through the
    0.3 Hz label filter (a real failure of one kind in a run)."""
    config = twin_config(26.0, seed=13)
    return write_twin_output(simulate(config), config, tmp_path_factory.mktemp('short') / 'bag')


def test_a_model_that_fails_leaves_the_others_fitted_saved_scored_and_reported(
    short_bag, mabi, tmp_path
):
    from id_learning.cli.main import main

    out = tmp_path / 'run'
    stale = out / 'models' / 'mlp'  # what a replaced run left: must not pass for this one's
    stale.mkdir(parents=True)
    (stale / 'model.json').write_text('{}')
    (out / 'run.json').write_text('{}')
    run = train_run(
        [short_bag], mabi, 'motor', ['rnea_lq', 'mlp'], out, progress=False, overwrite=True
    )
    assert list(run.models) == ['rnea_lq']
    assert set(run.failures) == {'mlp'}
    assert 'validation part is too short' in run.failures['mlp']
    load_model(out / 'models' / 'rnea_lq', mabi)  # saved, and complete
    assert not (out / 'models' / 'mlp').exists()
    metrics = json.loads((out / 'metrics.json').read_text())
    assert set(metrics['models']) == {'rnea_lq'}
    assert 'too short' in metrics['failed']['mlp']
    assert '## Models that failed' in (out / 'report.md').read_text()
    run_json = json.loads((out / 'run.json').read_text())
    assert (run_json['kinds'], list(run_json['failed'])) == (['rnea_lq'], ['mlp'])
    assert run_json['requested_kinds'] == ['rnea_lq', 'mlp']
    # The run evaluates like any other; the command line says what failed and exits 1.
    assert main(['evaluate', '--run', str(out), '--bag', str(short_bag), '--out',
                 str(tmp_path / 'eval'), '--quiet']) == 0  # fmt: skip
    status = main(['train', '--bag', str(short_bag), '--models', 'rnea_lq,mlp', '--out',
                   str(tmp_path / 'cli_run'), '--quiet'])  # fmt: skip
    assert status == 1


def test_a_run_where_every_model_fails_is_an_error_naming_each(short_bag, mabi, tmp_path):
    from id_learning.errors import TrainingError

    with pytest.raises(TrainingError, match=r'mlp: DatasetError.*lstm: DatasetError'):
        train_run([short_bag], mabi, 'motor', ['mlp', 'lstm'], tmp_path / 'run', progress=False)


def test_a_shuffled_run_scores_its_drawn_test_samples_and_evaluate_gives_them_back(
    bags, mabi, tmp_path, monkeypatch
):
    from id_learning.evaluation.scoring import test_index

    out = tmp_path / 'run'
    config = PreprocessConfig(split='shuffled', split_seed=4)
    run = train_run(bags, mabi, 'motor', ['rnea_lq', 'mlp'], out, hyper=FAST_HYPER,
                    progress=False, device='cpu', preprocess=config)  # fmt: skip
    dataset = run.dataset
    assert dataset.is_shuffled
    # Two whole recordings in time, each with its own drawn training samples.
    assert [len(rows) for rows in dataset.recording_rows()] == [
        len(load_recording(b, mabi).stamps_ns) for b in bags
    ]
    n = len(dataset.tau)
    assert abs(len(test_index(dataset)) - 0.3 * n) <= 2
    assert run.metrics['n_samples'] == len(test_index(dataset))
    stored = json.loads((out / 'run.json').read_text())['preprocessing']
    assert (stored['split'], stored['split_seed']) == ('shuffled', 4)
    # evaluate rebuilds the split from the run and scores the same samples the same way.
    evaluated = evaluate_run(out, bags, mabi, tmp_path / 'eval', progress=False)
    for kind in ('rnea_lq', 'mlp'):
        np.testing.assert_allclose(
            evaluated.metrics['models'][kind]['rmse_through_filter_nm'],
            run.metrics['models'][kind]['rmse_through_filter_nm'],
            rtol=1e-9,
        )
    # A split that cannot be rebuilt exactly (another random stream: the masks drawn now hash
    # otherwise) is refused, not scored on mixed samples.
    from id_learning.training import trainer

    with monkeypatch.context() as patch:
        patch.setattr(trainer, 'mask_sha256', lambda mask: '0' * 64)
        with pytest.raises(CheckpointError, match='shuffled split could not be rebuilt'):
            evaluate_run(out, bags, mabi, tmp_path / 'eval2', progress=False)
    # A mask hash edited into run.json is refused before: run.json no longer says what the
    # models' model.json (hash-checked) say of the data.
    document = json.loads((out / 'run.json').read_text())
    document['training_data']['bags'][0]['train_mask_sha256'] = '0' * 64
    (out / 'run.json').write_text(json.dumps(document))
    with pytest.raises(
        CheckpointError, match=r'run\.json: training_data\.bags\[0\]\.train_mask_sha256 is "0000'
    ):
        evaluate_run(out, bags, mabi, tmp_path / 'eval3', progress=False)


def test_kinds_are_fitted_cheapest_first_and_reported_in_the_order_given():
    from id_learning.training.fitting import fit_order

    assert fit_order(['lnn', 'mlp', 'rnea_effects', 'rnea_id', 'rnea_lq', 'custom']) == [
        'rnea_lq',
        'rnea_id',
        'rnea_effects',
        'mlp',
        'lnn',
        'custom',
    ]


def test_every_fit_keeps_the_budget_and_a_fit_cut_short_says_so(bags, mabi, tmp_path):
    """The identification is bounded by --max-seconds-per-model like the networks: past it no
    claim is judged, the final fit is linearised once, and the run's report names both."""
    lines: list[str] = []
    out = tmp_path / 'run'
    run = train_run(
        bags[:1], mabi, 'motor', ['mlp', 'rnea_id'], out, hyper=FAST_HYPER, progress=False,
        device='cpu', max_seconds_per_model=0.01, announce=lines.append,
    )  # fmt: skip
    assert list(run.models) == ['mlp', 'rnea_id']
    assert [line.split(':')[0] for line in lines] == ['rnea_id', 'mlp']
    cut = json.loads((out / 'metrics.json').read_text())['cut_short']
    assert 'the final fit (linearised once)' in cut['rnea_id']
    assert any('held-out judging' in step for step in cut['rnea_id'])
    assert 'cut short by its budget' in lines[0]
    assert '## Fits cut short by their time budget' in (out / 'report.md').read_text()
    physics = run.models['rnea_id'].model.physics_.report
    assert physics['balancers'] == []
    assert physics['confirmation']['claims'] == []
