"""The package's exceptions: one base class, one subclass per boundary."""

from __future__ import annotations

__all__ = [
    'BagError',
    'CheckpointError',
    'ConfigError',
    'DatasetError',
    'IdLearningError',
    'RobotModelError',
    'TrainingError',
]


class IdLearningError(Exception):
    """Base of every error id_learning raises on purpose."""


class ConfigError(IdLearningError):
    """A configuration file or value is invalid: names the file, key, value and allowed range."""


class RobotModelError(IdLearningError):
    """The URDF and the robot config disagree (joints, limits, drives)."""


class BagError(IdLearningError):
    """A bag is missing, truncated, corrupt, or breaks the bag contract: names file and topic."""


class DatasetError(IdLearningError):
    """Recorded samples are unusable (NaN, stamps, gaps, length): names topic, joint, sample."""


class CheckpointError(IdLearningError):
    """A model artifact is not what it claims or does not match the robot."""


class TrainingError(IdLearningError):
    """No model of a run could be fitted (each one's reason is in the message)."""
