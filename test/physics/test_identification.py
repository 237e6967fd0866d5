"""Identifying the rigid body and drives, against the twin's known parameters and pinocchio."""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pinocchio as pin
import pytest
from support import twin_config

from id_learning.dataset.preprocess import PreprocessConfig, prepare_dataset
from id_learning.dataset.signals import lowpass
from id_learning.errors import ConfigError
from id_learning.physics import RigidBodyDynamics
from id_learning.physics.base_parameters import (
    base_parameters,
    pseudo_inertia,
)
from id_learning.physics.identification import IdentificationConfig, identify
from id_learning.physics.identified import IdentifiedPhysics
from id_learning.robot.drives import current_from_motor_torque
from id_learning.twin import simulate

ROTOR_SCALE = np.array([1.25, 1.25, 1.3, 1.2, 1.2, 1.2])
VISCOUS = np.array([420.0, 520.0, 300.0, 60.0, 45.0, 20.0])
COULOMB = np.array([160.0, 210.0, 120.0, 28.0, 22.0, 9.0])
OFFSET = np.array([12.0, -18.0, 9.0, 2.0, -1.5, 0.6])
KT_SCALE = np.array([1.03, 0.97, 1.02, 1.04, 0.98, 1.01])
DURATION_S = 240.0


def drive_twin(**extra):
    effects = {
        'rotor_inertia': {'enabled': True, 'scale': ROTOR_SCALE.tolist()},
        'viscous_friction': {'enabled': True, 'coefficient': VISCOUS.tolist()},
        'coulomb_friction': {
            'enabled': True,
            'level': COULOMB.tolist(),
            'smoothing_velocity': 0.005,
        },
        'torque_offset': {'enabled': True, 'offset': OFFSET.tolist()},
        'torque_constant_scale': {'enabled': True, 'scale': KT_SCALE.tolist()},
        'inertial_parameter_error': {'enabled': True, 'mass_rel_std': 0.03, 'com_std_m': 0.01},
        **extra,
    }
    config = twin_config(DURATION_S, effects, seed=5)
    return config, simulate(config)


@pytest.fixture(scope='module')
def identified(mabi):
    _, result = drive_twin()
    dataset = prepare_dataset(result.recording, mabi)
    settings = IdentificationConfig(friction=('viscous', 'coulomb'), balancer='none')
    return result, dataset, identify(dataset, mabi, settings)


def test_the_pseudo_inertia_is_psd_for_real_bodies_and_not_for_impossible_ones(mabi):
    dynamics = RigidBodyDynamics.from_config(mabi)
    for body in dynamics.inertial_parameters().reshape(-1, 10):
        assert np.linalg.eigvalsh(pseudo_inertia(body)).min() > -1e-9
    # A point mass m at c has J = [[m c c^T, m c], [m c^T, m]].
    point = pin.Inertia(2.0, np.array([0.1, -0.2, 0.3]), np.zeros((3, 3)))
    c = point.lever
    expected = np.zeros((4, 4))
    expected[:3, :3] = 2.0 * np.outer(c, c)
    expected[:3, 3] = expected[3, :3] = 2.0 * c
    expected[3, 3] = 2.0
    np.testing.assert_allclose(pseudo_inertia(point.toDynamicParameters()), expected, atol=1e-12)
    # Principal moments that break the triangle inequality (Ixx > Iyy + Izz) are impossible.
    impossible = pin.Inertia(1.0, np.zeros(3), np.diag([1.0, 0.2, 0.2]))
    assert np.linalg.eigvalsh(pseudo_inertia(impossible.toDynamicParameters())).min() < 0


def test_base_parameters_give_the_same_torque_as_all_parameters(mabi):
    dynamics = RigidBodyDynamics.from_config(mabi)
    base = base_parameters(dynamics, mabi.limits)
    rng = np.random.default_rng(4)
    q = rng.uniform(mabi.limits.position_lower, mabi.limits.position_upper, (50, 6))
    v, a = rng.normal(size=q.shape), rng.normal(size=q.shape)
    regressor = dynamics.regressor(q, v, a)
    theta = dynamics.inertial_parameters() + rng.normal(size=60)
    beta = base.matrix @ theta
    np.testing.assert_allclose(
        regressor[:, :, base.independent] @ beta, regressor @ theta, rtol=1e-8, atol=1e-6
    )
    assert base.count < 60
    assert len(base.names) == base.count


def test_identification_recovers_the_drives_and_labels_gains_of_the_twin(identified, mabi):
    result, _, model = identified
    truth = result.parameters['true']
    rotor = np.array(truth['rotor_inertia_motor_side_kgm2'])
    np.testing.assert_allclose(model.rotor, rotor, rtol=0.1)
    # tau_u from currents is off by 1 / scale; the model's gain is g = 1 / scale - 1. Gravity
    # makes it identifiable on joints 2 and 3; on the vertical joint 1 it trades against the
    # rotor's and the first link's inertia, which act there alone.
    np.testing.assert_allclose(model.gain[1:3], 1 / KT_SCALE[1:3] - 1, atol=0.01)
    # Friction and offsets come through the label gain: the fitted ones are the labels'.
    np.testing.assert_allclose(model.friction['viscous'], VISCOUS / KT_SCALE, rtol=0.03)
    np.testing.assert_allclose(model.friction['coulomb'], COULOMB / KT_SCALE, rtol=0.05)
    np.testing.assert_allclose(model.offset, OFFSET, atol=1.5)


def test_every_identified_body_is_physical_and_base_parameters_cover_the_truth(identified, mabi):
    result, _, model = identified
    for body in model.theta.reshape(-1, 10):
        assert np.linalg.eigvalsh(pseudo_inertia(body)).min() >= -1e-6 * abs(body[0])
    report = model.report
    truth = np.array(result.parameters['true']['inertial_parameters'])
    base = base_parameters(RigidBodyDynamics.from_config(mabi), mabi.limits)
    true_beta = base.matrix @ truth
    inside = [
        entry['ci95'][0] <= value <= entry['ci95'][1]
        for entry, value in zip(report['base_parameters'], true_beta, strict=True)
    ]
    assert np.mean(inside) >= 0.8, inside
    assert report['condition_number'] > 1
    # The recording identifies some base parameters; those it cannot reach keep the prior.
    flags = [entry['identified'] for entry in report['base_parameters']]
    assert any(flags)


def test_identified_model_meets_the_labels_at_their_noise_through_the_filter(identified):
    result, dataset, model = identified
    test = slice(dataset.n_train, None)
    motion = dataset.controller
    torque = model.torque(motion.q, motion.v, motion.a)
    cutoff, period = dataset.cutoff_hz, dataset.period_s
    filtered = lowpass(torque, cutoff, period)
    clean = lowpass(result.tau_u_clean, cutoff, period)
    floor = np.sqrt(np.mean((dataset.tau[test] - clean[test]) ** 2, axis=0))
    rmse = np.sqrt(np.mean((filtered[test] - dataset.tau[test]) ** 2, axis=0))
    assert (rmse < 1.3 * floor).all(), rmse / floor


def test_a_payload_the_data_would_make_negative_stays_physical(mabi):
    """Labels 20 kg lighter than the URDF at the flange: least squares would fit a payload of
    negative mass; the pseudo-inertia constraint keeps it a real body."""
    config = twin_config(150.0, {}, seed=6)
    result = simulate(config)
    dynamics = RigidBodyDynamics.from_config(mabi)
    heavier = dynamics.with_payload(mabi.payload_frame, 20.0, np.array([0.1, 0.0, 0.05]))
    missing = heavier.rnea(result.q_true, result.v_true, result.a_true) - dynamics.rnea(
        result.q_true, result.v_true, result.a_true
    )
    current = result.recording.current - current_from_motor_torque(missing, mabi.drives)
    recording = replace(result.recording, current=current)
    dataset = prepare_dataset(recording, mabi)
    settings = IdentificationConfig(friction=(), balancer='none', delay=False)
    model = identify(dataset, mabi, settings)
    flange = model.theta.reshape(-1, 10)[-1]
    assert np.linalg.eigvalsh(pseudo_inertia(flange)).min() >= -1e-6 * abs(flange[0])
    assert flange[0] > 0.5 * dynamics.inertial_parameters().reshape(-1, 10)[-1][0]


def test_joint_torque_labels_keep_the_link_side_terms_and_the_friction_they_show(mabi):
    """This twin has no friction at all: the friction its joint torques are given is nil (a
    Panda's sensors see the friction of the bearings on their link side: it is estimated)."""
    config = replace(twin_config(150.0, {}, seed=8), joint_torque_sensors=True)
    result = simulate(config)
    dataset = prepare_dataset(result.recording, mabi, PreprocessConfig(target='joint'))
    model = identify(dataset, mabi, IdentificationConfig(balancer='none'))
    assert model.target == 'joint'
    np.testing.assert_array_equal(model.rotor, 0.0)
    np.testing.assert_array_equal(model.gain, 0.0)
    assert model.delay_s == 0.0
    assert set(model.friction) == {'viscous', 'coulomb', 'stribeck', 'load_dependent'}
    friction = model.parts(dataset.q, dataset.v, dataset.a)['friction']
    rms = np.sqrt(np.mean(friction**2, axis=0))
    # 1 % of the joint's torque, and 0.05 N*m where the joint carries almost none (the wrist).
    assert (rms < np.maximum(0.01 * np.sqrt(np.mean(dataset.tau**2, axis=0)), 0.05)).all(), rms


def test_identified_physics_round_trips_and_its_sample_path_equals_the_batch(identified, mabi):
    _, dataset, model = identified
    again = IdentifiedPhysics.from_arrays(
        mabi, model.arrays(), json.loads(json.dumps(model.metadata()))
    )
    rows = slice(0, 200, 7)
    q, v, a = dataset.q[rows], dataset.v[rows], dataset.a[rows]
    np.testing.assert_array_equal(again.torque(q, v, a), model.torque(q, v, a))
    one = model.sample_function()
    single = np.vstack([one(q[k], v[k], a[k]) for k in range(len(q))])
    np.testing.assert_allclose(single, model.torque(q, v, a), rtol=1e-9, atol=1e-8)


def test_bad_identification_settings_are_refused_naming_the_key():
    with pytest.raises(ConfigError, match='friction'):
        IdentificationConfig(friction=('wet',))
    with pytest.raises(ConfigError, match='balancer_ratios'):
        IdentificationConfig(balancer_ratios=(1.5,))
    with pytest.raises(ConfigError, match='iterations'):
        IdentificationConfig(iterations=0)
