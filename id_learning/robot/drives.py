"""The one place that converts between the motor and joint sides of a drive.

With gear ratio N (motor turns per joint turn), torque constant k_t [N*m/A] at the motor and
motor current i [A], the motor torque expressed on the joint side is

    tau_u = N * k_t * i            [N*m], joint side,

and the rotor inertia J_m [kg*m^2] at the motor shaft acts on the joint side as

    tau_rotor = J_m * N**2 * a     [N*m], with a the joint acceleration [rad/s^2].
"""

from __future__ import annotations

import numpy as np

from id_learning.robot.config import DriveConfig

__all__ = ['current_from_motor_torque', 'motor_torque_from_current', 'rotor_inertia_torque']


def motor_torque_from_current(current_a: np.ndarray, drives: DriveConfig) -> np.ndarray:
    """Motor torque tau_u [N*m] (joint side) from motor currents (..., n) [A]."""
    return np.asarray(current_a) * (drives.gear_ratio * drives.torque_constant)


def current_from_motor_torque(tau_u: np.ndarray, drives: DriveConfig) -> np.ndarray:
    """Motor currents [A] from motor torques tau_u (..., n) [N*m] (joint side)."""
    return np.asarray(tau_u) / (drives.gear_ratio * drives.torque_constant)


def rotor_inertia_torque(
    a: np.ndarray, rotor_inertia_motor_side: np.ndarray, gear_ratio: np.ndarray
) -> np.ndarray:
    """Joint-side torque [N*m] to accelerate the rotors: J_m * N**2 * a, a (..., n) [rad/s^2]."""
    return np.asarray(a) * (np.asarray(rotor_inertia_motor_side) * np.asarray(gear_ratio) ** 2)
