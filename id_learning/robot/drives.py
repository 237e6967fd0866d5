"""The one place that converts between the motor and joint sides of a drive.

With gear ratio N (motor turns per joint turn), torque constant k_t [N*m/A] at the motor and
motor current i [A], the motor torque expressed on the joint side is

    tau_u = N * k_t * i            [N*m], joint side,

and the rotor inertia J_m [kg*m^2] at the motor shaft acts on the joint side as

    tau_rotor = J_m * N**2 * a     [N*m], with a the joint acceleration [rad/s^2].

Coupled wrists (one motor moving several joints) generalise N to a reduction matrix
K = diag(N) @ C: motor angles theta = K q, and motor-side torques tau_m give the joint torques
K^T tau_m.
"""

from __future__ import annotations

import numpy as np

from id_learning.robot.config import DriveConfig

__all__ = [
    'amperes_per_newton_metre',
    'current_from_motor_torque',
    'joint_from_motor_motion',
    'joint_torque_from_motor_side',
    'motor_torque_from_current',
    'reduction_matrix',
    'rotor_basis',
    'rotor_inertia_joint_side',
    'rotor_inertia_torque',
    'torque_per_ampere',
]


def torque_per_ampere(drives: DriveConfig) -> np.ndarray:
    """N * k_t (n,) [N*m/A]: the joint-side motor torque of one ampere, per joint."""
    out: np.ndarray = np.asarray(drives.gear_ratio) * np.asarray(drives.torque_constant)
    return out


def amperes_per_newton_metre(drives: DriveConfig) -> np.ndarray:
    """1 / (N * k_t) (n,) [A/(N*m)]: the current for one N*m of joint-side motor torque."""
    out: np.ndarray = 1.0 / torque_per_ampere(drives)
    return out


def motor_torque_from_current(current_a: np.ndarray, drives: DriveConfig) -> np.ndarray:
    """Motor torque tau_u [N*m] (joint side) from motor currents (..., n) [A]."""
    out: np.ndarray = np.asarray(current_a) * torque_per_ampere(drives)
    return out


def current_from_motor_torque(tau_u: np.ndarray, drives: DriveConfig) -> np.ndarray:
    """Motor currents [A] from motor torques tau_u (..., n) [N*m] (joint side)."""
    out: np.ndarray = np.asarray(tau_u) / torque_per_ampere(drives)
    return out


def rotor_inertia_joint_side(
    rotor_inertia_motor_side: np.ndarray | float, gear_ratio: np.ndarray | float
) -> np.ndarray:
    """J_m * N**2 [kg*m^2]: a rotor's inertia as the joint sees it."""
    out: np.ndarray = np.asarray(rotor_inertia_motor_side) * np.asarray(gear_ratio) ** 2
    return out


def rotor_basis(a: np.ndarray, gear_ratio: np.ndarray | float) -> np.ndarray:
    """N**2 * a (..., n) [N*m per kg*m^2]: the rotor torque per unit motor-side inertia."""
    out: np.ndarray = np.asarray(a) * np.asarray(gear_ratio) ** 2
    return out


def rotor_inertia_torque(
    a: np.ndarray, rotor_inertia_motor_side: np.ndarray, gear_ratio: np.ndarray
) -> np.ndarray:
    """Joint-side torque [N*m] to accelerate the rotors: J_m * N**2 * a, a (..., n) [rad/s^2]."""
    out: np.ndarray = np.asarray(a) * rotor_inertia_joint_side(
        rotor_inertia_motor_side, gear_ratio
    )
    return out


def reduction_matrix(gear_ratio: np.ndarray, coupling: np.ndarray | None = None) -> np.ndarray:
    """K = diag(N) @ C (n, n): motor angles per joint angle; C the identity when uncoupled."""
    gear = np.asarray(gear_ratio, dtype=float)
    couple = np.eye(len(gear)) if coupling is None else np.asarray(coupling, dtype=float)
    out: np.ndarray = gear[:, None] * couple
    return out


def joint_from_motor_motion(motor: np.ndarray, reduction: np.ndarray) -> np.ndarray:
    """Joint angles or rates (..., n) from the motors' (..., n): q = K^-1 theta."""
    out: np.ndarray = np.asarray(motor) @ np.linalg.inv(reduction).T
    return out


def joint_torque_from_motor_side(
    torque_motor_side: np.ndarray, reduction: np.ndarray
) -> np.ndarray:
    """Joint torques (..., n) [N*m] from motor-shaft torques (..., n) [N*m]: K^T tau_m."""
    out: np.ndarray = np.asarray(torque_motor_side) @ reduction
    return out
