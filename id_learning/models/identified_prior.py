"""The identified physics as the prior under a network: what the ``*_id`` network kinds share.

``rnea_id_mlp``, ``delan_id`` and ``lnn_mlp_id`` predict ``tau = rnea_id(q, v, a) + network``:
the physics ``physics.identification`` estimates on the training part (shared with ``rnea_id``
through ``TrainingData.identified``), and a network trained on what it leaves. This module holds
their identification settings (``IdentificationSettings``), the identified model's torque split
(``identified_components``) and mass matrix (``identified_mass_matrix``), and ``IdentifiedPrior``,
the base of ``rnea_id`` and of the networks on it, which identifies in ``fit``, adds the physics
to a network's torque, parts and one-sample path, and saves the identified values beside the
weights under ``PHYSICS_PREFIX``.
"""

from __future__ import annotations

import copy
import time
from collections.abc import Mapping
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from id_learning.errors import CheckpointError, ConfigError
from id_learning.models.base import InverseDynamicsModel, SamplePredictor, TorqueComponents
from id_learning.models.data import TrainingData
from id_learning.models.network_common import require_fitted
from id_learning.physics.base_parameters import CadPrior
from id_learning.physics.identification import IdentificationConfig
from id_learning.physics.identified import FRICTION_LAWS, IdentifiedPhysics, sum_parts
from id_learning.robot.config import RobotConfig
from id_learning.robot.drives import rotor_inertia_joint_side

__all__ = [
    'PHYSICS_PREFIX',
    'IdentificationSettings',
    'IdentifiedPrior',
    'identification_config',
    'identified_components',
    'identified_mass_matrix',
]

#: Tensor-name prefix of the identified physics in the artifact of a network on it.
PHYSICS_PREFIX = 'physics.'


@dataclass(frozen=True)
class IdentificationSettings:
    """The identification's settings, mixed into the configs of the kinds that identify.

    A config class lists it first among its bases (``class RneaIdConfig(IdentificationSettings,
    ModelConfig)``), so that these fields follow the kind's own, and calls
    ``check_identification`` in its ``__post_init__``.

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
        cogging: identify each motor's cogging on the full band of the labels (motor labels;
            ``physics.cogging``).
    """

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
    cogging: bool = True

    def check_identification(self) -> None:
        """Check the identification settings (and a time budget, where the config has one).

        Raises:
            ConfigError: an unknown friction law or an out-of-range setting (names the key).
        """
        kind = getattr(self, 'kind', type(self).__name__)
        budget = getattr(self, 'max_seconds', None)
        if budget is not None and not budget > 0:
            raise ConfigError(f'{kind}: max_seconds must be > 0, got {budget}')
        for key in ('mass_rel_std', 'com_std_m', 'gain_std'):
            if not getattr(self, key) > 0:
                raise ConfigError(f'{kind}: {key} must be > 0, got {getattr(self, key)}')
        identification_config(self)


def identification_config(config: IdentificationSettings) -> IdentificationConfig:
    """The identification settings of a config that holds ``IdentificationSettings``.

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
        cogging=config.cogging,
    )


def identified_components(
    physics: IdentifiedPhysics, q: np.ndarray, v: np.ndarray, a: np.ndarray
) -> TorqueComponents:
    """The identified model's parts: rigid body split by the identified dynamics."""
    q, v, a = (np.atleast_2d(np.asarray(x, dtype=float)) for x in (q, v, a))
    parts = physics.parts(q, v, a)
    dynamics, scale = physics.dynamics, 1.0 + physics.gain
    inertial = scale * np.einsum('bij,bj->bi', dynamics.mass_matrix(q), a)
    gravity = scale * dynamics.gravity(q)
    coriolis = parts['rigid_body'] - inertial - gravity
    rest = parts['balancer'] + parts['offset'] + parts['delay'] + parts['cogging']
    return TorqueComponents(
        total=sum_parts(parts),
        inertial=inertial,
        coriolis=coriolis,
        gravity=gravity,
        rotor_inertia=parts['rotor_inertia'] if physics.target == 'motor' else None,
        friction=parts['friction'] if physics.friction else None,
        residual=rest,
    )


def identified_mass_matrix(physics: IdentifiedPhysics, q: np.ndarray) -> np.ndarray:
    """M_id(q) = M_theta(q) + diag(N^2 r) (B, n, n) [kg*m^2]: the identified links and rotors.

    Symmetric positive definite (physical bodies, rotor inertias >= 0; the rotors' zero for
    joint-torque labels). The identified torque's inertial part is ``(1 + g) * M_id(q) a``.
    """
    q = np.atleast_2d(np.asarray(q, dtype=float))
    rotor = rotor_inertia_joint_side(physics.rotor, physics.robot.drives.gear_ratio)
    out: np.ndarray = physics.dynamics.mass_matrix(q) + np.diag(rotor)
    return out


class IdentifiedPrior(InverseDynamicsModel):
    """A model on the identified physics: ``rnea_id`` itself, or a network on it.

    A network kind lists it before its network model's class among the bases (``class
    RneaIdMlpModel(IdentifiedPrior, RneaMlpModel)``); it calls ``identify`` in its fit and
    combines its network's torque, parts, one-sample path, weights and metadata with the
    physics' through the methods here.

    Attributes:
        physics_: the identified physics; None before ``fit`` or ``load_state``.
    """

    def __init__(self, config: Any, robot: RobotConfig) -> None:
        """Store the settings; no I/O, no fitting."""
        super().__init__(config, robot)
        self.physics_: IdentifiedPhysics | None = None

    def identify(self, data: TrainingData) -> IdentifiedPhysics:
        """Identify on the training part of ``data`` (shared with rnea_id) and keep it.

        The identification's budget is the config's ``max_seconds`` (from now).
        """
        config = self.config
        assert isinstance(config, IdentificationSettings)
        budget = getattr(config, 'max_seconds', None)
        deadline = None if budget is None else time.perf_counter() + budget
        self.physics_ = data.identified(identification_config(config), deadline)
        return self.physics_

    def identified_physics(self) -> IdentifiedPhysics:
        """The identified physics (``require_fitted`` refuses before a fit or a load)."""
        require_fitted(self, self.physics_)
        assert self.physics_ is not None
        return self.physics_

    def for_the_drive(self) -> InverseDynamicsModel:
        """A copy whose physics leaves out the labels' delay: the torque the drive needs now.

        The network's part, fitted on what the delayed physics leaves, is kept as it is (its
        band is far below the delay's reach).
        """
        physics = self.identified_physics()
        if not physics.delay_s:
            return self
        drive = copy.copy(self)
        drive.physics_ = replace(physics, delay_s=0.0)
        return drive

    def identified_mass_matrix(self, q: np.ndarray) -> np.ndarray:
        """``identified_mass_matrix`` of the identified physics (B, n, n) [kg*m^2]."""
        return identified_mass_matrix(self.identified_physics(), q)

    def physics_torque(self, q: np.ndarray, v: np.ndarray, a: np.ndarray) -> np.ndarray:
        """The identified physics' torque (B, n) [N*m]."""
        return self.identified_physics().torque(q, v, a)

    def physics_sample_predictor(self) -> SamplePredictor:
        """The identified physics of one sample, without the network (the predictor's prior)."""
        return self.identified_physics().sample_function()

    def with_physics(self, network: SamplePredictor) -> SamplePredictor:
        """One sample's torque: the identified physics' path plus ``network``'s."""
        physics = self.identified_physics().sample_function()

        def predict_one(q: np.ndarray, v: np.ndarray, a: np.ndarray) -> np.ndarray:
            tau: np.ndarray = physics(q, v, a) + network(q, v, a)
            return tau

        return predict_one

    def with_physics_parts(
        self, q: np.ndarray, v: np.ndarray, a: np.ndarray, network: Mapping[str, np.ndarray]
    ) -> TorqueComponents:
        """The identified physics' parts with the network's (B, n) [N*m] added by name.

        ``network`` maps TorqueComponents field names (not 'total') to the network's parts, which
        sum to its torque; a part the physics does not separate becomes the network's alone.
        """
        parts = identified_components(self.identified_physics(), q, v, a)
        combined = parts.parts()
        for name, value in network.items():
            combined[name] = combined[name] + value if name in combined else value
        total = parts.total + sum_parts(dict(network)) if network else parts.total
        return TorqueComponents(total=total, **combined)

    def with_physics_state(self, network: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        """The network's tensors and the identified values (named ``PHYSICS_PREFIX`` + name)."""
        arrays = self.identified_physics().arrays()
        return {**network, **{PHYSICS_PREFIX + k: v for k, v in arrays.items()}}

    def load_physics(
        self, tensors: dict[str, np.ndarray], fitted: dict[str, Any]
    ) -> dict[str, np.ndarray]:
        """Rebuild the identified physics from its tensors; the network's tensors, the rest.

        Raises:
            CheckpointError: the fitted metadata lacks the physics, or its arrays do not fit
                the robot.
        """
        if 'physics' not in fitted:
            raise CheckpointError(f'{self.kind}: the fitted metadata lacks the physics')
        arrays = {
            k.removeprefix(PHYSICS_PREFIX): v
            for k, v in tensors.items()
            if k.startswith(PHYSICS_PREFIX)
        }
        self.physics_ = IdentifiedPhysics.from_arrays(self.robot, arrays, fitted['physics'])
        return {k: v for k, v in tensors.items() if not k.startswith(PHYSICS_PREFIX)}

    def physics_metadata(self) -> dict[str, Any]:
        """The identification's settings and report, under 'physics'."""
        return {'physics': self.identified_physics().metadata()}
