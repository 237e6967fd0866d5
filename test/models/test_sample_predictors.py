"""The float64 numpy paths of every model kind equal its torch networks run in float64."""

from __future__ import annotations

import copy

import numpy as np
import pytest
import torch
from support import quick_preprocess, sine_recording

from id_learning.dataset import prepare_dataset
from id_learning.models.data import TrainingData
from id_learning.models.registry import STUDY_MODELS, make_model
from id_learning.models.torch_utils import NumpyMlp, make_mlp

#: Two hidden layers (or two LSTM layers) so that every loop of the numpy paths runs.
QUICK = {'max_epochs': 1, 'device': 'cpu', 'stride': 16}
VARIANTS: dict[str, tuple[str, dict[str, object]]] = {
    'rnea_lq': ('rnea_lq', {}),
    'rnea_lq_coulomb': ('rnea_lq', {'friction': 'viscous_coulomb_offset'}),
    'rnea_mlp': ('rnea_mlp', {**QUICK, 'width': 16, 'depth': 2}),
    'delan': ('delan', {**QUICK, 'width': 16, 'depth': 2}),
    'delan_softplus': ('delan', {**QUICK, 'width': 16, 'depth': 3, 'activation': 'softplus'}),
    'lnn': ('lnn', {**QUICK, 'width': 16, 'depth': 2}),
    'lnn_softplus': ('lnn', {**QUICK, 'width': 16, 'depth': 3, 'activation': 'softplus'}),
    'lnn_mlp': ('lnn_mlp', {**QUICK, 'width': 16, 'depth': 2, 'dissipation_depth': 2}),
    'mlp': ('mlp', {**QUICK, 'width': 16, 'depth': 2}),
    'mlp_relu': ('mlp', {**QUICK, 'width': 16, 'depth': 3, 'activation': 'relu'}),
    'lstm': (
        'lstm',
        {**QUICK, 'hidden_size': 16, 'num_layers': 2, 'sequence_length': 7, 'stride': 32},
    ),
    'rnea_id': ('rnea_id', {'balancer': 'joint_2', 'iterations': 1}),
}
ONE_SAMPLE = [name for name, (kind, _) in VARIANTS.items() if kind != 'lstm']
RTOL = 1e-9


@pytest.fixture(scope='module')
def data(mabi) -> TrainingData:
    return TrainingData(prepare_dataset(sine_recording(1250), mabi, quick_preprocess()), mabi)


@pytest.fixture(scope='module')
def models(data):
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        return {
            name: make_model(kind, data.robot, **hyper).fit(data)
            for name, (kind, hyper) in VARIANTS.items()
        }
    finally:
        torch.set_num_threads(threads)


def states(data: TrainingData, count: int = 40, seed: int = 0):
    """Samples of the training run, and random ones up to twice its range (softplus tails)."""
    ds = data.dataset
    rng = np.random.default_rng(seed)
    rows = np.linspace(0, len(ds.q) - 1, count // 2).astype(int)
    q, v, a = ds.q[rows], ds.v[rows], ds.a[rows]

    def wide(x: np.ndarray) -> np.ndarray:
        centre, half = 0.5 * (x.max(0) + x.min(0)), 0.5 * (x.max(0) - x.min(0))
        return centre + 2 * half * rng.uniform(-1, 1, (count - len(rows), x.shape[1]))

    return (np.vstack([q, wide(ds.q)]), np.vstack([v, wide(ds.v)]), np.vstack([a, wide(ds.a)]))


def float64_reference(model, q: np.ndarray, v: np.ndarray, a: np.ndarray) -> np.ndarray:
    """The model's torque with its torch network copied to float64 (float64 models as they are)."""
    if model.kind in ('rnea_lq', 'rnea_id'):
        return model.predict(q, v, a)
    network = copy.deepcopy(model.network_).double()
    with torch.inference_mode():
        if model.kind == 'mlp':
            return network(torch.from_numpy(np.hstack([q, v, a]))).numpy()
        if model.kind == 'rnea_mlp':
            h = network(torch.from_numpy(np.hstack([q, v]))).numpy()
            return model.physics_torque(q, v, a) + h
        tensors = [torch.from_numpy(np.ascontiguousarray(x)) for x in (q, v, a)]
        return network(*tensors).numpy()


def lstm_float64_run(model, q: np.ndarray, v: np.ndarray, a: np.ndarray) -> np.ndarray:
    """LstmModel.predict of a run (padded windows), with the network in float64."""
    inputs = np.hstack([q, v, a])
    length = model.sequence_length
    padded = np.vstack([np.repeat(inputs[:1], length - 1, axis=0), inputs])
    windows = np.stack([padded[k : k + length] for k in range(len(inputs))])
    network = copy.deepcopy(model.network_).double()
    with torch.inference_mode():
        return network(torch.from_numpy(windows)).numpy()


def assert_close(actual: np.ndarray, expected: np.ndarray, rtol: float) -> None:
    assert np.abs(expected).max() > 1e-3  # not a vacuous comparison of zeros
    np.testing.assert_allclose(actual, expected, rtol=rtol, atol=rtol * np.abs(expected).max())


@pytest.mark.parametrize('name', ONE_SAMPLE)
def test_sample_predictor_equals_the_float64_torch_network(models, data, name):
    model = models[name]
    q, v, a = states(data)
    predict_one = model.sample_predictor()
    fast = np.array([predict_one(q[k], v[k], a[k]) for k in range(len(q))])
    assert fast.shape == q.shape
    assert_close(fast, float64_reference(model, q, v, a), RTOL)


@pytest.mark.parametrize('name', ONE_SAMPLE)
def test_sample_predictor_equals_predict_up_to_float32_rounding(models, data, name):
    model = models[name]
    q, v, a = states(data, seed=1)
    predict_one = model.sample_predictor()
    fast = np.array([predict_one(q[k], v[k], a[k]) for k in range(len(q))])
    assert_close(fast, model.predict(q, v, a), 1e-5)


def test_lstm_streams_equal_the_float64_network_over_runs_with_a_reset(models, data):
    model = models['lstm']
    ds = data.dataset
    runs = [slice(100, 130), slice(400, 403), slice(600, 640)]  # one shorter than a window
    exact, online = model.sequence_predictor(np.float64), model.sequence_predictor()
    for rows in runs:
        exact.reset()
        online.reset()
        q, v, a = ds.q[rows], ds.v[rows], ds.a[rows]
        inputs = [np.concatenate(x) for x in zip(q, v, a, strict=True)]
        in_float64 = np.array([exact.push(x) for x in inputs])
        assert_close(in_float64, lstm_float64_run(model, q, v, a), RTOL)
        # the default float32 streams: the network's own precision, as predict() runs it; the
        # recurrent products done ahead after each output (as the predictor node does) change
        # nothing
        pushed = []
        for x in inputs:
            pushed.append(online.push(x))
            online.prepare()
        assert_close(np.array(pushed), model.predict(q, v, a), 1e-5)


def test_numpy_mlp_refuses_a_network_that_is_not_a_plain_mlp():
    net = make_mlp(3, 2, 4, 2)
    with pytest.raises(ValueError, match='not a make_mlp network'):
        NumpyMlp.from_sequential(torch.nn.Sequential(*net, torch.nn.Tanh()))


def test_every_study_model_and_the_identified_physics_are_covered():
    assert {kind for kind, _ in VARIANTS.values()} == {*STUDY_MODELS, 'rnea_id'}
