"""Identified physics as model kinds: ``rnea_id`` and the Newtonian network on it, ``rnea_id_mlp``.

``rnea_id`` is the rigid body and drives identified on the training part
(``physics.identification``): every body's inertial parameters kept physical and drawn towards
the URDF, a payload, rotor inertias, label gains, friction, a balancer where gravity is large,
torque offsets and the labels' delay; with joint-torque labels only the link-side terms (rigid
body, payload, balancer, offsets). ``rnea_id_mlp`` puts the study's MLP h(q, v) on top of it, so
the network learns only what the identified physics leaves.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, ClassVar, Literal, Self

import numpy as np

from id_learning.models.base import ModelConfig, SamplePredictor, TorqueComponents
from id_learning.models.blackbox import check_kind
from id_learning.models.data import TrainingData
from id_learning.models.identified_prior import (
    PHYSICS_PREFIX,
    IdentificationSettings,
    IdentifiedPrior,
)
from id_learning.models.network_common import NumpyNormalisedMlp
from id_learning.models.physics import RneaMlpConfig, RneaMlpModel
from id_learning.robot.config import RobotConfig

__all__ = ['RneaIdConfig', 'RneaIdMlpConfig', 'RneaIdMlpModel', 'RneaIdModel']


@dataclass(frozen=True)
class RneaIdConfig(IdentificationSettings, ModelConfig):
    """Settings of the identified physics (see IdentificationSettings).

    Attributes:
        max_seconds: the identification's time budget [s] (None: none); a fit cut short by it
            says so in its report (``cut_short``).
    """

    kind: Literal['rnea_id'] = 'rnea_id'
    max_seconds: float | None = None

    def __post_init__(self) -> None:
        """Check the kind and the identification settings."""
        check_kind(self, 'rnea_id')
        self.check_identification()


class RneaIdModel(IdentifiedPrior):
    """tau = the identified rigid body and drives (``physics.identified``)."""

    kind: ClassVar[str] = 'rnea_id'

    def __init__(self, config: RneaIdConfig, robot: RobotConfig) -> None:
        """Store the settings; no I/O, no fitting."""
        super().__init__(config, robot)
        self.config: RneaIdConfig = config
        #: The training part's (q, v, a) range, for the predictor's out-of-range warning.
        self.input_range_: dict[str, Any] | None = None

    def fit(self, data: TrainingData, *, progress: bool = False) -> Self:
        """Identify on the training part of ``data``."""
        data.require_varied(self.kind)
        del progress  # seconds
        self.identify(data)
        self.input_range_ = data.dataset.input_scaler.to_dict()
        return self

    def predict(self, q: np.ndarray, v: np.ndarray, a: np.ndarray) -> np.ndarray:
        """Torque (B, n) [N*m] for q, v, a (B, n) [rad, rad/s, rad/s^2]."""
        return self.physics_torque(q, v, a)

    def sample_predictor(self) -> SamplePredictor:
        """One sample's torque: pinocchio's RNEA with the identified bodies, drives folded."""
        return self.physics_sample_predictor()

    def components(self, q: np.ndarray, v: np.ndarray, a: np.ndarray) -> TorqueComponents:
        """Inertial, Coriolis, gravity (identified bodies), rotor, friction; the rest residual."""
        return self.with_physics_parts(q, v, a, {})

    def state(self) -> dict[str, np.ndarray]:
        """The identified values (inertial parameters, drives, balancer)."""
        return self.identified_physics().arrays()

    def load_state(self, tensors: dict[str, np.ndarray], fitted: dict[str, Any]) -> None:
        """Rebuild the identified physics.

        Raises:
            CheckpointError: the arrays or the metadata do not fit the robot.
        """
        self.load_physics({PHYSICS_PREFIX + k: v for k, v in tensors.items()}, fitted)
        self.input_range_ = fitted.get('input_scaler')

    def fitted_metadata(self) -> dict[str, Any]:
        """The settings and report of the identification, and the training input range."""
        out = self.physics_metadata()
        if self.input_range_ is not None:
            out['input_scaler'] = self.input_range_
        return out


@dataclass(frozen=True)
class RneaIdMlpConfig(IdentificationSettings, RneaMlpConfig):
    """The Newtonian network's settings on top of the identified physics (see RneaIdConfig)."""

    kind: Literal['rnea_id_mlp'] = 'rnea_id_mlp'

    def __post_init__(self) -> None:
        """Check the network's and the identification's settings."""
        super().__post_init__()
        self.check_identification()


class RneaIdMlpModel(IdentifiedPrior, RneaMlpModel):
    """tau = rnea_id(q, v, a) + h(q, v): the MLP learns what the identified physics leaves."""

    kind: ClassVar[str] = 'rnea_id_mlp'
    config: RneaIdMlpConfig

    def training_physics(self, data: TrainingData) -> np.ndarray:
        """Identify on the training part (shared with rnea_id); its torque on every sample."""
        ds = data.dataset
        return self.identify(data).torque(ds.q, ds.v, ds.a)

    def sample_predictor(self) -> SamplePredictor:
        """One sample's torque: the identified physics' path plus h in float64 numpy."""
        h = NumpyNormalisedMlp(self.network())
        concatenate = np.concatenate

        def residual_one(q: np.ndarray, v: np.ndarray, a: np.ndarray) -> np.ndarray:
            del a
            tau: np.ndarray = h(concatenate((q, v)))
            return tau

        return self.with_physics(residual_one)

    def components(self, q: np.ndarray, v: np.ndarray, a: np.ndarray) -> TorqueComponents:
        """The identified physics' parts, with h added to the residual."""
        return self.with_physics_parts(q, v, a, {'residual': self.residual_torque(q, v)})

    def state(self) -> dict[str, np.ndarray]:
        """The weights of h and the identified values."""
        return self.with_physics_state(super().state())

    def load_state(self, tensors: dict[str, np.ndarray], fitted: dict[str, Any]) -> None:
        """Rebuild h and the identified physics."""
        network = self.load_physics(tensors, fitted)
        super().load_state(network, fitted)

    def fitted_metadata(self) -> dict[str, Any]:
        """The scalers and fit summary of h and the identification's settings and report."""
        out = super().fitted_metadata()
        out.pop('rotor_inertia_motor_side_kgm2', None)
        return {**out, **self.physics_metadata()}
