"""delan_id and lnn_mlp_id: Lagrangian networks initialised from the identified physics."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from hypothesis import given
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays
from support import quick_preprocess, twin_config

from id_learning.dataset.preprocess import prepare_dataset
from id_learning.errors import CheckpointError, ConfigError
from id_learning.models.data import TrainingData
from id_learning.models.delan_residual import FACTOR_GAIN
from id_learning.models.lagrangian_base import LagrangianScaling
from id_learning.models.registry import load_model, make_model, save_model
from id_learning.physics.identified import IdentifiedPhysics
from id_learning.twin import simulate

KINDS = ('delan_id', 'lnn_mlp_id')
#: A quick identification (one linearisation, no held-out confirmation) with the balancer named.
IDENTIFICATION = {'balancer': 'joint_2', 'iterations': 1, 'confirm': False}
#: A few epochs of narrow networks on a sparse subsample.
QUICK = {'max_epochs': 5, 'device': 'cpu', 'width': 16, 'stride': 8, 'windows_per_batch': 1}


@pytest.fixture(scope='module')
def data(mabi) -> TrainingData:
    """A 50 s default twin run (every hidden effect, motor-torque labels), as training data."""
    result = simulate(twin_config(60.0, seed=9))
    return TrainingData(prepare_dataset(result.recording, mabi, quick_preprocess()), mabi)


@pytest.fixture(scope='module')
def rnea_id(data):
    return make_model('rnea_id', data.robot, **IDENTIFICATION).fit(data)


def initialised(kind: str, data: TrainingData):
    """The model as ``fit`` builds it before the first training step."""
    model = make_model(kind, data.robot, **IDENTIFICATION, **QUICK)
    _, _, residual_range = model.training_target(data)  # identifies (shared with rnea_id)
    scaling = LagrangianScaling.from_dataset(
        data.dataset, balance=model.config.energy_balance, torque=residual_range
    )
    model.network_ = model.make_network(scaling, torch.Generator().manual_seed(0)).eval()
    model.scaling_ = scaling
    return model


@pytest.fixture(scope='module')
def initial(data, rnea_id):
    return {kind: initialised(kind, data) for kind in KINDS}


@pytest.fixture(scope='module')
def fitted(data, rnea_id):
    threads = torch.get_num_threads()
    torch.set_num_threads(1)  # narrow networks: more threads only contend on a busy machine
    models = {kind: make_model(kind, data.robot, **IDENTIFICATION, **QUICK) for kind in KINDS}
    for model in models.values():
        model.fit(data)
    torch.set_num_threads(threads)
    return models


def random_states(data: TrainingData, count: int = 25, seed: int = 0):
    """q, v, a (count, n) drawn up to 1.5 times the training part's half range from its centre."""
    rng = np.random.default_rng(seed)
    out = []
    for x in (data.dataset.q, data.dataset.v, data.dataset.a):
        centre, half = 0.5 * (x.max(0) + x.min(0)), 0.5 * (x.max(0) - x.min(0))
        out.append(centre + 1.5 * half * rng.uniform(-1.0, 1.0, (count, x.shape[1])))
    return tuple(out)


def mass_matrix_from_torques(physics: IdentifiedPhysics, q: np.ndarray) -> np.ndarray:
    """The identified link-side M(q) from the identified torque at rest, a column per unit a.

    At v = 0 friction (odd in v) and the delay's rate term vanish, so
    tau(q, 0, e_k) - tau(q, 0, 0) = (1 + g) * M(q) e_k.
    """
    batch, n = q.shape
    rest = np.zeros((batch, n))
    columns = [
        physics.torque(q, rest, np.tile(np.eye(n)[k], (batch, 1))) - physics.torque(q, rest, rest)
        for k in range(n)
    ]
    return np.stack(columns, axis=2) / (1.0 + physics.gain)[None, :, None]


@pytest.mark.parametrize('kind', KINDS)
def test_before_training_the_models_are_rnea_id(kind, initial, rnea_id, data):
    model = initial[kind]
    assert model.identified_physics() is rnea_id.physics_  # one identification, shared
    q, v, a = random_states(data)
    expected = rnea_id.predict(q, v, a)
    scale = data.dataset.target_scaler.scale()
    # float32 resolution of the torque scale; the networks' outputs start at (near) zero.
    np.testing.assert_allclose(model.predict(q, v, a), expected, rtol=0, atol=1e-6 * scale.max())
    one = model.sample_predictor()
    single = np.vstack([one(q[k], v[k], a[k]) for k in range(len(q))])
    np.testing.assert_allclose(single, expected, rtol=0, atol=1e-6 * scale.max())
    expected_mass = mass_matrix_from_torques(rnea_id.physics_, q)
    mass = model.mass_matrix(q) if kind == 'delan_id' else model.mass_matrix(q, v)
    np.testing.assert_allclose(mass, expected_mass, rtol=1e-6, atol=1e-9 * np.abs(mass).max())


def test_delan_ids_residual_starts_near_zero_but_not_at_its_saddle(initial, rnea_id, data):
    """L L^T has no gradient at L = 0: the factor starts small, not zero."""
    model = initial['delan_id']
    q, _, _ = random_states(data)
    residual = model.mass_matrix(q) - mass_matrix_from_torques(rnea_id.physics_, q)
    largest = np.abs(residual).max()
    assert 0 < largest < 1e-6 * np.abs(model.mass_matrix(q)).max()


@given(q=arrays(np.float64, 6, elements=st.floats(-2 * np.pi, 2 * np.pi)))
def test_delan_ids_mass_matrix_is_the_identified_one_plus_a_positive_semidefinite_one(
    q, grown_delan_id
):
    model, physics = grown_delan_id
    mass = model.mass_matrix(q[None])[0]
    identified = mass_matrix_from_torques(physics, q[None])[0]
    residual = mass - identified
    np.testing.assert_allclose(mass, mass.T, rtol=1e-6, atol=1e-9 * np.abs(mass).max())
    assert np.linalg.eigvalsh(0.5 * (mass + mass.T)).min() > 0
    assert np.linalg.eigvalsh(0.5 * (residual + residual.T)).min() > -1e-6 * np.abs(mass).max()


@pytest.fixture(scope='module')
def grown_delan_id(data, rnea_id):
    """delan_id with its factor at DeLaN's usual initial scale: a residual as large as M_id."""
    model = initialised('delan_id', data)
    with torch.no_grad():
        model.network_.cholesky_net.linears()[-1].weight.div_(FACTOR_GAIN)
    q, _, _ = random_states(data)
    identified = mass_matrix_from_torques(rnea_id.physics_, q)
    residual = model.mass_matrix(q) - identified
    # Not vacuous: the residual is of the order of the identified inertia.
    assert np.abs(residual).max() > 0.1 * np.abs(identified).max()
    return model, rnea_id.physics_


def training_mse(model, data: TrainingData) -> float:
    """Mean squared error on the training part, normalised, through the label filter."""
    ds = data.dataset
    torque = ds.filter_like_labels(model.predict(ds.q, ds.v, ds.a))
    error = (torque - ds.tau)[data.train_rows] / ds.target_scaler.scale()
    return float(np.mean(error**2))


@pytest.mark.parametrize('kind', KINDS)
def test_a_few_epochs_learn_part_of_what_rnea_id_leaves(kind, fitted, rnea_id, data):
    assert fitted[kind].history_.to_dict()['best_epoch'] >= 1  # a step was taken and kept
    assert training_mse(fitted[kind], data) < 0.8 * training_mse(rnea_id, data)


@pytest.mark.parametrize('kind', KINDS)
def test_the_models_save_load_and_predict_the_same_one_sample_at_a_time(
    kind, fitted, data, tmp_path, robot_configs
):
    model = fitted[kind]
    save_model(model, tmp_path / kind)
    loaded = load_model(tmp_path / kind, data.robot, kind)
    q, v, a = random_states(data, seed=1)
    np.testing.assert_array_equal(loaded.predict(q, v, a), model.predict(q, v, a))
    np.testing.assert_array_equal(loaded.identified_physics().theta, model.physics_.theta)
    one = loaded.sample_predictor()
    single = np.vstack([one(q[k], v[k], a[k]) for k in range(len(q))])
    # float64 numpy against the float32 networks, on the normalised scale.
    scale = data.dataset.target_scaler.scale()
    expected = model.predict(q, v, a) / scale
    np.testing.assert_allclose(single / scale, expected, rtol=0, atol=1e-6)
    parts = loaded.components(q, v, a)
    np.testing.assert_allclose(sum(parts.parts().values()), parts.total, rtol=1e-9, atol=1e-6)
    np.testing.assert_allclose(parts.total / scale, expected, rtol=0, atol=1e-6)
    with pytest.raises(CheckpointError, match='do not match robot ur5'):
        load_model(tmp_path / kind, robot_configs['ur5'])


def test_delan_id_refuses_the_positive_diagonals_settings_and_names_bad_keys(mabi):
    with pytest.raises(ConfigError, match='diagonal_shift'):
        make_model('delan_id', mabi, diagonal_shift=1.0)
    with pytest.raises(ConfigError, match='mass_rel_std'):
        make_model('lnn_mlp_id', mabi, mass_rel_std=0.0)
    with pytest.raises(ConfigError, match='dissipation_width'):
        make_model('lnn_mlp_id', mabi, dissipation_width=0)
