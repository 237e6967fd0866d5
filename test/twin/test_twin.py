"""The digital twin against an independent model built here from pinocchio and closed forms."""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pinocchio as pin
import pytest
import yaml
from support import REPO, twin_config

from id_learning.dataset.recording import load_recording
from id_learning.errors import ConfigError
from id_learning.record.excitation import ExcitationTrajectory
from id_learning.twin import (
    GROUND_TRUTH_ARRAYS,
    GROUND_TRUTH_JSON,
    load_twin_config,
    simulate,
    write_twin_output,
)

QUIET = {
    'measurement': {
        'current_noise_std_a': 0.0,
        'current_resolution_a': 0.0,
        'encoder_counts_per_motor_turn': 0,
        'velocity_noise_std': 0.0,
    }
}


def true_motion(result, period_s: float, shift_s: float = 0.0):
    """q, v, a of the twin's excitation, re-evaluated from the ground-truth coefficients."""
    trajectory = ExcitationTrajectory.from_dict(result.parameters['excitation'])
    t = np.arange(result.recording.n_samples) * period_s - shift_s
    return trajectory.evaluate(t)


def pinocchio_rnea(q: np.ndarray, v: np.ndarray, a: np.ndarray) -> np.ndarray:
    model = pin.buildModelFromUrdf(str(REPO / 'urdf/mabi_max100.urdf'))
    data = model.createData()
    return np.array([pin.rnea(model, data, *row) for row in zip(q, v, a, strict=True)])


def test_twin_currents_match_an_independent_drive_and_friction_model(mabi):
    d = np.array([400.0, 500.0, 300.0, 60.0, 40.0, 20.0])
    fc = np.array([150.0, 200.0, 100.0, 25.0, 20.0, 8.0])
    scale = np.array([1.03, 0.97, 1.02, 1.04, 0.98, 1.01])
    rotor_scale = np.array([1.2, 1.3, 1.1, 1.2, 1.2, 1.2])
    offset = np.array([10.0, -15.0, 5.0, 1.0, -1.0, 0.5])
    effects = {
        'viscous_friction': {'enabled': True, 'coefficient': d.tolist()},
        'coulomb_friction': {'enabled': True, 'level': fc.tolist(), 'smoothing_velocity': 0.01},
        'rotor_inertia': {'enabled': True, 'scale': rotor_scale.tolist()},
        'torque_constant_scale': {'enabled': True, 'scale': scale.tolist()},
        'torque_offset': {'enabled': True, 'offset': offset.tolist()},
    }
    result = simulate(twin_config(30.0, effects, **QUIET))
    q, v, a = true_motion(result, mabi.ipo_period_s)
    n, kt, jm = mabi.drives.gear_ratio, mabi.drives.torque_constant, mabi.drives.rotor_inertia
    motor = pinocchio_rnea(q, v, a) + jm * rotor_scale * n**2 * a + d * v + fc * np.tanh(v / 0.01)
    expected_current = motor / (n * kt * scale) + offset / (n * kt)
    assert result.recording.n_samples > 3000
    np.testing.assert_allclose(result.recording.current, expected_current, rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(result.recording.position, q, rtol=0, atol=1e-12)
    np.testing.assert_allclose(result.recording.velocity, v, rtol=0, atol=1e-12)


def test_nominal_twin_without_effects_equals_the_urdf_model_plus_datasheet_drives(mabi):
    result = simulate(twin_config(30.0, {}, **QUIET))
    q, v, a = true_motion(result, mabi.ipo_period_s)
    n, kt, jm = mabi.drives.gear_ratio, mabi.drives.torque_constant, mabi.drives.rotor_inertia
    expected = pinocchio_rnea(q, v, a) + jm * n**2 * a
    np.testing.assert_allclose(result.tau_u_clean, expected, rtol=1e-10, atol=1e-8)
    np.testing.assert_allclose(result.recording.current * n * kt, expected, rtol=1e-10, atol=1e-8)


def test_the_rigid_body_config_is_the_default_twin_with_every_effect_off_and_torque_sensors():
    rigid = load_twin_config(REPO / 'config/twin_rigid_body.yaml')
    default = load_twin_config(REPO / 'config/twin_default.yaml')
    assert rigid.effects.enabled_names() == []
    assert rigid.joint_torque_sensors
    assert rigid.robot.name == default.robot.name
    assert rigid.excitation == default.excitation
    assert set(rigid.effects.effects) == set(default.effects.effects)


def test_components_sum_to_the_clean_motor_torque(short_twin):
    _, result = short_twin
    total = np.sum(list(result.components.values()), axis=0)
    np.testing.assert_allclose(total, result.tau_u_clean, rtol=1e-12, atol=1e-9)
    assert set(result.components) >= {'gravity', 'viscous_friction', 'gravity_spring', 'cogging'}


def test_signal_delay_makes_currents_lag_the_positions(mabi):
    period = mabi.ipo_period_s
    plain = simulate(twin_config(30.0, {}, **QUIET))
    delayed = simulate(
        twin_config(30.0, {'signal_delay': {'enabled': True, 'delay_s': 2 * period}}, **QUIET)
    )
    np.testing.assert_array_equal(delayed.recording.position, plain.recording.position)
    np.testing.assert_allclose(
        delayed.recording.current[2:], plain.recording.current[:-2], rtol=1e-9, atol=1e-9
    )
    assert not np.allclose(delayed.recording.current, plain.recording.current)


def test_joint_offset_shifts_the_measured_positions_only(mabi):
    offset = np.array([0.01, -0.02, 0.0, 0.005, 0.0, -0.01])
    plain = simulate(twin_config(30.0, {}, **QUIET))
    shifted = simulate(
        twin_config(30.0, {'joint_offset': {'enabled': True, 'offset': offset.tolist()}}, **QUIET)
    )
    np.testing.assert_allclose(
        shifted.recording.position, plain.recording.position - offset, atol=1e-12
    )
    np.testing.assert_array_equal(shifted.recording.current, plain.recording.current)


def test_gravity_spring_torque_follows_its_closed_form(mabi):
    spring = {
        'enabled': True,
        'joint': 'joint_2',
        'arm_base_m': 0.3,
        'arm_link_m': 0.5,
        'phase_rad': 0.1,
        'preload_n': 2000.0,
        'stiffness_n_per_m': 30000.0,
    }
    plain = simulate(twin_config(30.0, {}, **QUIET))
    sprung = simulate(twin_config(30.0, {'gravity_spring': spring}, **QUIET))
    q2 = plain.q_true[:, 1] + 0.1
    # Law of cosines for the spring length; the moment arm is a*b*sin(angle)/length.
    length = np.sqrt(0.5**2 + 0.3**2 - 2 * 0.5 * 0.3 * np.cos(q2))
    force = 2000.0 + 30000.0 * (length - 0.2)
    spring_torque = -force * 0.5 * 0.3 * np.sin(q2) / length
    difference = sprung.tau_u_clean - plain.tau_u_clean
    np.testing.assert_allclose(difference[:, 1], -spring_torque, rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(np.delete(difference, 1, axis=1), 0.0, atol=1e-9)


def test_load_dependent_friction_grows_with_the_transmitted_torque():
    mu = [0.05, 0.04, 0.03, 0.02, 0.02, 0.02]
    result = simulate(
        twin_config(
            30.0,
            {
                'load_dependent_friction': {
                    'enabled': True,
                    'coefficient': mu,
                    'smoothing_velocity': 0.01,
                }
            },
            **QUIET,
        )
    )
    expected = np.array(mu) * np.abs(result.tau_joint_clean) * np.tanh(result.v_true / 0.01)
    np.testing.assert_allclose(
        result.components['load_dependent_friction'], expected, rtol=1e-12, atol=1e-9
    )


def test_current_noise_and_quantisation_have_the_configured_size(mabi):
    noisy = simulate(twin_config(30.0, {}))
    config = noisy_config = twin_config(30.0, {})
    del noisy_config
    clean_current = noisy.tau_u_clean / (mabi.drives.gear_ratio * mabi.drives.torque_constant)
    error = noisy.recording.current - clean_current
    expected_std = np.sqrt(
        config.measurement.current_noise_std_a**2 + config.measurement.current_resolution_a**2 / 12
    )
    np.testing.assert_allclose(error.std(axis=0), expected_std, rtol=0.05)
    steps = noisy.recording.current / config.measurement.current_resolution_a
    np.testing.assert_allclose(steps, np.round(steps), atol=1e-6)
    counts = config.measurement.encoder_counts_per_motor_turn
    ticks = noisy.recording.position / (2 * np.pi / (counts * mabi.drives.gear_ratio))
    np.testing.assert_allclose(ticks, np.round(ticks), atol=1e-6)


def test_joint_torque_sensors_put_measured_joint_torques_in_effort():
    with_sensors = simulate(twin_config(30.0, joint_torque_sensors=True))
    without = simulate(twin_config(30.0))
    assert without.recording.joint_torque is None
    error = with_sensors.recording.joint_torque - with_sensors.tau_joint_clean
    noise = twin_config(30.0).measurement.joint_torque_noise_std
    assert np.all(np.abs(error.std(axis=0) - noise) < 0.1 * noise)


def test_same_seed_gives_the_same_bag_and_another_seed_does_not(tmp_path):
    config = twin_config(12.0)
    first = write_twin_output(simulate(config), config, tmp_path / 'a')
    second = write_twin_output(simulate(config), config, tmp_path / 'b')
    other_config = replace(config, seed=config.seed + 1)
    other = write_twin_output(simulate(other_config), other_config, tmp_path / 'c')
    assert (first / 'a_0.mcap').read_bytes() == (second / 'b_0.mcap').read_bytes()
    assert (first / GROUND_TRUTH_JSON).read_bytes() == (second / GROUND_TRUTH_JSON).read_bytes()
    assert (first / 'a_0.mcap').stat().st_size > 10_000
    assert (first / 'a_0.mcap').read_bytes() != (other / 'c_0.mcap').read_bytes()


def test_excessive_effects_beyond_the_torque_limits_are_refused():
    effects = {'viscous_friction': {'enabled': True, 'coefficient': 1e5}}
    with pytest.raises(ConfigError, match='beyond its limit'):
        simulate(twin_config(30.0, effects))


def test_unknown_effect_names_and_keys_are_refused():
    with pytest.raises(ConfigError, match=r'unknown effect.*friction_magic'):
        twin_config(30.0, {'friction_magic': {'enabled': True}})
    with pytest.raises(ConfigError, match=r'viscous_friction: unknown key.*coeff'):
        twin_config(30.0, {'viscous_friction': {'enabled': True, 'coeff': 3.0}})
    with pytest.raises(ConfigError, match=r'gravity_spring\.joint'):
        twin_config(30.0, {'gravity_spring': {'enabled': True, 'joint': 'joint_9'}})


def test_ground_truth_is_written_beside_the_bag_and_its_config_reloads(tmp_path, mabi):
    config, result = twin_config(12.0), None
    result = simulate(config)
    out = write_twin_output(result, config, tmp_path / 'twin')
    truth = json.loads((out / GROUND_TRUTH_JSON).read_text())
    assert truth['effects_enabled'] == config.effects.enabled_names()
    assert truth['joints'] == list(mabi.joints)
    with np.load(out / GROUND_TRUTH_ARRAYS) as arrays:
        np.testing.assert_allclose(arrays['tau_u_clean'], result.tau_u_clean, rtol=1e-6, atol=1e-3)
        np.testing.assert_array_equal(arrays['stamps_ns'], result.recording.stamps_ns)
    reloaded = load_twin_config(out / 'twin_config.yaml')
    assert reloaded.seed == config.seed
    assert yaml.safe_load((out / 'twin_config.yaml').read_text())['robot'].endswith(
        'mabi_max100.yaml'
    )


def test_shipped_default_bag_is_reproduced_by_its_own_config(mabi):
    bag = REPO / 'bags/default'
    config = load_twin_config(bag / 'twin_config.yaml')
    result = simulate(config)
    recorded = load_recording(bag, mabi)
    assert 540.0 < recorded.duration_s < 660.0
    np.testing.assert_array_equal(recorded.stamps_ns, result.recording.stamps_ns)
    np.testing.assert_array_equal(recorded.position, result.recording.position)
    np.testing.assert_array_equal(recorded.current, result.recording.current)


@pytest.mark.parametrize('value', [-1, 1.5, 'five', True])
def test_a_robot_seed_that_is_no_non_negative_integer_is_refused(value):
    with pytest.raises(ConfigError, match=r'robot_seed must be a non-negative integer'):
        load_twin_config(REPO / 'config/twin_default.yaml', {'robot_seed': value})


def test_robot_seed_equal_to_seed_is_the_one_seed_twin(mabi):
    config = twin_config(4.0)
    same = simulate(replace(config, robot_seed=config.seed))
    np.testing.assert_array_equal(same.recording.current, simulate(config).recording.current)
    other = simulate(replace(config, robot_seed=config.seed + 1))
    np.testing.assert_array_equal(other.recording.position, same.recording.position)
    assert not np.array_equal(other.recording.current, same.recording.current)
