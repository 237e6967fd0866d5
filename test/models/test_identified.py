"""The identified-physics kinds (rnea_id, rnea_id_mlp) and target-aware Newtonian physics."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
import torch
from support import twin_config

from id_learning.dataset.preprocess import PreprocessConfig, prepare_dataset
from id_learning.errors import ConfigError
from id_learning.evaluation.physics_report import identified_physics_section
from id_learning.models.data import TrainingData
from id_learning.models.registry import load_model, make_model, save_model
from id_learning.physics import RigidBodyDynamics
from id_learning.record.excitation import ExcitationTrajectory
from id_learning.twin import simulate

QUICK_MLP = {'max_epochs': 3, 'device': 'cpu', 'width': 16, 'windows_per_batch': 1}


@pytest.fixture(scope='module')
def data(mabi):
    """A 150 s default twin run (every hidden effect), as training data."""
    result = simulate(twin_config(150.0, seed=9))
    return TrainingData(prepare_dataset(result.recording, mabi), mabi)


@pytest.fixture(scope='module')
def fitted(data, mabi):
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        return {
            'rnea_id': make_model('rnea_id', mabi).fit(data),
            'rnea_id_mlp': make_model('rnea_id_mlp', mabi, **QUICK_MLP).fit(data),
        }
    finally:
        torch.set_num_threads(threads)


@pytest.mark.parametrize('kind', ['rnea_id', 'rnea_id_mlp'])
def test_identified_kinds_save_load_and_predict_exactly_the_same(
    kind, fitted, data, mabi, tmp_path
):
    model = fitted[kind]
    save_model(model, tmp_path / kind)
    loaded = load_model(tmp_path / kind, mabi, kind)
    ds = data.dataset
    rows = slice(0, 500, 9)
    q, v, a = ds.q[rows], ds.v[rows], ds.a[rows]
    np.testing.assert_array_equal(loaded.predict(q, v, a), model.predict(q, v, a))
    one = loaded.sample_predictor()
    single = np.vstack([one(q[k], v[k], a[k]) for k in range(len(q))])
    # float64 numpy against the float32 network of rnea_id_mlp; exact for rnea_id.
    np.testing.assert_allclose(single, model.predict(q, v, a), rtol=1e-6, atol=1e-3)
    parts = loaded.components(q, v, a)
    np.testing.assert_allclose(sum(parts.parts().values()), parts.total, rtol=1e-9, atol=1e-6)
    np.testing.assert_allclose(parts.total, model.predict(q, v, a), rtol=1e-9, atol=1e-6)


def test_rnea_id_names_the_balancer_and_the_payload_the_urdf_lacks(fitted, mabi):
    report = fitted['rnea_id'].fitted_metadata()['physics']['report']
    assert 'joint_2' in [entry['joint'] for entry in report['balancers']]
    nominal = RigidBodyDynamics.from_config(mabi).inertial_parameters().reshape(-1, 10)
    identified = fitted['rnea_id'].physics_.theta.reshape(-1, 10)
    # The twin's 40 kg payload sits on the last body.
    assert identified[-1, 0] - nominal[-1, 0] == pytest.approx(40.0, rel=0.15)


def test_the_report_section_puts_the_identified_physics_beside_the_urdf(fitted, mabi):
    lines = identified_physics_section({'mlp': object(), **fitted}, mabi)
    text = '\n'.join(lines)
    assert lines[0] == '## Identified physics (rnea_id) against the URDF'
    physics = fitted['rnea_id'].physics_
    report = physics.report
    n_data = sum(b['identified'] for b in report['base_parameters'])
    assert f'{n_data} of {len(report["base_parameters"])} base parameters' in text
    # One row per body, per joint and per base parameter, each naming it first.
    for j, joint in enumerate(mabi.joints):
        assert f'| body {j + 1} ({joint}) |' in text
        assert f'| {joint} | {mabi.drives.rotor_inertia[j]:.4g} |' in text
    for entry in report['base_parameters']:
        assert f'| {entry["name"]} | {entry["unit"]} |' in text
    payload = np.asarray(report['payload']['value'])
    assert payload[0] == pytest.approx(40.0, rel=0.15)
    assert f'mass {payload[0]:.4g} ±' in text
    assert identified_physics_section({'mlp': object()}, mabi) == []


def test_rnea_id_settings_are_checked_naming_the_key(mabi):
    with pytest.raises(ConfigError, match='mass_rel_std'):
        make_model('rnea_id', mabi, mass_rel_std=0.0)
    with pytest.raises(ConfigError, match='friction'):
        make_model('rnea_id', mabi, friction='viscous,sticky')


def test_rnea_mlp_on_joint_torques_adds_no_rotor_inertia(mabi):
    """A joint torque sensor at the gear output never sees the motor's inertia."""
    config = replace(twin_config(60.0, {}, seed=3), joint_torque_sensors=True)
    result = simulate(config)
    dataset = prepare_dataset(
        result.recording, mabi, PreprocessConfig(target='joint', mode='study')
    )
    data = TrainingData(dataset, mabi)
    model = make_model('rnea_mlp', mabi, max_epochs=1, device='cpu', width=8).fit(data)
    np.testing.assert_array_equal(model.training_physics(data), data.physics.rnea)
    q, v, a = dataset.q[:5], dataset.v[:5], dataset.a[:5]
    assert model.components(q, v, a).rotor_inertia is None
    assert model.fitted_metadata()['target'] == 'joint'


@pytest.mark.parametrize('kind', ['rnea_id', 'rnea_id_mlp'])
def test_for_the_drive_leaves_out_the_labels_delay_and_nothing_else(kind, fitted, data, mabi):
    model = fitted[kind]
    delay = model.identified_physics().delay_s
    assert 0.002 < delay < 0.006  # the twin's currents lag the motion by 4 ms
    drive = model.for_the_drive()
    assert drive.identified_physics().delay_s == 0.0
    assert model.identified_physics().delay_s == delay  # the fitted model is left as it was
    ds = data.dataset
    rows = slice(0, 2000, 7)
    q, v, a = ds.q[rows], ds.v[rows], ds.a[rows]
    label, now = (
        model.identified_physics().parts(q, v, a),
        drive.identified_physics().parts(q, v, a),
    )
    # The lag: the delay's term, and the cogging's phase (at q - d v in the labels, at q now).
    lag = label['delay'] + label['cogging'] - now['cogging']
    np.testing.assert_allclose(drive.predict(q, v, a), model.predict(q, v, a) - lag, atol=1e-6)
    for name in set(label) - {'delay', 'cogging'}:
        np.testing.assert_array_equal(now[name], label[name])
    one = drive.sample_predictor()
    single = np.vstack([one(q[k], v[k], a[k]) for k in range(len(q))])
    np.testing.assert_allclose(single, drive.predict(q, v, a), rtol=1e-6, atol=1e-3)
    assert drive.for_the_drive() is drive


def test_the_label_view_is_the_drive_torque_delayed(fitted, mabi):
    """predict(t) ~ for_the_drive().predict(t - d) along a smooth motion, to first order."""
    model = fitted['rnea_id']
    delay = model.identified_physics().delay_s
    trajectory = simulate(twin_config(40.0, seed=12)).parameters['excitation']
    plan = ExcitationTrajectory.from_dict(trajectory)
    t = np.linspace(5.0, 35.0, 400)
    now = model.for_the_drive().predict(*plan.evaluate(t - delay))
    label = model.predict(*plan.evaluate(t))
    unshifted = model.for_the_drive().predict(*plan.evaluate(t))
    # Friction flips make the first-order shift inexact near zero speed: judge the smooth rest.
    _, v, _ = plan.evaluate(t)
    smooth = np.all(np.abs(v) > 0.05, axis=1)
    assert smooth.sum() > 50
    error = np.sqrt(np.mean((label - now)[smooth] ** 2, axis=0))
    without = np.sqrt(np.mean((label - unshifted)[smooth] ** 2, axis=0))
    assert np.all(error < 0.2 * without + 1e-3), (error, without)


def test_models_without_a_lag_of_their_own_serve_themselves(mabi):
    model = make_model('rnea_lq', mabi)
    assert model.for_the_drive() is model
