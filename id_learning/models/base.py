"""The one interface every inverse-dynamics model implements, and its torque decomposition.

Arrays are (B, n) in the robot's joint order: q [rad], v [rad/s], a [rad/s^2] -> tau [N*m],
joint side; the torque is the model's target (tau_u from currents, or the measured joint torque).
``predict`` gives it as the labels record it, which is what a model is fitted and scored on;
``for_the_drive`` gives the model whose torque is what the drive needs at each instant: a label
that lags the motion (currents measured late) is learned with its lag, which a feed-forward must
leave out.
Models follow the estimator contract: the constructor stores settings and does no I/O, fit()
returns self, fitted state lives in attributes ending in ``_``.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Callable
from dataclasses import dataclass, fields
from typing import Any, ClassVar, Protocol, Self, runtime_checkable

import numpy as np

from id_learning.models.data import TrainingData
from id_learning.robot.config import RobotConfig

__all__ = [
    'InverseDynamicsModel',
    'ModelConfig',
    'SamplePredictor',
    'SequenceModel',
    'SequenceStream',
    'TorqueComponents',
    'as_sequence_model',
]

#: One sample's torque: q, v, a (n,) [rad, rad/s, rad/s^2] -> tau (n,) [N*m], float64.
SamplePredictor = Callable[[np.ndarray, np.ndarray, np.ndarray], np.ndarray]


class SequenceStream(Protocol):
    """The online form of a sequence model: one input row in, that sample's torque out."""

    def reset(self) -> None:
        """Forget the past samples (the next push starts a new window)."""

    def prepare(self) -> None:
        """Do ahead of the next push what does not depend on its row."""

    def push(self, row: np.ndarray) -> np.ndarray:
        """Torque (n,) [N*m] for the input row (3n,) = (q, v, a), given the rows before it."""


@runtime_checkable
class SequenceModel(Protocol):
    """What a model whose torque depends on a window of past samples offers besides predict()."""

    @property
    def sequence_length(self) -> int:
        """Samples per window, at the recording's rate."""

    def predict_window(self, window: np.ndarray) -> np.ndarray:
        """Torque (n,) [N*m] of the last row of one window (T, 3n) of (q, v, a) rows."""

    def sequence_predictor(self) -> SequenceStream:
        """A stream built once from the fitted state, for the online predictor."""


@dataclass(frozen=True)
class ModelConfig:
    """Base of the models' frozen configs; each subclass sets ``kind`` to its registry name."""

    kind: str

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready hyper-parameters."""
        return {item.name: getattr(self, item.name) for item in fields(self)}


@dataclass(frozen=True, eq=False)
class TorqueComponents:
    """A model's torque split into physical parts, each (B, n) [N*m] or None if not separable.

    ``total`` always equals the model's prediction; the parts that are not None sum to it.
    """

    total: np.ndarray
    inertial: np.ndarray | None = None
    coriolis: np.ndarray | None = None
    gravity: np.ndarray | None = None
    rotor_inertia: np.ndarray | None = None
    friction: np.ndarray | None = None
    residual: np.ndarray | None = None

    def parts(self) -> dict[str, np.ndarray]:
        """The parts that the model separates, by name."""
        return {
            item.name: getattr(self, item.name)
            for item in fields(self)
            if item.name != 'total' and getattr(self, item.name) is not None
        }


class InverseDynamicsModel(ABC):
    """Predict the joint-side torque of a robot from (q, v, a)."""

    kind: ClassVar[str]
    #: Sequence models predict from windows of past samples: predict() takes a contiguous run.
    is_sequence_model: ClassVar[bool] = False

    def __init__(self, config: ModelConfig, robot: RobotConfig) -> None:
        """Store the settings; no I/O, no fitting."""
        self.config = config
        self.robot = robot

    @property
    def joint_names(self) -> tuple[str, ...]:
        """Joint names, the column order of every array."""
        return self.robot.joints

    @abstractmethod
    def fit(self, data: TrainingData, *, progress: bool = False) -> Self:
        """Fit on the training part of ``data`` (its tail is the validation part)."""

    @abstractmethod
    def predict(self, q: np.ndarray, v: np.ndarray, a: np.ndarray) -> np.ndarray:
        """Torque (B, n) [N*m] for states (B, n); sequence models take a contiguous run."""

    def sample_predictor(self) -> SamplePredictor:
        """A function of one sample for the online predictor, built once from the fitted state.

        Models override this with a float64 numpy path that equals ``predict`` on a batch of one
        (up to the float32 rounding of the torch networks); the default calls ``predict``. Not
        for sequence models, whose torque depends on past samples.
        """

        def predict_one(q: np.ndarray, v: np.ndarray, a: np.ndarray) -> np.ndarray:
            tau: np.ndarray = self.predict(q[None], v[None], a[None])[0]
            return tau

        return predict_one

    def for_the_drive(self) -> InverseDynamicsModel:
        """The model as feed-forward: its torque for the motion at the sample's own time.

        Models that learn the labels' lag as a term of their own (``rnea_id`` and the networks
        on it) return a copy without it; the others cannot tell it apart and return themselves.
        The predictor, the online check and the closed loop serve this model.
        """
        return self

    def components(self, q: np.ndarray, v: np.ndarray, a: np.ndarray) -> TorqueComponents:
        """Split the prediction into physical parts; by default nothing is separable."""
        return TorqueComponents(total=self.predict(q, v, a))

    @abstractmethod
    def state(self) -> dict[str, np.ndarray]:
        """Fitted tensors to save (safetensors), by name."""

    @abstractmethod
    def load_state(self, tensors: dict[str, np.ndarray], fitted: dict[str, Any]) -> None:
        """Restore fitted tensors and the JSON-ready fitted values from ``fitted_metadata``."""

    def fitted_metadata(self) -> dict[str, Any]:
        """JSON-ready fitted values that are not tensors (scalers, identified parameters)."""
        return {}


def as_sequence_model(model: InverseDynamicsModel) -> SequenceModel | None:
    """The model as a sequence model, or None for a model of one sample.

    Raises:
        TypeError: the model says it is a sequence model but lacks the protocol's methods.
    """
    if not model.is_sequence_model:
        return None
    if not isinstance(model, SequenceModel):
        raise TypeError(f'{model.kind}: is_sequence_model is set but it is not a SequenceModel')
    return model
