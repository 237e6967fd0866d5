"""Effect-term columns against closed forms, finite differences and pinocchio itself."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from id_learning.errors import RobotModelError
from id_learning.physics import AugmentedModel, EffectSpec, NominalModel, effect_columns
from id_learning.physics.inertial import inertial_base_directions, transform_dynamic_parameters

N_SAMPLES = 60
J = 1  # the joint the per-joint columns are checked on (joint_2: gravity acts there)


@pytest.fixture(scope='module')
def model(mabi):
    return NominalModel(mabi)


def motion(robot, t: np.ndarray):
    """Smooth per-joint sinusoids inside the limits, with exact derivatives up to the jerk."""
    n = robot.n_joints
    mid = 0.5 * (robot.limits.position_lower + robot.limits.position_upper)
    amplitude = 0.3 * np.ones(n)
    omega = 2 * np.pi * (0.1 + 0.03 * np.arange(n))
    phase = 0.4 * np.arange(n)
    arg = np.outer(t, omega) + phase
    q = mid + amplitude * np.sin(arg)
    v = amplitude * omega * np.cos(arg)
    a = -amplitude * omega**2 * np.sin(arg)
    jerk = -amplitude * omega**3 * np.cos(arg)
    return q, v, a, jerk


@pytest.fixture(scope='module')
def quantities(model):
    t = np.linspace(0.0, 9.0, N_SAMPLES)
    q, v, a, jerk = motion(model.robot, t)
    return model.evaluate(q, v, a, jerk, derivatives=True, regressor=True)


def spec(name: str, robot, **settings) -> EffectSpec:
    return EffectSpec(name, J, robot.joints[J], settings)


def only_on_joint(x: np.ndarray) -> np.ndarray:
    others = np.delete(x, J, axis=1)
    assert not np.any(others)
    return x[:, J, :]


def test_friction_and_drive_columns_match_their_closed_forms(model, quantities):
    robot, qs = model.robot, quantities
    v, eps = qs.v[:, J], 0.005
    gear = robot.drives.gear_ratio[J]
    expected = {
        'viscous_friction': ({}, v[:, None]),
        'coulomb_friction': ({'smoothing_velocity': eps}, np.tanh(v / eps)[:, None]),
        'stribeck_friction': (
            {'velocity': 0.03, 'smoothing_velocity': eps},
            (np.exp(-((v / 0.03) ** 2)) * np.tanh(v / eps))[:, None],
        ),
        'load_dependent_friction': (
            {'smoothing_velocity': eps},
            (np.abs(qs.tau_rigid[:, J]) * np.tanh(v / eps))[:, None],
        ),
        'rotor_inertia': ({}, (gear**2 * qs.a[:, J])[:, None]),
        'torque_constant_scale': ({}, qs.tau_nominal[:, J][:, None]),
        'torque_offset': ({}, np.ones((N_SAMPLES, 1))),
        'cogging': (
            {'periods_per_motor_turn': 6},
            np.column_stack([np.sin(6 * gear * qs.q[:, J]), np.cos(6 * gear * qs.q[:, J])]),
        ),
        'gravity_spring': (
            {'reference_rad': 0.1, 'degree': 3},
            np.column_stack([(qs.q[:, J] - 0.1) ** k for k in (1, 2, 3)]),
        ),
    }
    for name, (settings, closed_form) in expected.items():
        columns = effect_columns(spec(name, robot, **settings), qs, model)
        np.testing.assert_allclose(only_on_joint(columns), closed_form, rtol=1e-12, atol=1e-12)


def test_joint_offset_column_is_the_position_derivative_of_the_rigid_body_torque(
    model, quantities
):
    qs, h = quantities, 1e-6
    step = np.zeros(model.robot.n_joints)
    step[J] = h
    finite = (
        model.dynamics.rnea(qs.q + step, qs.v, qs.a) - model.dynamics.rnea(qs.q - step, qs.v, qs.a)
    ) / (2 * h)
    columns = effect_columns(spec('joint_offset', model.robot), qs, model)
    assert columns.shape == (N_SAMPLES, model.robot.n_joints, 1)
    np.testing.assert_allclose(columns[:, :, 0], finite, rtol=1e-5, atol=1e-4)


def test_signal_delay_column_is_minus_the_time_derivative_of_the_nominal_torque(model):
    t, h = np.linspace(0.0, 9.0, N_SAMPLES), 1e-5

    def nominal(times):
        return model.evaluate(*motion(model.robot, times)).tau_nominal

    finite = (nominal(t + h) - nominal(t - h)) / (2 * h)
    quantities = model.evaluate(*motion(model.robot, t), derivatives=True)
    columns = effect_columns(EffectSpec('signal_delay'), quantities, model)
    np.testing.assert_allclose(-columns[:, :, 0], finite, rtol=1e-5, atol=1e-3)


@pytest.mark.parametrize('jerk', [0.0, 1.0], ids=['constant acceleration', 'constant jerk'])
def test_a_whole_model_delay_is_the_torque_of_the_motion_it_holds_back(mabi, jerk):
    """The state d back is second order in q and v, first in a: exact at constant acceleration;
    at constant jerk off only by q's d^3 / 6 term. The delayed model's torque is the undelayed
    one's on the motion d earlier, friction and nominal torque alike."""
    rng = np.random.default_rng(4)
    n, d = mabi.n_joints, 0.024  # three IPO cycles
    q0, v0, a0 = rng.uniform(-0.5, 0.5, (3, n))
    j0 = jerk * rng.uniform(-1.0, 1.0, n)
    t = np.linspace(0.0, 2.0, 15)[:, None]

    def state(times: np.ndarray) -> tuple[np.ndarray, ...]:
        return (
            q0 + v0 * times + a0 * times**2 / 2 + j0 * times**3 / 6,
            v0 + a0 * times + j0 * times**2 / 2,
            a0 + j0 * times,
            j0 + 0 * times,
        )

    # Heavy viscous friction: a wrong jerk term in the velocity d back costs N*m.
    friction = [
        (EffectSpec('viscous_friction', j, mabi.joints[j]), np.array([2e4])) for j in range(n)
    ] + [
        (EffectSpec('coulomb_friction', j, mabi.joints[j], {'smoothing_velocity': 0.005}),
         np.array([50.0]))
        for j in range(n)
    ]  # fmt: skip
    delay = EffectSpec('signal_delay', settings={'rate_of': 'model'})
    delayed = AugmentedModel(mabi, 'motor', [*friction, (delay, np.array([d]))])
    undelayed = AugmentedModel(mabi, 'motor', friction)
    # q's d^3 / 6 jerk (2.3 urad per rad/s^3) through a gravity slope of a few kN*m/rad.
    tolerance = 1e-8 if jerk == 0 else 0.05
    np.testing.assert_allclose(
        delayed.torque(*state(t)), undelayed.torque(*state(t - d)[:3]), rtol=0, atol=tolerance
    )


def test_payload_columns_reproduce_a_point_mass_that_pinocchio_attaches(model, quantities):
    robot, qs = model.robot, quantities
    mass, com = 12.0, np.array([0.12, -0.03, 0.05])
    heavier = model.dynamics.with_payload(robot.payload_frame, mass, com)
    truth = heavier.rnea(qs.q, qs.v, qs.a) - qs.tau_rigid
    payload = EffectSpec(
        'payload_mass', settings={'frame': robot.payload_frame, 'com_guess_m': com.tolist()}
    )
    columns = effect_columns(payload, qs, model)
    np.testing.assert_allclose(columns @ np.r_[mass, mass * com], truth, rtol=1e-9, atol=1e-8)


def test_inertial_columns_reproduce_any_change_of_the_link_parameters(model, quantities):
    qs = quantities
    base, null = inertial_base_directions(model.dynamics, model.robot.limits)
    masses, coms = model.dynamics.body_masses_and_coms()
    rng = np.random.default_rng(11)
    changed = model.dynamics.with_masses_and_coms(
        masses * (1 + 0.05 * rng.standard_normal(masses.shape)),
        coms + 0.02 * rng.standard_normal(coms.shape),
    )
    change = changed.inertial_parameters() - model.dynamics.inertial_parameters()
    theta = np.linalg.lstsq(np.hstack([base, null]), change, rcond=None)[0][: base.shape[1]]
    spec_ = EffectSpec('inertial_parameter_error', settings={'base_directions': base.tolist()})
    columns = effect_columns(spec_, qs, model)
    truth = changed.rnea(qs.q, qs.v, qs.a) - qs.tau_rigid
    np.testing.assert_allclose(columns @ theta, truth, rtol=1e-7, atol=1e-6)
    # the null directions never move a torque
    np.testing.assert_allclose(qs.regressor @ null, 0.0, atol=1e-8)
    assert base.shape[1] + null.shape[1] == base.shape[0]


def test_dynamic_parameters_move_between_frames_like_pinocchio_does():
    rng = np.random.default_rng(2)
    rotation = pin.rpy.rpyToMatrix(*rng.uniform(-np.pi, np.pi, 3))
    translation = rng.uniform(-0.5, 0.5, 3)
    body = pin.Inertia(3.0, rng.uniform(-0.2, 0.2, 3), np.diag([0.1, 0.2, 0.25]))
    moved = pin.SE3(rotation, translation).act(body).toDynamicParameters()
    np.testing.assert_allclose(
        transform_dynamic_parameters(body.toDynamicParameters(), rotation, translation),
        moved,
        rtol=1e-12,
        atol=1e-12,
    )


def test_an_effect_spec_round_trips_through_json_and_refuses_a_foreign_joint(model):
    joints = model.robot.joints
    original = EffectSpec('cogging', 2, joints[2], {'periods_per_motor_turn': 12})
    again = EffectSpec.from_dict(original.to_dict(), joints)
    assert (again.name, again.joint, again.label) == (original.name, 2, original.label)
    with pytest.raises(RobotModelError, match='joint_3'):
        EffectSpec.from_dict(original.to_dict(), ('a', 'b'))
