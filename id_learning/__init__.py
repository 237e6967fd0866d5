"""id_learning: learn an industrial robot's inverse dynamics and predict the motor torque tau_u.

Data flow: record -> dataset -> models -> evaluation/diagnosis -> predictor -> nodes. The core
(everything but ``id_learning.nodes``) imports no rclpy.
"""

from __future__ import annotations

from id_learning.errors import (
    BagError,
    CheckpointError,
    ConfigError,
    DatasetError,
    IdLearningError,
    RobotModelError,
)

__version__ = '0.1.0'

__all__ = [
    'BagError',
    'CheckpointError',
    'ConfigError',
    'DatasetError',
    'IdLearningError',
    'RobotModelError',
    '__version__',
]
