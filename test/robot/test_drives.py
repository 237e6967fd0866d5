"""Motor/joint side conversions of drives.py: explicit numbers and hypothesis properties."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from id_learning.robot import (
    DriveConfig,
    RobotConfig,
    current_from_motor_torque,
    motor_torque_from_current,
    rotor_inertia_torque,
)

GEAR_RATIOS = st.floats(1.0, 500.0)
TORQUE_CONSTANTS = st.floats(0.01, 10.0)
ROTOR_INERTIAS = st.floats(0.0, 0.1)
CURRENTS = st.floats(-200.0, 200.0)  # A
TORQUES = st.floats(-20000.0, 20000.0)  # N*m joint side
ACCELERATIONS = st.floats(-50.0, 50.0)  # rad/s^2


@st.composite
def drives_and_batch(draw: st.DrawFn, values: st.SearchStrategy[float]) -> tuple:
    """A drive config of 1..7 joints and a (B, n) batch drawn from ``values``."""
    n = draw(st.integers(1, 7))
    batch = draw(st.integers(1, 5))
    drives = DriveConfig(
        gear_ratio=draw(arrays(np.float64, n, elements=GEAR_RATIOS)),
        torque_constant=draw(arrays(np.float64, n, elements=TORQUE_CONSTANTS)),
        rotor_inertia=draw(arrays(np.float64, n, elements=ROTOR_INERTIAS)),
    )
    return drives, draw(arrays(np.float64, (batch, n), elements=values))


@settings(max_examples=150, deadline=None, derandomize=True)
@given(drives_and_batch(CURRENTS))
def test_current_to_motor_torque_and_back_is_the_identity(case: tuple) -> None:
    drives, current_a = case

    tau_u = motor_torque_from_current(current_a, drives)
    back = current_from_motor_torque(tau_u, drives)

    assert tau_u.shape == current_a.shape
    np.testing.assert_allclose(back, current_a, rtol=1e-12, atol=1e-12)


@settings(max_examples=150, deadline=None, derandomize=True)
@given(drives_and_batch(TORQUES))
def test_motor_torque_to_current_and_back_is_the_identity(case: tuple) -> None:
    drives, tau_u = case

    current_a = current_from_motor_torque(tau_u, drives)

    np.testing.assert_allclose(
        motor_torque_from_current(current_a, drives), tau_u, rtol=1e-12, atol=1e-9
    )


@settings(max_examples=150, deadline=None, derandomize=True)
@given(drives_and_batch(CURRENTS))
def test_motor_torque_is_gear_ratio_times_torque_constant_times_current(case: tuple) -> None:
    drives, current_a = case

    tau_u = motor_torque_from_current(current_a, drives)

    for b, row in enumerate(current_a):
        for j, current in enumerate(row):
            expected = float(drives.gear_ratio[j]) * float(drives.torque_constant[j]) * current
            assert tau_u[b, j] == pytest.approx(expected, rel=1e-12, abs=1e-12)


@settings(max_examples=150, deadline=None, derandomize=True)
@given(drives_and_batch(ACCELERATIONS))
def test_rotor_torque_is_rotor_inertia_times_squared_gear_ratio_times_acceleration(
    case: tuple,
) -> None:
    drives, a = case

    tau = rotor_inertia_torque(a, drives.rotor_inertia, drives.gear_ratio)

    assert tau.shape == a.shape
    for b, row in enumerate(a):
        for j, acceleration in enumerate(row):
            expected = (
                float(drives.rotor_inertia[j]) * float(drives.gear_ratio[j]) ** 2 * acceleration
            )
            assert tau[b, j] == pytest.approx(expected, rel=1e-12, abs=1e-12)
    # Doubling the gear ratio quadruples the reflected inertia.
    np.testing.assert_allclose(
        rotor_inertia_torque(a, drives.rotor_inertia, 2.0 * drives.gear_ratio),
        4.0 * tau,
        rtol=1e-12,
        atol=1e-12,
    )


@pytest.mark.parametrize(
    ('gear_ratio', 'torque_constant', 'current_a', 'tau_u'),
    [
        (100.0, 0.5, 2.0, 100.0),
        (205.0, 2.05, 1.0, 420.25),
        (81.0, 0.98, -3.0, -238.14),
        (121.0, 1.36, 0.0, 0.0),
    ],
)
def test_motor_torque_from_current_with_explicit_numbers(
    gear_ratio: float, torque_constant: float, current_a: float, tau_u: float
) -> None:
    drives = DriveConfig(np.array([gear_ratio]), np.array([torque_constant]), np.array([0.0]))

    assert motor_torque_from_current(np.array([current_a]), drives)[0] == pytest.approx(
        tau_u, rel=1e-12, abs=1e-12
    )
    if current_a != 0.0:
        assert current_from_motor_torque(np.array([tau_u]), drives)[0] == pytest.approx(
            current_a, rel=1e-12
        )


def test_one_amp_on_every_mabi_motor_gives_the_joint_side_torques(
    robot_configs: dict[str, RobotConfig],
) -> None:
    drives = robot_configs['mabi_max100'].drives

    tau_u = motor_torque_from_current(np.ones(6), drives)

    expected = [205 * 2.05, 220 * 2.05, 185 * 1.85, 121 * 1.36, 112 * 1.36, 81 * 0.98]
    np.testing.assert_allclose(tau_u, expected, rtol=1e-12)


def test_rotor_torque_with_explicit_numbers() -> None:
    # MABI axis 1: J_m = 3.5e-3 kg*m^2 at the motor, N = 205, a = 2 rad/s^2.
    tau = rotor_inertia_torque(np.array([2.0]), np.array([3.5e-3]), np.array([205.0]))

    assert tau[0] == pytest.approx(3.5e-3 * 205.0**2 * 2.0, rel=1e-12)
    assert tau[0] == pytest.approx(294.175, rel=1e-12)
