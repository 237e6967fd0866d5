"""Payloads and link-parameter changes of RigidBodyDynamics, against references."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest
from pinocchio_reference import G_WORLD, payload_frame_setup, random_states, world_axes

from id_learning.errors import RobotModelError
from id_learning.physics import RigidBodyDynamics
from id_learning.robot import RobotConfig


# -- payload, masses and centres of mass ---------------------------------------------------------
def test_point_payload_changes_gravity_by_the_closed_form_torque(
    robot_name: str,
    robot_configs: dict[str, RobotConfig],
    robot_dynamics: dict[str, RigidBodyDynamics],
) -> None:
    config, dynamics = robot_configs[robot_name], robot_dynamics[robot_name]
    mass, com = 7.5, np.array([0.04, -0.03, 0.11])  # kg, m in the payload frame
    loaded = dynamics.with_payload(config.payload_frame, mass, com)

    model, data, index, axes, frame_id, supporting = payload_frame_setup(config)
    assert supporting  # the payload hangs on at least one joint
    q, _, _ = random_states(config, np.random.default_rng(22), count=20)

    expected = np.zeros_like(q)
    for k in range(len(q)):
        q_pin = np.zeros(model.nq)
        q_pin[index] = q[k]
        pin.framesForwardKinematics(model, data, q_pin)
        point = data.oMf[frame_id].act(com)
        for i, name in enumerate(config.joints):
            if name in supporting:
                origin, axis = world_axes(model, data, axes, name)
                # Torque needed to hold the weight m g acting at the point, about the axis.
                expected[k, i] = -mass * G_WORLD @ np.cross(axis, point - origin)

    change = loaded.gravity(q) - dynamics.gravity(q)
    assert np.abs(expected).max() > 1.0
    np.testing.assert_allclose(change, expected, rtol=1e-9, atol=1e-9)


def test_payload_rotational_inertia_leaves_gravity_unchanged_but_not_inertia(
    robot_configs: dict[str, RobotConfig], robot_dynamics: dict[str, RigidBodyDynamics]
) -> None:
    config, dynamics = robot_configs['mabi_max100'], robot_dynamics['mabi_max100']
    q, v, a = random_states(config, np.random.default_rng(23), count=10)
    com = np.array([0.16, 0.0, 0.02])
    point = dynamics.with_payload('flange', 40.0, com)
    solid = dynamics.with_payload('flange', 40.0, com, np.diag([0.12, 0.35, 0.35]))

    np.testing.assert_allclose(solid.gravity(q), point.gravity(q), rtol=1e-12)
    assert np.abs(solid.rnea(q, v, a) - point.rnea(q, v, a)).max() > 1e-3
    assert solid.total_moving_mass() == pytest.approx(dynamics.total_moving_mass() + 40.0)


def test_payload_model_obeys_the_nominal_regressor(
    robot_name: str,
    robot_configs: dict[str, RobotConfig],
    robot_dynamics: dict[str, RigidBodyDynamics],
) -> None:
    # The regressor depends on kinematics only, so it must also predict the loaded robot.
    config, dynamics = robot_configs[robot_name], robot_dynamics[robot_name]
    q, v, a = random_states(config, np.random.default_rng(24), count=10)
    loaded = dynamics.with_payload(config.payload_frame, 3.0, np.array([0.0, 0.05, 0.1]))

    predicted = dynamics.regressor(q, v, a) @ loaded.inertial_parameters()

    tau = loaded.rnea(q, v, a)
    np.testing.assert_allclose(predicted, tau, rtol=0, atol=1e-9 * np.abs(tau).max())


def test_unknown_payload_frame_is_refused(robot_dynamics: dict[str, RigidBodyDynamics]) -> None:
    with pytest.raises(RobotModelError, match="payload frame 'spindle' does not exist"):
        robot_dynamics['mabi_max100'].with_payload('spindle', 1.0, np.zeros(3))


def test_unchanged_masses_and_coms_reproduce_rnea(
    robot_name: str,
    robot_configs: dict[str, RobotConfig],
    robot_dynamics: dict[str, RigidBodyDynamics],
) -> None:
    config, dynamics = robot_configs[robot_name], robot_dynamics[robot_name]
    q, v, a = random_states(config, np.random.default_rng(25), count=20)
    masses, coms = dynamics.body_masses_and_coms()
    assert masses.shape == (dynamics.n_bodies,)
    assert coms.shape == (dynamics.n_bodies, 3)

    same = dynamics.with_masses_and_coms(masses, coms)

    tau = dynamics.rnea(q, v, a)
    np.testing.assert_allclose(same.rnea(q, v, a), tau, rtol=0, atol=1e-10 * np.abs(tau).max())


def test_new_masses_and_coms_are_set_and_rotational_inertia_is_kept(
    robot_dynamics: dict[str, RigidBodyDynamics],
) -> None:
    dynamics = robot_dynamics['mabi_max100']
    masses, coms = dynamics.body_masses_and_coms()
    new_masses = masses * np.linspace(0.9, 1.1, len(masses))
    new_coms = coms + 0.01

    changed = dynamics.with_masses_and_coms(new_masses, new_coms)

    got_masses, got_coms = changed.body_masses_and_coms()
    np.testing.assert_allclose(got_masses, new_masses, rtol=1e-15)
    np.testing.assert_allclose(got_coms, new_coms, rtol=1e-15)
    for body in range(1, dynamics.n_bodies + 1):
        np.testing.assert_allclose(
            changed.model.inertias[body].inertia, dynamics.model.inertias[body].inertia
        )
    assert changed.total_moving_mass() == pytest.approx(new_masses.sum())


def test_inertial_parameters_round_trip_through_with_inertial_parameters(
    robot_configs: dict[str, RobotConfig], robot_dynamics: dict[str, RigidBodyDynamics]
) -> None:
    config, dynamics = robot_configs['ur5'], robot_dynamics['ur5']
    q, v, a = random_states(config, np.random.default_rng(26), count=10)
    parameters = dynamics.inertial_parameters()

    rebuilt = dynamics.with_inertial_parameters(parameters)

    np.testing.assert_allclose(rebuilt.inertial_parameters(), parameters, rtol=1e-12, atol=1e-14)
    np.testing.assert_allclose(rebuilt.rnea(q, v, a), dynamics.rnea(q, v, a), atol=1e-9)


# -- the MABI URDF -------------------------------------------------------------------------------
