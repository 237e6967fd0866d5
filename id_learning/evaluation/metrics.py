"""Error metrics of torque predictions, per joint; pure functions on (N, n) arrays.

Every function takes ``prediction`` and ``target`` of shape (N, n) [N*m] in the robot's joint
order and returns one value per joint (n,), except ``absolute_errors`` (N, n).

The reference study reports RMSEs on the normalised scale its networks are trained on: each
joint's torque mapped onto [-1, 1] by a min/max scaler fitted on the training part, so that an
error e [N*m] reads e / half_range there (``MinMaxScaler.scale()``).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

__all__ = [
    'ErrorMetrics',
    'absolute_errors',
    'error_metrics',
    'mse',
    'nmse',
    'normalised_mse',
    'normalised_rmse',
    'rmse',
]


def _check(prediction: np.ndarray, target: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    prediction = np.asarray(prediction, dtype=float)
    target = np.asarray(target, dtype=float)
    if prediction.shape != target.shape or prediction.ndim != 2:
        raise ValueError(
            f'prediction {prediction.shape} and target {target.shape} must both be (N, n)'
        )
    if len(target) == 0:
        raise ValueError('no samples to compare')
    return prediction, target


def absolute_errors(prediction: np.ndarray, target: np.ndarray) -> np.ndarray:
    """|prediction - target|, (N, n) [N*m]."""
    prediction, target = _check(prediction, target)
    out: np.ndarray = np.abs(prediction - target)
    return out


def mse(prediction: np.ndarray, target: np.ndarray) -> np.ndarray:
    """Mean squared error per joint, (n,) [(N*m)^2]."""
    prediction, target = _check(prediction, target)
    out: np.ndarray = np.mean(np.square(prediction - target), axis=0)
    return out


def rmse(prediction: np.ndarray, target: np.ndarray) -> np.ndarray:
    """Root mean squared error per joint, (n,) [N*m]."""
    out: np.ndarray = np.sqrt(mse(prediction, target))
    return out


def normalised_rmse(prediction: np.ndarray, target: np.ndarray, scale: np.ndarray) -> np.ndarray:
    """RMSE on the study's [-1, 1] scale: RMSE / half range per joint, (n,) [-].

    Args:
        prediction: (N, n) predicted torque [N*m].
        target: (N, n) label torque [N*m].
        scale: (n,) half range of each joint's training labels [N*m] (``MinMaxScaler.scale()``).
    """
    out: np.ndarray = rmse(prediction, target) / _positive_scale(scale)
    return out


def normalised_mse(prediction: np.ndarray, target: np.ndarray, scale: np.ndarray) -> np.ndarray:
    """MSE on the study's [-1, 1] scale (the networks' training loss per joint), (n,) [-]."""
    out: np.ndarray = mse(prediction, target) / np.square(_positive_scale(scale))
    return out


def nmse(prediction: np.ndarray, target: np.ndarray) -> np.ndarray:
    """MSE divided by the target's variance per joint, (n,) [-].

    The nMSE of the inverse-dynamics learning literature: 0 is perfect, 1 is no better than
    predicting the mean. A constant target column (variance 0) gives inf, or 0 when it is met.
    """
    prediction, target = _check(prediction, target)
    error = mse(prediction, target)
    variance = np.var(target, axis=0)
    with np.errstate(divide='ignore', invalid='ignore'):
        ratio = error / variance
    return np.where(variance > 0, ratio, np.where(error > 0, np.inf, 0.0))


def _positive_scale(scale: np.ndarray) -> np.ndarray:
    scale = np.asarray(scale, dtype=float)
    if (scale <= 0).any():
        raise ValueError(f'scale must be > 0 for every joint, got {scale.tolist()}')
    return scale


@dataclass(frozen=True, eq=False)
class ErrorMetrics:
    """Per-joint errors of one model on one set of samples.

    Attributes:
        rmse_nm: (n,) RMSE [N*m].
        rmse_normalised: (n,) RMSE on the study's [-1, 1] scale [-].
        mse_normalised: (n,) MSE on the [-1, 1] scale [-] (the training loss's scale).
        nmse: (n,) MSE / variance of the target [-].
        max_abs_nm: (n,) largest absolute error [N*m].
        n_samples: samples compared.
    """

    rmse_nm: np.ndarray
    rmse_normalised: np.ndarray
    mse_normalised: np.ndarray
    nmse: np.ndarray
    max_abs_nm: np.ndarray
    n_samples: int

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form, with the means over joints."""
        return {
            'rmse_nm': self.rmse_nm.tolist(),
            'rmse_normalised': self.rmse_normalised.tolist(),
            'mse_normalised': self.mse_normalised.tolist(),
            'nmse': self.nmse.tolist(),
            'max_abs_nm': self.max_abs_nm.tolist(),
            'mean_rmse_normalised': float(np.mean(self.rmse_normalised)),
            'mean_mse_normalised': float(np.mean(self.mse_normalised)),
            'mean_nmse': float(np.mean(self.nmse)),
            'n_samples': self.n_samples,
        }


def error_metrics(prediction: np.ndarray, target: np.ndarray, scale: np.ndarray) -> ErrorMetrics:
    """Every per-joint metric of one prediction.

    Args:
        prediction: (N, n) predicted torque [N*m].
        target: (N, n) label torque [N*m].
        scale: (n,) half range of the training labels per joint [N*m].
    """
    prediction, target = _check(prediction, target)
    return ErrorMetrics(
        rmse_nm=rmse(prediction, target),
        rmse_normalised=normalised_rmse(prediction, target, scale),
        mse_normalised=normalised_mse(prediction, target, scale),
        nmse=nmse(prediction, target),
        max_abs_nm=np.max(absolute_errors(prediction, target), axis=0),
        n_samples=len(target),
    )
