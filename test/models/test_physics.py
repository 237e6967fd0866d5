"""RNEA+LQ and RNEA+MLP against the twin's ground truth and an independent pinocchio RNEA."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest
import torch
from safetensors.numpy import load_file, save_file
from support import quick_preprocess, twin_config

from id_learning.dataset import prepare_dataset
from id_learning.dataset.preprocess import PreprocessConfig, lowpass
from id_learning.errors import CheckpointError, ConfigError
from id_learning.models.data import TrainingData
from id_learning.models.physics import (
    RneaLqConfig,
    RneaLqModel,
    RneaMlpConfig,
    RneaMlpModel,
)
from id_learning.twin import simulate

# The twin's default drive effects (config/twin_default.yaml).
ROTOR_SCALE = [1.25, 1.25, 1.3, 1.2, 1.2, 1.2]
VISCOUS = np.array([420.0, 520.0, 300.0, 60.0, 45.0, 20.0])  # N*m*s/rad
COULOMB = np.array([160.0, 210.0, 120.0, 28.0, 22.0, 9.0])  # N*m
OFFSET = np.array([12.0, -18.0, 9.0, 2.0, -1.5, 0.6])  # N*m
TWIN_COULOMB_VELOCITY = 0.005  # rad/s, the twin's default smoothing velocity
# 240 s (168 s of training rows) at this seed excite every joint's rotor inertia above the noise
# that survives the 0.3-1.2 Hz filters; the preconditions below check that this still holds.
DURATION_S = 240.0
SEED = 7


@pytest.fixture(scope='module', autouse=True)
def one_torch_thread():
    """Small networks gain nothing from intra-op threads and stall on a loaded machine.

    Module scope, so that it is in force before the module's fitted-model fixtures run.
    """
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(threads)


def drive_effects(*, coulomb_and_offset: bool) -> dict:
    effects = {
        'rotor_inertia': {'enabled': True, 'scale': ROTOR_SCALE},
        'viscous_friction': {'enabled': True, 'coefficient': VISCOUS.tolist()},
    }
    if coulomb_and_offset:
        effects['coulomb_friction'] = {
            'enabled': True,
            'level': COULOMB.tolist(),
            'smoothing_velocity': TWIN_COULOMB_VELOCITY,
        }
        effects['torque_offset'] = {'enabled': True, 'offset': OFFSET.tolist()}
    return effects


def twin_training_data(effects: dict, mode: str = 'through_filter'):
    config = twin_config(DURATION_S, effects, seed=SEED)
    result = simulate(config)
    dataset = prepare_dataset(
        result.recording, config.robot, PreprocessConfig(target='motor', mode=mode)
    )
    return config, result, TrainingData(dataset, config.robot)


@pytest.fixture(scope='module')
def drive_twin():
    """Twin data whose only effects beyond the URDF are rotor inertia and viscous friction."""
    return twin_training_data(drive_effects(coulomb_and_offset=False))


@pytest.fixture(scope='module')
def friction_twin():
    """Twin data with rotor inertia, viscous and Coulomb friction and a torque offset."""
    return twin_training_data(drive_effects(coulomb_and_offset=True))


def label_noise_rms(result, data: TrainingData, rows: slice | None = None) -> np.ndarray:
    """RMS per joint of the noise left in the filtered labels (training rows by default) [N*m]."""
    ds = data.dataset
    clean = lowpass(result.tau_u_clean, ds.cutoff_hz, ds.period_s, ds.filter_order)
    rows = data.train_rows if rows is None else rows
    return np.sqrt(np.mean((ds.tau[rows] - clean[rows]) ** 2, axis=0))


def rms(x: np.ndarray) -> np.ndarray:
    return np.sqrt(np.mean(x**2, axis=0))


def round_trip(model, tmp_path: Path):
    """Save state and metadata as the artifact does (safetensors + JSON), load into a new model."""
    save_file(model.state(), str(tmp_path / 'weights.safetensors'))
    fitted = json.loads(json.dumps(model.fitted_metadata()))
    loaded = type(model)(model.config, model.robot)
    loaded.load_state(load_file(str(tmp_path / 'weights.safetensors')), fitted)
    return loaded


# -- RNEA+LQ -------------------------------------------------------------------------------------
def test_rnea_lq_recovers_the_twins_true_rotor_inertia_and_viscous_coefficients(drive_twin):
    config, result, data = drive_twin
    assert config.effects.enabled_names() == ['viscous_friction', 'rotor_inertia']
    true_inertia = np.array(result.parameters['true']['rotor_inertia_motor_side_kgm2'])
    np.testing.assert_allclose(true_inertia, config.robot.drives.rotor_inertia * ROTOR_SCALE)
    # Preconditions: each effect stands out of the noise that survives the label filter.
    noise = label_noise_rms(result, data)
    rows = data.train_rows
    assert (rms(data.physics.rotor_basis[rows] * true_inertia) > 1.5 * noise).all()
    assert (rms(data.dataset.v[rows] * VISCOUS) > 10 * noise).all()

    model = RneaLqModel(RneaLqConfig(), config.robot).fit(data)

    fitted = model.fitted_metadata()['parameters']
    assert set(fitted) == {'rotor_inertia_motor_side', 'viscous'}
    np.testing.assert_allclose(fitted['rotor_inertia_motor_side'], true_inertia, rtol=0.05)
    np.testing.assert_allclose(fitted['viscous'], VISCOUS, rtol=0.02)


def test_rnea_lq_predicts_held_out_twin_torque_at_the_label_noise_through_the_filter(drive_twin):
    config, result, data = drive_twin
    model = RneaLqModel(RneaLqConfig(), config.robot).fit(data)
    ds, test = data.dataset, data.test_rows
    # Independent scoring: the torque along the recording on the controller's inputs, filtered
    # like the labels with scipy, against the labels of the test part.
    torque = model.predict(ds.controller.q, ds.controller.v, ds.controller.a)
    filtered = lowpass(torque, ds.cutoff_hz, ds.period_s, ds.filter_order)
    rmse = rms(filtered[test] - ds.tau[test])
    noise = label_noise_rms(result, data, test)
    # The model has the twin's effect forms: what is left is the label noise itself.
    assert (rmse < 1.2 * noise).all(), (rmse, noise)


def test_rnea_lq_with_coulomb_and_offset_recovers_them_where_viscous_only_cannot(friction_twin):
    config, result, data = friction_twin
    assert set(config.effects.enabled_names()) == {
        'viscous_friction',
        'coulomb_friction',
        'rotor_inertia',
        'torque_offset',
    }
    noise = label_noise_rms(result, data)
    assert (3 * noise < COULOMB).all()
    true_inertia = np.array(result.parameters['true']['rotor_inertia_motor_side_kgm2'])

    full = RneaLqModel(
        RneaLqConfig(friction='viscous_coulomb_offset', coulomb_velocity=TWIN_COULOMB_VELOCITY),
        config.robot,
    ).fit(data)
    viscous_only = RneaLqModel(RneaLqConfig(friction='viscous'), config.robot).fit(data)

    fitted = full.fitted_metadata()['parameters']
    np.testing.assert_allclose(fitted['rotor_inertia_motor_side'], true_inertia, rtol=0.05)
    np.testing.assert_allclose(fitted['viscous'], VISCOUS, rtol=0.06)
    np.testing.assert_allclose(fitted['coulomb'], COULOMB, rtol=0.04)
    offset_error = np.abs(np.array(fitted['offset']) - OFFSET)
    assert (offset_error < 0.02 * COULOMB).all(), offset_error
    # Without the Coulomb term the viscous coefficient absorbs it and the fit stays poor.
    full_rmse = np.array(full.fitted_metadata()['training_rmse_nm'])
    viscous_rmse = np.array(viscous_only.fitted_metadata()['training_rmse_nm'])
    assert (viscous_rmse > 2 * full_rmse).all()
    viscous_error = np.abs(viscous_only.fitted_metadata()['parameters']['viscous'] / VISCOUS - 1)
    assert (viscous_error > 0.1).any()


def test_rnea_lq_fitted_the_studys_way_misses_the_coulomb_level():
    """Filtered labels against unfiltered regressor columns see a smeared Coulomb step."""
    config, _, data = twin_training_data(drive_effects(coulomb_and_offset=True), mode='study')
    assert not data.dataset.is_through_filter
    study = RneaLqModel(
        RneaLqConfig(friction='viscous_coulomb_offset', coulomb_velocity=TWIN_COULOMB_VELOCITY),
        config.robot,
    ).fit(data)
    coulomb = np.array(study.fitted_metadata()['parameters']['coulomb'])
    assert np.max(np.abs(coulomb / COULOMB - 1)) > 0.1


def test_rnea_lq_components_sum_to_its_prediction(friction_twin):
    config, _, data = friction_twin
    model = RneaLqModel(RneaLqConfig(friction='viscous_coulomb_offset'), config.robot).fit(data)
    test = data.dataset.test
    q, v, a = (x[::50] for x in (test.q, test.v, test.a))

    parts = model.components(q, v, a)

    assert set(parts.parts()) == {
        'inertial',
        'coriolis',
        'gravity',
        'rotor_inertia',
        'friction',
        'residual',
    }
    np.testing.assert_array_equal(parts.total, model.predict(q, v, a))
    scale = np.max(np.abs(parts.total))
    np.testing.assert_allclose(sum(parts.parts().values()), parts.total, rtol=0, atol=1e-9 * scale)
    p = model.state()
    np.testing.assert_allclose(parts.residual, np.broadcast_to(p['offset'], q.shape))
    gear = config.robot.drives.gear_ratio
    np.testing.assert_allclose(parts.rotor_inertia, p['rotor_inertia_motor_side'] * gear**2 * a)
    np.testing.assert_allclose(parts.gravity, model.dynamics.gravity(q))


def test_rnea_lq_viscous_only_has_no_residual_component(drive_twin):
    config, _, data = drive_twin
    model = RneaLqModel(RneaLqConfig(), config.robot).fit(data)
    test = data.dataset.test
    assert model.components(test.q[:3], test.v[:3], test.a[:3]).residual is None


def test_rnea_lq_save_then_load_predicts_identically(friction_twin, tmp_path):
    config, _, data = friction_twin
    model = RneaLqModel(RneaLqConfig(friction='viscous_coulomb'), config.robot).fit(data)
    loaded = round_trip(model, tmp_path)
    test = data.dataset.test
    np.testing.assert_array_equal(
        loaded.predict(test.q, test.v, test.a), model.predict(test.q, test.v, test.a)
    )
    assert loaded.fitted_metadata() == model.fitted_metadata()


def test_rnea_lq_refuses_a_state_without_its_parameters(mabi):
    model = RneaLqModel(RneaLqConfig(), mabi)
    with pytest.raises(CheckpointError, match='rotor_inertia_motor_side'):
        model.load_state({'viscous': np.zeros(6)}, {})


@pytest.mark.parametrize(
    ('overrides', 'key'),
    [
        ({'friction': 'stribeck'}, 'friction'),
        ({'coulomb_velocity': 0.0}, 'coulomb_velocity'),
        ({'kind': 'mlp'}, 'kind'),
    ],
)
def test_rnea_lq_config_rejects_bad_values_naming_the_key(overrides, key):
    with pytest.raises(ConfigError, match=key):
        RneaLqConfig(**overrides)


def test_rnea_lq_refuses_to_predict_before_fitting(mabi):
    zeros = np.zeros((1, 6))
    with pytest.raises(RuntimeError, match='not fitted'):
        RneaLqModel(RneaLqConfig(), mabi).predict(zeros, zeros, zeros)


# -- RNEA+MLP ------------------------------------------------------------------------------------
def independent_rnea(robot, q: np.ndarray, v: np.ndarray, a: np.ndarray) -> np.ndarray:
    """Pinocchio's RNEA on a model built straight from the URDF, columns mapped by joint name."""
    model = pin.buildModelFromUrdf(str(robot.urdf_path))
    data = model.createData()
    index = [model.joints[model.getJointId(name)].idx_v for name in robot.joints]
    out = np.empty_like(q)
    for k in range(len(q)):
        qk, vk, ak = (np.zeros(model.nv) for _ in range(3))
        qk[index], vk[index], ak[index] = q[k], v[k], a[k]
        out[k] = pin.rnea(model, data, qk, vk, ak)[index]
    return out


def zero_residual_model(robot, config: RneaMlpConfig | None = None) -> RneaMlpModel:
    """An RNEA+MLP whose network h is identically zero."""
    model = RneaMlpModel(config or RneaMlpConfig(), robot)
    n = robot.n_joints
    unit = {'low': [-1.0] * 2 * n, 'high': [1.0] * 2 * n}
    zero = {'low': [0.0] * n, 'high': [0.0] * n}
    shapes = {'net.0.weight': (64, 2 * n), 'net.0.bias': (64,), 'net.2.weight': (64, 64)}
    shapes |= {'net.2.bias': (64,), 'net.4.weight': (n, 64), 'net.4.bias': (n,)}
    tensors = {name: np.zeros(shape, dtype=np.float32) for name, shape in shapes.items()}
    model.load_state(tensors, {'state_scaler': unit, 'residual_scaler': zero})
    return model


def random_states(robot, count: int, seed: int) -> tuple[np.ndarray, ...]:
    rng = np.random.default_rng(seed)
    limits = robot.limits
    shape = (count, robot.n_joints)
    return (
        rng.uniform(limits.position_lower, limits.position_upper, shape),
        rng.uniform(-limits.velocity, limits.velocity, shape),
        rng.uniform(-limits.acceleration, limits.acceleration, shape),
    )


def test_rnea_mlp_with_zero_network_equals_pinocchio_rnea_plus_datasheet_rotor_inertia(mabi):
    q, v, a = random_states(mabi, 40, seed=3)
    model = zero_residual_model(mabi)
    assert not np.any(model.residual_torque(q, v))

    expected = independent_rnea(mabi, q, v, a) + (
        mabi.drives.rotor_inertia * mabi.drives.gear_ratio**2 * a
    )

    np.testing.assert_allclose(model.predict(q, v, a), expected, rtol=1e-12, atol=1e-9)
    rotor = model.components(q, v, a).rotor_inertia
    assert np.max(np.abs(rotor)) > 10.0  # N*m: the rotor term is not vacuous
    parts = model.components(q, v, a).parts()
    np.testing.assert_allclose(sum(parts.values()), expected, rtol=1e-10, atol=1e-8)


@pytest.fixture(scope='module')
def fitted_rnea_mlp(short_twin):
    config, result = short_twin
    dataset = prepare_dataset(result.recording, config.robot, quick_preprocess())
    data = TrainingData(dataset, config.robot)
    model = RneaMlpModel(
        RneaMlpConfig(max_epochs=30, stride=4, batch_size=128, device='cpu'), config.robot
    )
    return model.fit(data), data


def test_rnea_mlp_short_fit_beats_the_physics_alone_on_validation(fitted_rnea_mlp):
    model, data = fitted_rnea_mlp
    ds, rows = data.dataset, data.validation_rows
    physics_error = model.physics_torque(ds.q[rows], ds.v[rows], ds.a[rows]) - ds.tau[rows]
    model_error = model.predict(ds.q[rows], ds.v[rows], ds.a[rows]) - ds.tau[rows]
    half = ds.target_scaler.scale()
    physics_loss = np.mean((physics_error / half) ** 2)
    assert model.history_ is not None
    assert model.history_.best_validation_loss < 0.5 * physics_loss
    assert np.mean((model_error / half) ** 2) < 0.5 * physics_loss


def test_rnea_mlp_components_split_h_into_friction_and_residual(fitted_rnea_mlp):
    model, data = fitted_rnea_mlp
    test = data.dataset.test
    q, v, a = (x[::40] for x in (test.q, test.v, test.a))
    parts = model.components(q, v, a)
    np.testing.assert_allclose(parts.total, model.predict(q, v, a), rtol=0, atol=1e-9)
    scale = np.max(np.abs(parts.total))
    np.testing.assert_allclose(sum(parts.parts().values()), parts.total, atol=1e-9 * scale)
    np.testing.assert_allclose(
        parts.friction + parts.residual, model.residual_torque(q, v), atol=1e-9 * scale
    )
    # friction is h's velocity-dependent part: it vanishes at rest.
    at_rest = model.components(q, np.zeros_like(v), a)
    np.testing.assert_array_equal(at_rest.friction, np.zeros_like(v))


def test_rnea_mlp_save_then_load_predicts_identically(fitted_rnea_mlp, tmp_path):
    model, data = fitted_rnea_mlp
    loaded = round_trip(model, tmp_path)
    test = data.dataset.test
    assert set(model.state()) == {f'net.{i}.{p}' for i in (0, 2, 4) for p in ('weight', 'bias')}
    np.testing.assert_array_equal(
        loaded.predict(test.q, test.v, test.a), model.predict(test.q, test.v, test.a)
    )


def test_rnea_mlp_predicts_a_single_sample_as_one_row(fitted_rnea_mlp):
    model, data = fitted_rnea_mlp
    test = data.dataset.test
    one = model.predict(test.q[:1], test.v[:1], test.a[:1])
    assert one.shape == (1, 6)
    np.testing.assert_allclose(one[0], model.predict(test.q, test.v, test.a)[0], rtol=1e-6)


def test_rnea_mlp_refuses_tensors_of_another_width(mabi):
    model = zero_residual_model(mabi)
    with pytest.raises(CheckpointError, match='do not match'):
        model.__class__(RneaMlpConfig(width=32), mabi).load_state(
            model.state(), model.fitted_metadata()
        )
