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
from dataclasses import dataclass
from typing import Any, ClassVar, Literal, Self

import numpy as np

from id_learning.errors import CheckpointError, ConfigError
from id_learning.models.base import (
    InverseDynamicsModel,
    ModelConfig,
    SamplePredictor,
    TorqueComponents,
)
from id_learning.models.blackbox import check_kind
from id_learning.models.data import TrainingData
from id_learning.models.network_common import NumpyNormalisedMlp, require_fitted
from id_learning.models.physics import RneaMlpConfig, RneaMlpModel
from id_learning.physics.base_parameters import CadPrior
from id_learning.physics.identification import IdentificationConfig
from id_learning.physics.identified import FRICTION_LAWS, IdentifiedPhysics, sum_parts
from id_learning.robot.config import RobotConfig

__all__ = ['RneaIdConfig', 'RneaIdMlpConfig', 'RneaIdMlpModel', 'RneaIdModel']

_LOG = logging.getLogger(__name__)
#: Tensor-name prefix of the identified physics in an rnea_id_mlp artifact.
PHYSICS_PREFIX = 'physics.'


def identification_config(config: Any) -> IdentificationConfig:
    """The identification settings of an rnea_id or rnea_id_mlp config.

    Raises:
        ConfigError: an unknown friction law or an out-of-range setting (names the key).
    """
    friction = tuple(law.strip() for law in str(config.friction).split(',') if law.strip())
    return IdentificationConfig(
        friction=friction,
        balancer=config.balancer,
        delay=config.delay,
        payload=config.payload,
        label_gain=config.label_gain,
        prior=CadPrior(mass_rel=config.mass_rel_std, com_abs_m=config.com_std_m),
        gain_std=config.gain_std,
        iterations=config.iterations,
        confirm=config.confirm,
    )


@dataclass(frozen=True)
class RneaIdConfig(ModelConfig):
    """Settings of the identified physics.

    Attributes:
        friction: comma-separated friction laws per joint (motor labels): viscous, coulomb,
            stribeck, load_dependent.
        balancer: 'auto' (joints whose gravity sweeps 5 % of their torque limit), 'none', or
            comma-separated joint names.
        delay: estimate the labels' delay behind the positions (motor labels).
        payload: estimate a payload at the robot's payload frame.
        label_gain: estimate each joint's torque-constant error (motor labels).
        mass_rel_std: the CAD prior's relative std of a body's mass.
        com_std_m: the CAD prior's std of a body's centre of mass [m].
        gain_std: the prior std of a label gain around 0.
        iterations: linearisations of the bilinear terms.
        confirm: balancers, the payload and bodies that leave their CAD prior's 95 % range
            enter only where the training part's held-out tail confirms them.
        max_seconds: the identification's time budget [s] (None: none); a fit cut short by it
            says so in its report (``cut_short``).
    """

    kind: Literal['rnea_id'] = 'rnea_id'
    friction: str = ','.join(FRICTION_LAWS)
    balancer: str = 'auto'
    delay: bool = True
    payload: bool = True
    label_gain: bool = True
    mass_rel_std: float = 0.10
    com_std_m: float = 0.03
    gain_std: float = 0.05
    iterations: int = 3
    confirm: bool = True
    max_seconds: float | None = None

    def __post_init__(self) -> None:
        """Check the kind and the identification settings."""
        check_kind(self, 'rnea_id')
        _check_identification(self)


def _check_identification(config: Any) -> None:
    if getattr(config, 'max_seconds', None) is not None and not config.max_seconds > 0:
        raise ConfigError(f'{config.kind}: max_seconds must be > 0, got {config.max_seconds}')
    for key in ('mass_rel_std', 'com_std_m', 'gain_std'):
        if not getattr(config, key) > 0:
            raise ConfigError(f'{config.kind}: {key} must be > 0, got {getattr(config, key)}')
    identification_config(config)


def _components(
    physics: IdentifiedPhysics, q: np.ndarray, v: np.ndarray, a: np.ndarray
) -> TorqueComponents:
    """The identified model's parts: rigid body split by the identified dynamics."""
    q, v, a = (np.atleast_2d(np.asarray(x, dtype=float)) for x in (q, v, a))
    parts = physics.parts(q, v, a)
    dynamics, scale = physics.dynamics, 1.0 + physics.gain
    inertial = scale * np.einsum('bij,bj->bi', dynamics.mass_matrix(q), a)
    gravity = scale * dynamics.gravity(q)
    coriolis = parts['rigid_body'] - inertial - gravity
    rest = parts['balancer'] + parts['offset'] + parts['delay']
    return TorqueComponents(
        total=sum_parts(parts),
        inertial=inertial,
        coriolis=coriolis,
        gravity=gravity,
        rotor_inertia=parts['rotor_inertia'] if physics.target == 'motor' else None,
        friction=parts['friction'] if physics.friction else None,
        residual=rest,
    )


class RneaIdModel(InverseDynamicsModel):
    """tau = the identified rigid body and drives (``physics.identified``)."""

    kind: ClassVar[str] = 'rnea_id'

    def __init__(self, config: RneaIdConfig, robot: RobotConfig) -> None:
        """Store the settings; no I/O, no fitting."""
        super().__init__(config, robot)
        self.config: RneaIdConfig = config
        self.physics_: IdentifiedPhysics | None = None
        #: The training part's (q, v, a) range, for the predictor's out-of-range warning.
        self.input_range_: dict[str, Any] | None = None

    def _physics(self) -> IdentifiedPhysics:
        require_fitted(self, self.physics_)
        assert self.physics_ is not None
        return self.physics_

    def fit(self, data: TrainingData, *, progress: bool = False) -> Self:
        """Identify on the training part of ``data``."""
        data.require_varied(self.kind)
        del progress  # seconds
        budget = self.config.max_seconds
        deadline = None if budget is None else time.perf_counter() + budget
        self.physics_ = data.identified(identification_config(self.config), deadline)
        self.input_range_ = data.dataset.input_scaler.to_dict()
        return self

    def predict(self, q: np.ndarray, v: np.ndarray, a: np.ndarray) -> np.ndarray:
        """Torque (B, n) [N*m] for q, v, a (B, n) [rad, rad/s, rad/s^2]."""
        return self._physics().torque(q, v, a)

    def sample_predictor(self) -> SamplePredictor:
        """One sample's torque: pinocchio's RNEA with the identified bodies, drives folded."""
        return self._physics().sample_function()

    def components(self, q: np.ndarray, v: np.ndarray, a: np.ndarray) -> TorqueComponents:
        """Inertial, Coriolis, gravity (identified bodies), rotor, friction; the rest residual."""
        return _components(self._physics(), q, v, a)

    def state(self) -> dict[str, np.ndarray]:
        """The identified values (inertial parameters, drives, balancer)."""
        return self._physics().arrays()

    def load_state(self, tensors: dict[str, np.ndarray], fitted: dict[str, Any]) -> None:
        """Rebuild the identified physics.

        Raises:
            CheckpointError: the arrays or the metadata do not fit the robot.
        """
        if 'physics' not in fitted:
            raise CheckpointError(f'{self.kind}: the fitted metadata lacks the physics')
        self.physics_ = IdentifiedPhysics.from_arrays(self.robot, tensors, fitted['physics'])
        self.input_range_ = fitted.get('input_scaler')

    def fitted_metadata(self) -> dict[str, Any]:
        """The settings and report of the identification, and the training input range."""
        out: dict[str, Any] = {'physics': self._physics().metadata()}
        if self.input_range_ is not None:
            out['input_scaler'] = self.input_range_
        return out


@dataclass(frozen=True)
class RneaIdMlpConfig(RneaMlpConfig):
    """The Newtonian network's settings on top of the identified physics (see RneaIdConfig)."""

    kind: Literal['rnea_id_mlp'] = 'rnea_id_mlp'
    friction: str = ','.join(FRICTION_LAWS)
    balancer: str = 'auto'
    delay: bool = True
    payload: bool = True
    label_gain: bool = True
    mass_rel_std: float = 0.10
    com_std_m: float = 0.03
    gain_std: float = 0.05
    iterations: int = 3
    confirm: bool = True

    def __post_init__(self) -> None:
        """Check the network's and the identification's settings."""
        super().__post_init__()
        _check_identification(self)


class RneaIdMlpModel(RneaMlpModel):
    """tau = rnea_id(q, v, a) + h(q, v): the MLP learns what the identified physics leaves."""

    kind: ClassVar[str] = 'rnea_id_mlp'

    def __init__(self, config: RneaIdMlpConfig, robot: RobotConfig) -> None:
        """Store the settings; no I/O, no fitting."""
        super().__init__(config, robot)
        self.config: RneaIdMlpConfig = config
        self.physics_: IdentifiedPhysics | None = None

    def training_physics(self, data: TrainingData) -> np.ndarray:
        """Identify on the training part (shared with rnea_id); its torque on every sample."""
        budget = self.config.max_seconds
        deadline = None if budget is None else time.perf_counter() + budget
        self.physics_ = data.identified(identification_config(self.config), deadline)
        ds = data.dataset
        return self.physics_.torque(ds.q, ds.v, ds.a)

    def _physics(self) -> IdentifiedPhysics:
        if self.physics_ is None:
            raise CheckpointError(f'{self.kind}: the model is not fitted')
        return self.physics_

    def physics_torque(self, q: np.ndarray, v: np.ndarray, a: np.ndarray) -> np.ndarray:
        """The identified physics' torque (B, n) [N*m]."""
        return self._physics().torque(q, v, a)

    def physics_sample_predictor(self) -> SamplePredictor:
        """The identified physics of one sample, without h."""
        return self._physics().sample_function()

    def sample_predictor(self) -> SamplePredictor:
        """One sample's torque: the identified physics' path plus h in float64 numpy."""
        physics = self._physics().sample_function()
        h = NumpyNormalisedMlp(self.network())

        def predict_one(q: np.ndarray, v: np.ndarray, a: np.ndarray) -> np.ndarray:
            tau: np.ndarray = physics(q, v, a) + h(np.concatenate((q, v)))
            return tau

        return predict_one

    def components(self, q: np.ndarray, v: np.ndarray, a: np.ndarray) -> TorqueComponents:
        """The identified physics' parts, with h added to the residual."""
        parts = _components(self._physics(), q, v, a)
        h = self.residual_torque(q, v)
        residual = h if parts.residual is None else parts.residual + h
        return TorqueComponents(
            total=parts.total + h,
            inertial=parts.inertial,
            coriolis=parts.coriolis,
            gravity=parts.gravity,
            rotor_inertia=parts.rotor_inertia,
            friction=parts.friction,
            residual=residual,
        )

    def state(self) -> dict[str, np.ndarray]:
        """The weights of h and the identified values."""
        arrays = self._physics().arrays()
        return {**super().state(), **{PHYSICS_PREFIX + k: v for k, v in arrays.items()}}

    def load_state(self, tensors: dict[str, np.ndarray], fitted: dict[str, Any]) -> None:
        """Rebuild h and the identified physics."""
        network = {k: v for k, v in tensors.items() if not k.startswith(PHYSICS_PREFIX)}
        arrays = {
            k.removeprefix(PHYSICS_PREFIX): v
            for k, v in tensors.items()
            if k.startswith(PHYSICS_PREFIX)
        }
        super().load_state(network, fitted)
        if 'physics' not in fitted:
            raise CheckpointError(f'{self.kind}: the fitted metadata lacks the physics')
        self.physics_ = IdentifiedPhysics.from_arrays(self.robot, arrays, fitted['physics'])

    def fitted_metadata(self) -> dict[str, Any]:
        """The scalers and fit summary of h and the identification's settings and report."""
        out = super().fitted_metadata()
        out.pop('rotor_inertia_motor_side_kgm2', None)
        return {**out, 'physics': self._physics().metadata()}
