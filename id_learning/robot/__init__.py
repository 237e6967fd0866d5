"""Robot description: config (URDF, joints, drives, limits) and the drive-side conversions."""

from __future__ import annotations

from id_learning.robot.config import (
    DriveConfig,
    JointLimits,
    RobotConfig,
    TopicConfig,
    load_robot_config,
)
from id_learning.robot.drives import (
    current_from_motor_torque,
    motor_torque_from_current,
    rotor_inertia_torque,
)

__all__ = [
    'DriveConfig',
    'JointLimits',
    'RobotConfig',
    'TopicConfig',
    'current_from_motor_torque',
    'load_robot_config',
    'motor_torque_from_current',
    'rotor_inertia_torque',
]
