"""Motor/joint side conversions of drives.py: explicit numbers and hypothesis properties."""

from __future__ import annotations

import re
import tokenize
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays
from support import REPO

from id_learning.robot import (
    DriveConfig,
    RobotConfig,
    current_from_motor_torque,
    motor_torque_from_current,
    rotor_inertia_torque,
)
from id_learning.robot.drives import (
    amperes_per_newton_metre,
    joint_from_motor_motion,
    joint_torque_from_motor_side,
    reduction_matrix,
    rotor_basis,
    rotor_inertia_joint_side,
    torque_per_ampere,
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


@st.composite
def coupled_case(draw: st.DrawFn) -> tuple:
    """A reduction K = diag(N) C of 2..4 joints with a well-conditioned coupling, and a batch."""
    n = draw(st.integers(2, 4))
    gear = draw(arrays(np.float64, n, elements=GEAR_RATIOS))
    off = draw(arrays(np.float64, (n, n), elements=st.floats(-0.3, 0.3)))
    coupling = np.eye(n) + np.triu(off, 1)  # unit upper-triangular, as wrist couplings are
    rows = st.floats(-5.0, 5.0)
    batch = draw(st.integers(1, 4))
    return (
        reduction_matrix(gear, coupling),
        draw(arrays(np.float64, (batch, n), elements=rows)),
        draw(arrays(np.float64, (batch, n), elements=rows)),
    )


@settings(max_examples=100, deadline=None, derandomize=True)
@given(coupled_case())
def test_coupled_drives_conserve_power(case: tuple) -> None:
    """The motors' power tau_m . theta_dot is the joints' tau_j . q_dot (virtual work)."""
    reduction, motor_rate, torque_motor_side = case

    q_dot = joint_from_motor_motion(motor_rate, reduction)
    tau_joint = joint_torque_from_motor_side(torque_motor_side, reduction)

    np.testing.assert_allclose(q_dot @ reduction.T, motor_rate, rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(
        np.sum(tau_joint * q_dot, axis=1),
        np.sum(torque_motor_side * motor_rate, axis=1),
        rtol=1e-9,
        atol=1e-6,
    )


def test_uncoupled_reduction_divides_by_the_gear_ratio() -> None:
    reduction = reduction_matrix(np.array([100.0, 50.0]))

    np.testing.assert_allclose(
        joint_from_motor_motion(np.array([[200.0, -25.0]]), reduction), [[2.0, -0.5]]
    )
    np.testing.assert_allclose(
        joint_torque_from_motor_side(np.array([[1.5, 2.0]]), reduction), [[150.0, 100.0]]
    )


def test_reflected_inertia_and_rotor_basis_with_explicit_numbers() -> None:
    drives = DriveConfig(np.array([205.0, 81.0]), np.array([2.05, 0.98]), np.array([3.5e-3, 1e-3]))

    np.testing.assert_allclose(
        rotor_inertia_joint_side(drives.rotor_inertia, drives.gear_ratio),
        [3.5e-3 * 205.0**2, 1e-3 * 81.0**2],
        rtol=1e-12,
    )
    np.testing.assert_allclose(rotor_basis(np.array([2.0, -1.0]), drives.gear_ratio),
                               [2.0 * 205.0**2, -(81.0**2)], rtol=1e-12)  # fmt: skip
    np.testing.assert_allclose(torque_per_ampere(drives), [205 * 2.05, 81 * 0.98], rtol=1e-12)
    np.testing.assert_allclose(
        amperes_per_newton_metre(drives) * torque_per_ampere(drives), 1.0, rtol=1e-12
    )


#: Inline motor/joint conversions: N * k_t, N**2, or J * N**2 written out of drives.py.
_INLINE = re.compile(
    r'gear(_ratio)?\s*\*\*\s*2|gear(_ratio)?\s*\*\s*[\w.\[\]]*torque_constant'
    r'|torque_constant\s*\*\s*[\w.\[\]]*gear'
)


def _code_lines(path: Path) -> dict[int, str]:
    """Each line's code tokens, strings and comments left out (docstrings state the formulas)."""
    lines: dict[int, list[str]] = {}
    with path.open('rb') as stream:
        for token in tokenize.tokenize(stream.readline):
            if token.type in (tokenize.NAME, tokenize.OP, tokenize.NUMBER):
                lines.setdefault(token.start[0], []).append(token.string)
    return {number: ''.join(parts) for number, parts in lines.items()}


def test_motor_joint_conversions_live_in_drives_only() -> None:
    """Every conversion goes through robot/drives.py, so a convention changes in one place."""
    found = []
    for path in sorted((REPO / 'id_learning').rglob('*.py')):
        if path.name == 'drives.py' and path.parent.name == 'robot':
            continue
        for number, code in _code_lines(path).items():
            if _INLINE.search(code):
                found.append(f'{path.relative_to(REPO)}:{number}: {code}')
    assert not found, 'convert with id_learning.robot.drives:\n' + '\n'.join(found)


def test_the_conversion_check_finds_an_inline_conversion(tmp_path: Path) -> None:
    source = tmp_path / 'inline.py'
    source.write_text('"""tau = gear_ratio * torque_constant * i"""\n'
                      'tau = drives.gear_ratio * drives.torque_constant * i\n'
                      'rotor = j * gear ** 2  # reflected\n', encoding='utf-8')  # fmt: skip

    hits = [n for n, code in _code_lines(source).items() if _INLINE.search(code)]

    assert hits == [2, 3]
