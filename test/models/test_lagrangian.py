"""DeLaN, LNN and LNN+MLP: Euler-Lagrange torque against independent references; the models."""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest
import torch
from support import quick_preprocess
from torch.func import grad, hessian, jacfwd, jacrev, vmap

from id_learning.errors import CheckpointError, ConfigError
from id_learning.models.artifact import read_artifact, write_artifact
from id_learning.models.delan import DelanNetwork, euler_lagrange_torque
from id_learning.models.lagrangian import (
    DelanConfig,
    DelanModel,
    LnnConfig,
    LnnMlpConfig,
    LnnMlpModel,
    LnnModel,
)
from id_learning.models.lagrangian_base import LagrangianScaling
from id_learning.models.lnn import LnnMlpNetwork, LnnNetwork

N_DOF = 3
MODELS = {
    'delan': (DelanConfig, DelanModel),
    'lnn': (LnnConfig, LnnModel),
    'lnn_mlp': (LnnMlpConfig, LnnMlpModel),
}
#: Few epochs on a sparse subsample: enough to see learning, fast enough for the suite.
QUICK = {
    'max_epochs': 6,
    'stride': 4,
    'batch_size': 64,
    'windows_per_batch': 1,
    'learning_rate': 3e-3,
    'device': 'cpu',
}


@pytest.fixture(autouse=True, scope='module')
def one_thread():
    """These networks are small: one thread is fastest, more only contend on a busy machine."""
    previous = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(previous)


@pytest.fixture
def float64():
    previous = torch.get_default_dtype()
    torch.set_default_dtype(torch.float64)
    yield
    torch.set_default_dtype(previous)


def random_scaling(seed: int = 0, balance: float = 0.0) -> LagrangianScaling:
    rng = np.random.default_rng(seed)
    q = rng.uniform(-2.0, 2.0, (200, N_DOF)) + np.array([0.3, -0.5, 1.0])
    v = rng.uniform(-1.5, 1.5, (200, N_DOF)) * np.array([1.0, 0.5, 2.0])
    tau = rng.normal(0.0, 1.0, (200, N_DOF)) * np.array([50.0, 20.0, 3.0])
    return LagrangianScaling.from_data(q, v, tau, balance=balance)


def random_state(seed: int, batch: int = 7) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    generator = torch.Generator().manual_seed(seed)
    q, v, a = (torch.randn(batch, N_DOF, generator=generator) for _ in range(3))
    return q, 2.0 * v, 3.0 * a


def generator(seed: int) -> torch.Generator:
    return torch.Generator().manual_seed(seed)


# --------------------------------------------------------------------------------------------
# Euler-Lagrange torque from a Cholesky factor


def two_link_arm_mass_matrix(q: torch.Tensor) -> torch.Tensor:
    """Planar two-link arm (Spong, Robot Modeling and Control, 7.4): M(q) (2, 2)."""
    alpha, beta, delta = 3.2, 0.45, 0.8
    c2 = torch.cos(q[1])
    return torch.stack(
        [
            torch.stack([alpha + 2 * beta * c2, delta + beta * c2]),
            torch.stack([delta + beta * c2, torch.as_tensor(delta, dtype=q.dtype)]),
        ]
    )


def test_euler_lagrange_torque_of_a_two_link_arm_matches_the_closed_form(float64) -> None:
    # Known mass matrix: M = [[a + 2b cos q2, d + b cos q2], [d + b cos q2, d]]; its
    # Coriolis/centrifugal torque is c = b sin q2 [-(2 v1 v2 + v2^2), v1^2].
    beta = 0.45

    def cholesky(q: torch.Tensor) -> torch.Tensor:
        return torch.linalg.cholesky(two_link_arm_mass_matrix(q))

    q, v, a = (x[:, :2] for x in random_state(seed=1, batch=11))
    factor = vmap(cholesky)(q)
    derivative = vmap(jacfwd(cholesky))(q).permute(0, 3, 1, 2)  # (B, k, i, j) = dL_ij / dq_k
    inertial, coriolis = euler_lagrange_torque(factor, derivative, v, a)

    mass = vmap(two_link_arm_mass_matrix)(q)
    s2 = torch.sin(q[:, 1])
    expected_coriolis = (
        beta
        * s2[:, None]
        * torch.stack([-(2 * v[:, 0] * v[:, 1] + v[:, 1] ** 2), v[:, 0] ** 2], dim=1)
    )
    assert expected_coriolis.abs().max() > 0.1
    torch.testing.assert_close(inertial, torch.einsum('bij,bj->bi', mass, a), rtol=0, atol=1e-12)
    torch.testing.assert_close(coriolis, expected_coriolis, rtol=0, atol=1e-12)


# --------------------------------------------------------------------------------------------
# Networks against autograd on the same functions


@pytest.mark.parametrize('balance', [0.0, 1.0])
def test_delan_torque_matches_autograd_euler_lagrange_of_its_mass_matrix_and_potential(
    float64, balance: float
) -> None:
    network = DelanNetwork(random_scaling(balance=balance), generator=generator(2))
    q, v, a = random_state(seed=3)

    def mass(row: torch.Tensor) -> torch.Tensor:
        return network.mass_matrix(row.unsqueeze(0))[0]

    def potential(row: torch.Tensor) -> torch.Tensor:
        return network.potential(row.unsqueeze(0))[0]

    def reference(q1: torch.Tensor, v1: torch.Tensor, a1: torch.Tensor) -> torch.Tensor:
        dmass = jacrev(mass)(q1)  # (i, j, k) = dM_ij / dq_k
        mass_dot = torch.einsum('ijk,k->ij', dmass, v1)
        kinetic_gradient = 0.5 * torch.einsum('i,ijk,j->k', v1, dmass, v1)
        return mass(q1) @ a1 + mass_dot @ v1 - kinetic_gradient + grad(potential)(q1)

    expected = vmap(reference)(q, v, a)
    parts = network.components(q, v, a)
    assert expected.abs().max() > 1.0
    torch.testing.assert_close(network(q, v, a), expected, rtol=0, atol=1e-10)
    torch.testing.assert_close(parts['gravity'], vmap(grad(potential))(q), rtol=0, atol=1e-10)
    torch.testing.assert_close(
        parts['inertial'], torch.einsum('bij,bj->bi', vmap(mass)(q), a), rtol=0, atol=1e-10
    )


def test_delan_cholesky_derivative_matches_finite_differences(float64) -> None:
    network = DelanNetwork(random_scaling(), generator=generator(4))
    q, _, _ = random_state(seed=5)
    _, derivative = network.cholesky(q)
    step = 1e-6
    for k in range(N_DOF):
        shift = torch.zeros(N_DOF)
        shift[k] = step
        difference = (network.cholesky(q + shift)[0] - network.cholesky(q - shift)[0]) / (2 * step)
        torch.testing.assert_close(derivative[:, k], difference, rtol=0, atol=1e-7)


def test_delan_mass_matrix_is_symmetric_positive_definite_far_outside_the_data(float64) -> None:
    network = DelanNetwork(random_scaling(), generator=generator(6))
    q = 20.0 * random_state(seed=7, batch=50)[0]
    mass = network.mass_matrix(q)
    torch.testing.assert_close(mass, mass.transpose(1, 2), rtol=0, atol=0)
    assert torch.linalg.eigvalsh(mass).min() > 0


def test_delan_at_rest_predicts_its_gravity_torque_only(float64) -> None:
    network = DelanNetwork(random_scaling(), generator=generator(8))
    q, _, _ = random_state(seed=9)
    zeros = torch.zeros_like(q)
    parts = network.components(q, zeros, zeros)
    assert parts['gravity'].abs().max() > 0.1
    torch.testing.assert_close(parts['inertial'], zeros, rtol=0, atol=0)
    torch.testing.assert_close(parts['coriolis'], zeros, rtol=0, atol=0)
    torch.testing.assert_close(network(q, zeros, zeros), parts['gravity'], rtol=0, atol=0)


def lnn_reference(network: LnnNetwork, q, v, a) -> torch.Tensor:
    """(d2L/dv2) a + (d2L/dq dv) v - dL/dq with torch.func on the same physical Lagrangian."""

    scaling = network.scaling

    def tensor(x) -> torch.Tensor:
        return torch.as_tensor(x, dtype=q.dtype)

    gains, energy = (tensor(x) for x in scaling.balanced())

    def unit(x: torch.Tensor, scaler) -> torch.Tensor:
        return (x - tensor(0.5 * (scaler.low_ + scaler.high_))) / tensor(scaler.scale())

    def lagrangian(q1: torch.Tensor, v1: torch.Tensor) -> torch.Tensor:
        x = torch.cat([unit(q1, scaling.position) * gains, unit(v1, scaling.velocity) * gains])
        return energy * network.lagrangian_net(x.unsqueeze(0))[0, 0]

    def one(q1: torch.Tensor, v1: torch.Tensor, a1: torch.Tensor) -> torch.Tensor:
        hessian_vv = hessian(lagrangian, argnums=1)(q1, v1)
        mixed = jacrev(jacrev(lagrangian, argnums=1), argnums=0)(q1, v1)  # d2L / dv_i dq_j
        return hessian_vv @ a1 + mixed @ v1 - grad(lagrangian, argnums=0)(q1, v1)

    return vmap(one)(q, v, a)


@pytest.mark.parametrize(
    ('activation', 'balance'), [('softplus', 0.0), ('tanh', 0.0), ('tanh', 1.0)]
)
def test_lnn_torque_matches_torch_func_euler_lagrange(
    float64, activation: str, balance: float
) -> None:
    scaling = random_scaling(balance=balance)
    network = LnnNetwork(scaling, activation=activation, generator=generator(10))
    q, v, a = random_state(seed=11)
    expected = lnn_reference(network, q, v, a)
    assert expected.abs().max() > 1.0
    torch.testing.assert_close(network(q, v, a), expected, rtol=0, atol=1e-10)


def test_lnn_components_split_inertia_and_rest_gravity_and_sum_to_the_torque(float64) -> None:
    network = LnnNetwork(random_scaling(), generator=generator(12))
    q, v, a = random_state(seed=13)
    zeros = torch.zeros_like(q)
    parts = network.components(q, v, a)
    total = network(q, v, a)
    torch.testing.assert_close(sum(parts.values()), total, rtol=0, atol=1e-10)
    # Inertia is the part linear in a; gravity is the torque at rest.
    torch.testing.assert_close(parts['inertial'], total - network(q, v, zeros), rtol=0, atol=1e-10)
    torch.testing.assert_close(parts['gravity'], network(q, zeros, zeros), rtol=0, atol=1e-10)


def test_lnn_mlp_adds_the_dissipation_network_to_the_lnn_torque(float64) -> None:
    network = LnnMlpNetwork(random_scaling(), generator=generator(14))
    q, v, a = random_state(seed=15)
    friction = network.dissipation(q, v)
    assert friction.abs().max() > 0.1
    torch.testing.assert_close(network(q, v, a), network.lnn(q, v, a) + friction, rtol=0, atol=0)
    parts = network.components(q, v, a)
    torch.testing.assert_close(parts['friction'], friction, rtol=0, atol=0)
    torch.testing.assert_close(sum(parts.values()), network(q, v, a), rtol=0, atol=1e-10)


def test_scaling_survives_a_json_round_trip_exactly() -> None:
    scaling = random_scaling(seed=16)
    again = LagrangianScaling.from_dict(json.loads(json.dumps(scaling.to_dict())))
    assert again.energy == scaling.energy
    for name in ('position', 'velocity', 'torque'):
        np.testing.assert_array_equal(getattr(again, name).scale(), getattr(scaling, name).scale())
    expected = np.exp(np.mean(np.log(scaling.torque.scale() * scaling.position.scale())))
    assert scaling.energy == pytest.approx(expected, rel=1e-12)
    balanced = random_scaling(seed=16, balance=0.75)
    assert LagrangianScaling.from_dict(json.loads(json.dumps(balanced.to_dict()))).balance == 0.75
    assert LagrangianScaling.from_dict(balanced.to_dict()).balance_inertia
    # A model saved before the balance (or its Cholesky inputs) existed has none.
    old = {k: v for k, v in balanced.to_dict().items() if k != 'energy_balance'}
    assert LagrangianScaling.from_dict(old).balance == 0.0
    older = {k: v for k, v in balanced.to_dict().items() if k != 'balance_inertia'}
    assert not LagrangianScaling.from_dict(older).balance_inertia


@pytest.mark.parametrize('balance_inertia', [True, False])
def test_delan_mass_matrix_is_built_from_the_cholesky_net_on_the_balanced_positions(
    float64, balance_inertia: bool
) -> None:
    """M = L L^T, L = diag(sqrt(e_i) / h_v,i) (G * L_s(x)), x the positions scaled to [-1, 1]
    times the balance gains r_i (not multiplied in models saved before that, which load with
    ``balance_inertia`` False)."""
    from dataclasses import replace

    scaling = replace(random_scaling(seed=21, balance=1.0), balance_inertia=balance_inertia)
    network = DelanNetwork(scaling, generator=generator(22), diagonal_shift=-1.0)
    q, _, _ = random_state(seed=23)
    gains, _ = scaling.balanced()
    centre = torch.as_tensor(0.5 * (scaling.position.low_ + scaling.position.high_))
    x = (q - centre) / torch.as_tensor(scaling.position.scale())
    if balance_inertia:
        x = x * torch.as_tensor(gains)
    out = network.cholesky_net(x)
    n = N_DOF
    energies = torch.as_tensor(scaling.joint_energies())
    rows, cols = torch.tril_indices(n, n, offset=-1)
    factor = torch.zeros(len(q), n, n, dtype=q.dtype)
    factor[:, range(n), range(n)] = torch.nn.functional.softplus(out[:, :n] - 1.0) + 1e-3
    low = torch.minimum(energies[rows], energies[cols])
    high = torch.maximum(energies[rows], energies[cols])
    factor[:, rows, cols] = out[:, n:] * (low / high) ** 0.5
    rows_scale = torch.sqrt(energies) / torch.as_tensor(scaling.velocity.scale())
    cholesky = rows_scale[:, None] * factor
    expected = cholesky @ cholesky.transpose(1, 2)
    torch.testing.assert_close(network.mass_matrix(q), expected, rtol=1e-12, atol=1e-9)


@pytest.mark.parametrize('balance', [0.0, 0.5, 1.0])
def test_balance_sets_each_joints_sensitivity_to_the_scalar_net(balance: float) -> None:
    """Joint i's normalised torque is ``E_b r_i / e_i`` times the net's input gradient: equal
    for every joint at b = 1, ``E / e_i`` (the plain scaling) at b = 0."""
    scaling = random_scaling(seed=17, balance=balance)
    energies = scaling.joint_energies()
    assert energies.max() / energies.min() > 10.0
    gains, energy = scaling.balanced()
    sensitivity = energy * gains / energies
    np.testing.assert_allclose(sensitivity, (scaling.energy / energies) ** (1.0 - balance))
    assert gains.max() == pytest.approx(1.0)


def test_delan_gravity_is_the_balanced_potentials_gradient_in_physical_units(float64) -> None:
    scaling = random_scaling(seed=18, balance=1.0)
    network = DelanNetwork(scaling, generator=generator(19))
    q, _, _ = random_state(seed=20)
    gains, energy = scaling.balanced()
    centre = torch.as_tensor(0.5 * (scaling.position.low_ + scaling.position.high_))
    half = torch.as_tensor(scaling.position.scale())

    def potential(row: torch.Tensor) -> torch.Tensor:
        x = (row - centre) / half * torch.as_tensor(gains)
        return energy * network.potential_net(x.unsqueeze(0))[0, 0]

    torch.testing.assert_close(network.gravity(q), vmap(grad(potential))(q), rtol=0, atol=1e-10)


# --------------------------------------------------------------------------------------------
# Models on twin data


@pytest.fixture(scope='module')
def training_data(short_twin, mabi):
    from id_learning.dataset.preprocess import prepare_dataset
    from id_learning.models.data import TrainingData

    _, result = short_twin
    return TrainingData(prepare_dataset(result.recording, mabi, quick_preprocess()), mabi)


@pytest.fixture(scope='module')
def fitted(training_data, mabi):
    """One quickly fitted model of each kind."""
    return {
        kind: model_class(config_class(**QUICK), mabi).fit(training_data)
        for kind, (config_class, model_class) in MODELS.items()
    }


def validation_loss(model, data) -> float:
    """Mean squared error through the label filter on the validation rows, normalised scale."""
    dataset, rows = data.dataset, data.validation_rows
    predicted = dataset.filter_like_labels(model.predict(dataset.q, dataset.v, dataset.a))
    error = (predicted[rows] - dataset.tau[rows]) / dataset.target_scaler.scale()
    return float(np.mean(error**2))


@pytest.mark.parametrize('kind', list(MODELS))
def test_a_few_epochs_lower_the_validation_loss(kind, fitted, training_data, mabi) -> None:
    config_class, model_class = MODELS[kind]
    config = config_class(**QUICK)
    untrained = model_class(config, mabi)
    scaling = LagrangianScaling.from_dataset(training_data.dataset)
    network = untrained.make_network(scaling, generator(config.seed))
    untrained.load_state(
        {name: value.numpy() for name, value in network.state_dict().items()},
        {'scaling': scaling.to_dict()},
    )
    trained = fitted[kind]
    assert trained.history_ is not None
    assert len(trained.history_.train_loss) == QUICK['max_epochs']
    # The validation rows of a 26 s run lie outside the fitted part of its trajectory, so the
    # gain is modest (measured through the filter: DeLaN x0.21, LNN x0.75, LNN+MLP x0.29), but
    # it must be there.
    assert validation_loss(trained, training_data) < 0.9 * validation_loss(
        untrained, training_data
    )


def test_fitted_metadata_records_scaling_and_training(fitted) -> None:
    for kind, model in fitted.items():
        metadata = json.loads(json.dumps(model.fitted_metadata()))
        assert metadata['history']['epochs'] == QUICK['max_epochs'], kind
        assert metadata['scaling']['energy_scale_j'] > 0, kind


@pytest.mark.parametrize('kind', list(MODELS))
def test_saving_and_loading_gives_identical_predictions(
    kind, fitted, training_data, mabi, tmp_path
) -> None:
    from id_learning.models.registry import load_model, save_model

    model = fitted[kind]
    save_model(model, tmp_path / kind)
    loaded = load_model(tmp_path / kind, mabi, kind)
    test = training_data.dataset.test
    assert len(test.q) > 100
    assert type(loaded) is type(model)
    assert loaded.config == model.config
    np.testing.assert_array_equal(
        loaded.predict(test.q, test.v, test.a), model.predict(test.q, test.v, test.a)
    )
    assert {name: value.dtype for name, value in model.state().items()} == {
        name: np.dtype(np.float32) for name in model.state()
    }


def test_a_model_saved_before_the_balance_loads_unbalanced_and_says_so(fitted, mabi) -> None:
    model = fitted['delan']
    assert model.config.energy_balance > 0
    fitted_state = model.fitted_metadata()
    old = {**fitted_state, 'scaling': {**fitted_state['scaling']}}
    del old['scaling']['energy_balance']  # as written before the balance existed
    loaded = DelanModel(model.config, mabi)
    loaded.load_state(model.state(), old)
    assert loaded.config.energy_balance == 0.0
    assert loaded.scaling_ is not None
    assert loaded.scaling_.balance == 0.0
    network = loaded.network()
    torch.testing.assert_close(network.lagrangian_energy, network.energy)
    torch.testing.assert_close(network.lagrangian_q_half, network.q_half)


def test_state_round_trip_through_safetensors_and_json_is_exact(fitted, mabi, tmp_path) -> None:
    model = fitted['delan']
    write_artifact(
        tmp_path, 'delan', mabi, model.state(), settings={}, fitted=model.fitted_metadata()
    )
    saved, tensors = read_artifact(tmp_path, mabi, 'delan')
    loaded = DelanModel(DelanConfig(**QUICK), mabi)
    loaded.load_state(tensors, saved['fitted'])
    for name, value in model.state().items():
        np.testing.assert_array_equal(loaded.state()[name], value)
    assert loaded.fitted_metadata() == json.loads(json.dumps(model.fitted_metadata()))


def test_one_sample_is_predicted_as_one_row(fitted, training_data) -> None:
    test = training_data.dataset.test
    for kind, model in fitted.items():
        single = model.predict(test.q[:1], test.v[:1], test.a[:1])
        assert single.shape == (1, 6), kind
        batch = model.predict(test.q[:5], test.v[:5], test.a[:5])
        np.testing.assert_allclose(single[0], batch[0], rtol=1e-5, atol=1e-4 * np.abs(batch).max())


def test_components_sum_to_the_prediction_and_only_lnn_mlp_has_friction(
    fitted, training_data
) -> None:
    test = training_data.dataset.test
    for kind, model in fitted.items():
        parts = model.components(test.q, test.v, test.a)
        scale = np.abs(parts.total).max()
        np.testing.assert_allclose(
            sum(parts.parts().values()), parts.total, rtol=0, atol=1e-5 * scale
        )
        np.testing.assert_array_equal(parts.total, model.predict(test.q, test.v, test.a))
        expected = {'inertial', 'coriolis', 'gravity'} | (
            {'friction'} if kind == 'lnn_mlp' else set()
        )
        assert set(parts.parts()) == expected, kind


def test_delan_inertial_torque_is_its_mass_matrix_times_the_acceleration(
    fitted, training_data
) -> None:
    model = fitted['delan']
    test = training_data.dataset.test
    mass = model.mass_matrix(test.q)
    assert mass.shape == (len(test.q), 6, 6)
    assert np.linalg.eigvalsh(mass).min() > 0
    inertial = np.einsum('bij,bj->bi', mass, test.a)
    parts = model.components(test.q, test.v, test.a)
    np.testing.assert_allclose(
        parts.inertial, inertial, rtol=0, atol=1e-5 * np.abs(inertial).max()
    )


def test_fit_is_reproducible_for_a_seed(training_data, mabi) -> None:
    config = DelanConfig(**{**QUICK, 'max_epochs': 2})
    first = DelanModel(config, mabi).fit(training_data).state()
    second = DelanModel(config, mabi).fit(training_data).state()
    other = DelanModel(replace(config, seed=1), mabi).fit(training_data).state()
    for name, value in first.items():
        np.testing.assert_array_equal(value, second[name])
    assert any(not np.array_equal(value, other[name]) for name, value in first.items())


def test_predicting_before_fitting_is_refused(mabi) -> None:
    zeros = np.zeros((1, 6))
    with pytest.raises(RuntimeError, match='not fitted'):
        LnnModel(LnnConfig(), mabi).predict(zeros, zeros, zeros)


def test_weights_of_another_network_are_refused(fitted, mabi) -> None:
    delan, lnn = fitted['delan'], fitted['lnn']
    with pytest.raises(CheckpointError, match='do not match the network'):
        LnnModel(LnnConfig(), mabi).load_state(delan.state(), delan.fitted_metadata())
    wider = LnnModel(LnnConfig(width=32), mabi)
    with pytest.raises(CheckpointError, match='do not match the network'):
        wider.load_state(lnn.state(), lnn.fitted_metadata())
    with pytest.raises(CheckpointError, match='scaling'):
        LnnModel(LnnConfig(), mabi).load_state(lnn.state(), {})


@pytest.mark.parametrize(
    ('config_class', 'overrides', 'message'),
    [
        (DelanConfig, {'activation': 'relu'}, 'activation'),
        (LnnMlpConfig, {'dissipation_activation': 'relu'}, 'dissipation_activation'),
        (LnnConfig, {'stride': 0}, 'stride'),
        (LnnConfig, {'device': 'tpu'}, 'device'),
        (DelanConfig, {'diagonal_epsilon': 0.0}, 'diagonal_epsilon'),
        (LnnConfig, {'energy_balance': 1.5}, 'energy_balance'),
        (LnnConfig, {'max_seconds': -1.0}, 'max_seconds'),
    ],
)
def test_invalid_settings_are_refused_naming_the_key(config_class, overrides, message) -> None:
    with pytest.raises(ConfigError, match=message):
        config_class(**overrides)


def test_a_config_of_another_kind_is_refused(mabi) -> None:
    with pytest.raises(ConfigError, match="'delan'"):
        DelanModel(LnnConfig(), mabi)


DEVICES = [
    'cpu',
    pytest.param(
        'cuda',
        marks=pytest.mark.skipif(
            not torch.cuda.is_available(),
            reason='no CUDA device here; the cpu case checks the same on the CPU',
        ),
    ),
]


@pytest.mark.parametrize('device', DEVICES)
def test_fit_on_any_device_predicts_on_the_cpu_the_torque_of_its_lagrangian(
    device, training_data, mabi
) -> None:
    model = LnnModel(LnnConfig(**{**QUICK, 'device': device, 'max_epochs': 2}), mabi)
    model.fit(training_data)
    network = model.network_
    assert network is not None
    assert {parameter.device.type for parameter in network.parameters()} == {'cpu'}
    # The prediction is the Euler-Lagrange torque of the fitted Lagrangian (torch.func on the
    # CPU), and it is learnt from the data: not the torque of the untrained network.
    test = training_data.dataset.test
    rows = slice(0, 40)
    q, v, a = (torch.as_tensor(x[rows], dtype=torch.float32) for x in (test.q, test.v, test.a))
    predicted = model.predict(test.q[rows], test.v[rows], test.a[rows])
    expected = lnn_reference(network, q, v, a).detach().numpy()
    scale = np.abs(expected).max()
    np.testing.assert_allclose(predicted, expected, rtol=0, atol=1e-4 * scale)
    untrained = model.make_network(model.scaling_, generator(model.config.seed))
    assert any(
        not torch.equal(trained, initial)
        for trained, initial in zip(network.parameters(), untrained.parameters(), strict=True)
    )


@pytest.mark.parametrize('kind', ['delan', 'lnn', 'lnn_mlp'])
def test_the_init_setting_reaches_every_network_and_is_checked(kind, mabi):
    from id_learning.models.registry import make_model

    with pytest.raises(ConfigError, match='init must be one of'):
        make_model(kind, mabi, init='orthogonal')
    scaling = LagrangianScaling.from_data(
        np.zeros((2, 6)), np.ones((2, 6)), np.ones((2, 6)) * 10.0
    )
    nets = {}
    for init in ('xavier', 'fan_in'):
        model = make_model(kind, mabi, init=init)
        network = model.make_network(scaling, torch.Generator().manual_seed(0))
        nets[init] = [p.detach().clone() for n, p in network.named_parameters() if 'weight' in n]
    # Xavier's first layer (6 or 12 inputs, 64 units) is narrower than fan-in's 1/sqrt(fan_in).
    for xavier, fan_in in zip(nets['xavier'], nets['fan_in'], strict=True):
        if xavier.shape[1] in (6, 12):
            assert float(fan_in.std()) > 1.5 * float(xavier.std())
