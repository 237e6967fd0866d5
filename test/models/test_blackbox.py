"""The MLP and LSTM baselines: shapes, learning, windows, determinism and exact save/load."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import torch
from safetensors.numpy import load_file, save_file
from support import quick_preprocess

from id_learning.dataset import prepare_dataset
from id_learning.errors import CheckpointError, ConfigError
from id_learning.models.blackbox import LstmConfig, LstmModel, MlpConfig, MlpModel
from id_learning.models.data import TrainingData

# Short fits on the 26 s twin run: a few seconds each on one core.
SHORT_MLP = {'max_epochs': 40, 'stride': 4, 'batch_size': 64, 'learning_rate': 3e-3}
SHORT_LSTM = {
    'max_epochs': 30,
    'stride': 8,
    'batch_size': 32,
    'hidden_size': 32,
    'learning_rate': 3e-3,
}
SHORT_MLP['device'] = SHORT_LSTM['device'] = 'cpu'


@pytest.fixture(scope='module', autouse=True)
def one_torch_thread():
    """Small networks gain nothing from intra-op threads and stall on a loaded machine.

    Module scope, so that it is in force before the module's fitted-model fixtures run.
    """
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(threads)


@pytest.fixture(scope='module')
def data(short_twin) -> TrainingData:
    config, result = short_twin
    dataset = prepare_dataset(result.recording, config.robot, quick_preprocess())
    return TrainingData(dataset, config.robot)


@pytest.fixture(scope='module')
def mlp(data) -> MlpModel:
    return MlpModel(MlpConfig(**SHORT_MLP), data.robot).fit(data)


@pytest.fixture(scope='module')
def lstm(data) -> LstmModel:
    return LstmModel(LstmConfig(**SHORT_LSTM), data.robot).fit(data)


def zero_predictor_loss(data: TrainingData) -> float:
    """Validation loss of predicting each joint's training mid-range (0 on the [-1, 1] scale)."""
    ds, rows = data.dataset, data.validation_rows
    return float(np.mean(ds.target_scaler.transform(ds.tau[rows]) ** 2))


def round_trip(model, tmp_path: Path):
    """Save state and metadata as the artifact does (safetensors + JSON), load into a new model."""
    save_file(model.state(), str(tmp_path / 'weights.safetensors'))
    fitted = json.loads(json.dumps(model.fitted_metadata()))
    loaded = type(model)(model.config, model.robot)
    loaded.load_state(load_file(str(tmp_path / 'weights.safetensors')), fitted)
    return loaded


def normalised_validation_loss(model, data: TrainingData) -> float:
    ds, rows = data.dataset, data.validation_rows
    error = model.predict(ds.q[rows], ds.v[rows], ds.a[rows]) - ds.tau[rows]
    return float(np.mean((error / ds.target_scaler.scale()) ** 2))


# -- MLP -----------------------------------------------------------------------------------------
def test_mlp_predicts_one_torque_row_per_sample(mlp, data):
    test = data.dataset.test
    assert mlp.predict(test.q, test.v, test.a).shape == test.tau.shape
    assert mlp.predict(test.q[:1], test.v[:1], test.a[:1]).shape == (1, 6)
    assert mlp.predict(test.q[0], test.v[0], test.a[0]).shape == (1, 6)


def test_a_short_mlp_fit_beats_the_zero_predictor_on_validation(mlp, data):
    baseline = zero_predictor_loss(data)
    assert mlp.history_ is not None
    assert len(mlp.history_.validation_loss) >= 5
    assert mlp.history_.best_validation_loss < 0.5 * baseline
    # The history's loss is the study's normalised MSE of the physical prediction.
    np.testing.assert_allclose(
        normalised_validation_loss(mlp, data), mlp.history_.best_validation_loss, rtol=0.25
    )


def test_mlp_save_then_load_predicts_identically(mlp, data, tmp_path):
    loaded = round_trip(mlp, tmp_path)
    test = data.dataset.test
    assert sorted(mlp.state()) == sorted(
        f'net.{i}.{p}' for i in (0, 2, 4) for p in ('weight', 'bias')
    )
    assert all(value.dtype == np.float32 for value in mlp.state().values())
    np.testing.assert_array_equal(
        loaded.predict(test.q, test.v, test.a), mlp.predict(test.q, test.v, test.a)
    )


def test_mlp_fit_is_deterministic_for_a_seed_and_leaves_torch_rng_alone(data):
    config = MlpConfig(**{**SHORT_MLP, 'max_epochs': 3})
    before = torch.random.get_rng_state()
    first = MlpModel(config, data.robot).fit(data).state()
    second = MlpModel(config, data.robot).fit(data).state()
    other = MlpModel(MlpConfig(**{**SHORT_MLP, 'max_epochs': 3, 'seed': 1}), data.robot)
    third = other.fit(data).state()
    assert torch.equal(torch.random.get_rng_state(), before)
    for name, value in first.items():
        np.testing.assert_array_equal(second[name], value)
    assert not np.array_equal(third['net.0.weight'], first['net.0.weight'])


def test_mlp_separates_no_torque_components(mlp, data):
    test = data.dataset.test
    parts = mlp.components(test.q[:4], test.v[:4], test.a[:4])
    assert parts.parts() == {}
    np.testing.assert_array_equal(parts.total, mlp.predict(test.q[:4], test.v[:4], test.a[:4]))


def test_mlp_refuses_tensors_of_another_depth(mlp):
    deeper = MlpModel(MlpConfig(depth=3), mlp.robot)
    with pytest.raises(CheckpointError, match='do not match'):
        deeper.load_state(mlp.state(), mlp.fitted_metadata())


def test_mlp_refuses_metadata_without_scalers(mlp):
    with pytest.raises(CheckpointError, match='target_scaler'):
        MlpModel(mlp.config, mlp.robot).load_state(mlp.state(), {'input_scaler': {}})


@pytest.mark.parametrize(
    ('overrides', 'key'),
    [
        ({'stride': 0}, 'stride'),
        ({'device': 'tpu'}, 'device'),
        ({'activation': 'sigmoid'}, 'activation'),
        ({'width': 0}, 'width'),
        ({'max_seconds': -1.0}, 'max_seconds'),
        ({'learning_rate': 0.0}, 'learning_rate'),
    ],
)
def test_mlp_config_rejects_bad_values_naming_the_key(overrides, key):
    with pytest.raises(ConfigError, match=key):
        MlpConfig(**overrides)


def test_networks_refuse_to_predict_before_fitting(mabi):
    zeros = np.zeros((1, 6))
    with pytest.raises(RuntimeError, match='not fitted'):
        MlpModel(MlpConfig(), mabi).predict(zeros, zeros, zeros)
    with pytest.raises(RuntimeError, match='not fitted'):
        LstmModel(LstmConfig(), mabi).predict_window(np.zeros((20, 18)))


# -- LSTM ----------------------------------------------------------------------------------------
def test_lstm_predicts_one_torque_row_per_sample_of_a_run(lstm, data):
    test = data.dataset.test
    assert LstmModel.is_sequence_model
    assert lstm.predict(test.q, test.v, test.a).shape == test.tau.shape
    assert lstm.predict(test.q[:1], test.v[:1], test.a[:1]).shape == (1, 6)
    assert lstm.predict_window(np.zeros((20, 18))).shape == (6,)
    assert lstm.predict_windows(np.zeros((3, 20, 18))).shape == (3, 6)


def test_a_short_lstm_fit_beats_the_zero_predictor_on_validation(lstm, data):
    baseline = zero_predictor_loss(data)
    assert lstm.history_ is not None
    assert len(lstm.history_.validation_loss) >= 10
    # The validation tail lies beyond the 20 s of training motion: a clear gain is enough here.
    assert lstm.history_.best_validation_loss < 0.8 * baseline
    assert lstm.history_.best_validation_loss < lstm.history_.validation_loss[0]


def test_lstm_predict_over_a_run_equals_predict_window_on_each_window(lstm, data):
    test = data.dataset.test
    run = slice(100, 140)
    q, v, a = test.q[run], test.v[run], test.a[run]
    inputs = np.hstack([q, v, a])
    padded = np.vstack([np.repeat(inputs[:1], 19, axis=0), inputs])

    along_run = lstm.predict(q, v, a)

    one_by_one = np.array([lstm.predict_window(padded[k : k + 20]) for k in range(len(inputs))])
    scale = data.dataset.target_scaler.scale()
    np.testing.assert_allclose(along_run, one_by_one, rtol=0, atol=1e-5 * scale.max())
    # The padding matters: the first window differs from the same sample with real history.
    with_history = lstm.predict_window(np.hstack([test.q, test.v, test.a])[81:101])
    assert not np.allclose(with_history, along_run[0], rtol=0, atol=1e-6 * scale.max())


def test_lstm_rejects_a_window_of_the_wrong_length(lstm):
    with pytest.raises(ValueError, match=r'\(20, 18\)'):
        lstm.predict_window(np.zeros((19, 18)))


def test_lstm_save_then_load_predicts_identically(lstm, data, tmp_path):
    loaded = round_trip(lstm, tmp_path)
    test = data.dataset.test
    assert 'lstm.weight_ih_l1' in lstm.state()
    np.testing.assert_array_equal(
        loaded.predict(test.q, test.v, test.a), lstm.predict(test.q, test.v, test.a)
    )
    window = np.hstack([test.q, test.v, test.a])[:20]
    np.testing.assert_array_equal(loaded.predict_window(window), lstm.predict_window(window))
