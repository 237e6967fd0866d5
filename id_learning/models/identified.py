"""Identified physics as model kinds: ``rnea_id`` and the Newtonian network on it, ``rnea_id_mlp``.

``rnea_id`` is the rigid body and drives identified on the training part
(``physics.identification``): every body's inertial parameters kept physical and drawn towards
the URDF, a payload, rotor inertias, label gains, friction, a balancer where gravity is large,
torque offsets and the labels' delay; with joint-torque labels only the link-side terms (rigid
body, payload, balancer, offsets). ``rnea_id_mlp`` puts the study's MLP h(q, v) on top of it, so
the network learns only what the identified physics leaves.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass, replace
from typing import Any, ClassVar, Literal, Self

import numpy as np

from id_learning.models.base import ModelConfig, SamplePredictor, TorqueComponents
from id_learning.models.blackbox import check_kind
from id_learning.models.data import TrainingData
from id_learning.models.identified_prior import (
    PHYSICS_PREFIX,
    IdentificationSettings,
    IdentifiedPrior,
    identification_config,
)
from id_learning.models.network_common import NumpyNormalisedMlp
from id_learning.models.physics import RneaMlpConfig, RneaMlpModel
from id_learning.physics.identification import identify
from id_learning.physics.identified import IdentifiedPhysics
from id_learning.robot.config import RobotConfig

__all__ = ['RneaIdConfig', 'RneaIdMlpConfig', 'RneaIdMlpModel', 'RneaIdModel']

_LOG = logging.getLogger(__name__)


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
    """The Newtonian network's settings on top of the identified physics (see RneaIdConfig).

    ``joint_rounds``: after the physics then h, rounds in which the physics is identified again
    on the labels less h (under the identification's constraints: physical bodies, the CAD
    prior) and h fitted again on what the new physics leaves (0: physics first, then h).
    """

    kind: Literal['rnea_id_mlp'] = 'rnea_id_mlp'
    joint_rounds: int = 0

    def __post_init__(self) -> None:
        """Check the network's and the identification's settings."""
        super().__post_init__()
        self.check_identification()


class RneaIdMlpModel(IdentifiedPrior, RneaMlpModel):
    """tau = rnea_id(q, v, a) + h(q, v): the MLP learns what the identified physics leaves."""

    kind: ClassVar[str] = 'rnea_id_mlp'
    config: RneaIdMlpConfig
    _joint_physics: IdentifiedPhysics | None = None

    def training_physics(self, data: TrainingData) -> np.ndarray:
        """Identify on the training part (shared with rnea_id); its torque on every sample.

        In a joint round, the physics identified on the labels less h instead.
        """
        ds = data.dataset
        physics = self._joint_physics or self.identify(data)
        return physics.torque(ds.q, ds.v, ds.a)

    def fit(self, data: TrainingData, *, progress: bool = False) -> Self:
        """Physics, then h; then ``joint_rounds`` of both again, each on what the other leaves.

        Alternating minimisation of one objective, the labels' error over the physics' and the
        network's parameters together: each round identifies the physics on the labels less h
        (filtered like them), with every constraint and prior of the identification, and fits
        h on the labels less that physics. A round is kept only where it lowers the whole
        model's error on the validation tail (an h that learned nothing would otherwise bend
        the physics); the first that does not ends the rounds.
        """
        self._joint_physics = None
        start, budget = time.perf_counter(), self.config.max_seconds
        super().fit(data, progress=progress)
        ds = data.dataset
        settings = identification_config(self.config)
        best, best_error = dict(self.__dict__), self._validation_error(data)
        for done in range(self.config.joint_rounds):
            if budget is not None and time.perf_counter() - start > budget / 2:
                _LOG.warning(
                    '%s: %d of %d joint rounds done within max_seconds %g s; the rest skipped',
                    self.kind, done, self.config.joint_rounds, budget,
                )  # fmt: skip
                break
            h = self.residual_torque(ds.q, ds.v)
            if ds.is_through_filter:
                h = ds.filter_like_labels(h)
            self._joint_physics = identify(replace(ds, tau=ds.tau - h), self.robot, settings)
            self.physics_ = self._joint_physics
            super().fit(data, progress=progress)
            error = self._validation_error(data)
            if not error < best_error:
                _LOG.info('%s: joint round %d did not lower the validation error', self.kind, done)
                break
            best, best_error = dict(self.__dict__), error
        self.__dict__.update(best)
        self._joint_physics = None
        return self

    def _validation_error(self, data: TrainingData) -> float:
        """The whole model's normalised mean squared error on the validation tail."""
        ds, rows = data.dataset, data.validation_rows
        tau = self.predict(ds.q, ds.v, ds.a)
        if ds.is_through_filter:
            tau = ds.filter_like_labels(tau)
        return float(np.mean(((tau[rows] - ds.tau[rows]) / ds.target_scaler.scale()) ** 2))

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
