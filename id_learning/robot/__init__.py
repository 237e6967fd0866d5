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
from id_learning.robot.urdf_checks import check_urdf
from id_learning.robot.urdf_inertials import check_urdf_inertials

__all__ = [
    'DriveConfig',
    'JointLimits',
    'RobotConfig',
    'TopicConfig',
    'check_urdf',
    'check_urdf_inertials',
    'current_from_motor_torque',
    'load_robot_config',
    'motor_torque_from_current',
    'rotor_inertia_torque',
]
