"""Newtonian models: the URDF's rigid-body dynamics (RNEA) plus drive terms identified from data.

Both models start from the manufacturer's model, RNEA_URDF(q, v, a), and the rotor inertia seen
through the gearbox, I_M * gear_ratio**2 * a (I_M motor side [kg*m^2]):

- RNEA+LQ (``rnea_lq``) fits I_M and a friction model per joint by linear least squares, I_M
  and the friction coefficients held >= 0 (a drive has no negative inertia, and its friction
  dissipates; a negative estimate is reported only when the noise cannot explain it);
- RNEA+MLP (``rnea_mlp``, the study's Newtonian network) keeps the datasheet I_M and learns the
  rest with an MLP h(q, v).
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from dataclasses import dataclass
from functools import cached_property
from typing import Any, ClassVar, Literal, Self

import numpy as np
import torch

from id_learning.dataset.preprocess import Dataset, MinMaxScaler
from id_learning.dataset.signals import lowpass
from id_learning.errors import CheckpointError, ConfigError
from id_learning.models.base import (
    InverseDynamicsModel,
    ModelConfig,
    SamplePredictor,
    TorqueComponents,
)
from id_learning.models.blackbox import NetworkConfig, check_kind, check_mlp_shape
from id_learning.models.data import TrainingData
from id_learning.models.fitting import select_device
from id_learning.models.network_common import (
    NormalisedMlp,
    NumpyNormalisedMlp,
    centre_and_half,
    load_scalers,
    predict_chunked,
    require_fitted,
    scalers_metadata,
    seeded,
)
from id_learning.models.torch_model import TorchModel
from id_learning.models.torch_utils import to_tensor
from id_learning.physics.friction import coulomb
from id_learning.physics.rigid_body import RigidBodyDynamics
from id_learning.robot.config import RobotConfig
from id_learning.robot.drives import rotor_inertia_joint_side, rotor_inertia_torque

__all__ = [
    'FRICTION_MODELS',
    'RneaLqConfig',
    'RneaLqModel',
    'RneaMlpConfig',
    'RneaMlpModel',
]

_LOG = logging.getLogger(__name__)

FRICTION_MODELS = ('viscous', 'viscous_coulomb', 'viscous_coulomb_offset')
#: The RNEA+LQ parameters per joint, in regressor column order, with their units.
LQ_PARAMETERS = {
    'rotor_inertia_motor_side': 'kg*m^2',
    'viscous': 'N*m*s/rad',
    'coulomb': 'N*m',
    'offset': 'N*m',
}
#: The RNEA+LQ parameters physics gives a sign (an inertia, and friction that dissipates), with
#: what a negative value would be.
LQ_NON_NEGATIVE = {
    'rotor_inertia_motor_side': 'a negative inertia',
    'viscous': 'driving friction',
    'coulomb': 'driving friction',
}
#: A signed parameter's negative estimate is a finding (the URDF model is off) only when the label
#: noise cannot explain it, t <= LQ_FINDING_T (one-sided p ~ 2e-4 for normal noise; on the exact
#: rigid twins, 2,000 held values in 370 fits, t stayed above -3.3), and it matters: the term
#: carries LQ_FINDING_SHARE of the joint label's RMS or more. Otherwise it is held at 0 quietly.
LQ_FINDING_T = -3.5
LQ_FINDING_SHARE = 0.01
#: Weights w (N, k) on the training rows -> Var(w^T noise) / Var(noise) per column [-].
NoiseGain = Callable[[np.ndarray], np.ndarray]


class _NominalPhysics(InverseDynamicsModel):
    """The URDF's rigid-body dynamics, built on first use (the constructor does no I/O)."""

    @cached_property
    def dynamics(self) -> RigidBodyDynamics:
        """The nominal (URDF) rigid-body model of the robot."""
        return RigidBodyDynamics.from_config(self.robot)

    def sample_rnea(self) -> SamplePredictor:
        """RNEA_URDF(q, v, a) of one sample (n,) -> (n,) [N*m], with its own scratch data."""
        return self.dynamics.sample_rnea()

    def rigid_body_parts(
        self, q: np.ndarray, v: np.ndarray, a: np.ndarray
    ) -> dict[str, np.ndarray]:
        """M(q) a, C(q, v) v and g(q), each (B, n) [N*m]; they sum to RNEA(q, v, a)."""
        mass = self.dynamics.mass_matrix(q)
        return {
            'inertial': np.einsum('bij,bj->bi', mass, a),
            'coriolis': self.dynamics.coriolis(q, v),
            'gravity': self.dynamics.gravity(q),
        }


def _states(q: np.ndarray, v: np.ndarray, a: np.ndarray) -> tuple[np.ndarray, ...]:
    return tuple(np.atleast_2d(np.asarray(x, dtype=float)) for x in (q, v, a))


def label_noise_gain(ds: Dataset, rows: np.ndarray, joint: int) -> NoiseGain:
    """``NoiseGain`` of noise white before the joint's label filter (what filtering labels does).

    w^T noise = (F w)^T white for the zero-phase (symmetric) filter F, so the gain is
    ||F w||^2 over the filter's energy sum(h**2) (an impulse's response, h).
    """
    cutoff = np.array([ds.cutoff_hz[joint]], dtype=float)
    impulse = np.zeros((int(40.0 / (cutoff[0] * ds.period_s)) | 1, 1))  # 40 cut-off periods
    impulse[len(impulse) // 2] = 1.0
    energy = float(np.sum(lowpass(impulse, cutoff, ds.period_s, ds.filter_order) ** 2))

    def gain(weights: np.ndarray) -> np.ndarray:
        embedded = np.zeros((len(ds.tau), weights.shape[1]))
        embedded[rows] = weights
        filtered = ds.filter_like_labels(embedded, joint=joint)
        out: np.ndarray = np.sum(filtered**2, axis=0) / energy
        return out

    return gain


# -- RNEA + least squares ------------------------------------------------------------------------
@dataclass(frozen=True)
class RneaLqConfig(ModelConfig):
    """RNEA+LQ settings.

    Attributes:
        friction: per-joint friction model fitted with the rotor inertia:
            'viscous' (the study's: theta_D * v), 'viscous_coulomb' (+ F_c * tanh(v / v_eps)) or
            'viscous_coulomb_offset' (+ a constant per joint).
        coulomb_velocity: v_eps of the Coulomb term [rad/s], the speed below which friction
            turns smoothly through zero.

    How the least squares meet the labels follows the dataset's preprocessing: through the
    filter (the default), each regressor column and the RNEA torque, computed on a controller's
    inputs, are low-passed exactly like the labels before solving (without it, the filter's
    smear of the Coulomb step at every velocity reversal biases F_c and theta_D by 10-40 %, and
    its attenuation of the gravity torque's harmonics leaks into the rotor inertia); the study's
    way, the columns on the filtered inputs meet the filtered labels as they are. Prediction
    always uses the unfiltered model.
    """

    kind: Literal['rnea_lq'] = 'rnea_lq'
    friction: str = 'viscous'
    coulomb_velocity: float = 0.01

    def __post_init__(self) -> None:
        """Check ranges, naming the key."""
        check_kind(self, 'rnea_lq')
        if self.friction not in FRICTION_MODELS:
            raise ConfigError(
                f'rnea_lq: friction must be one of {FRICTION_MODELS}, got {self.friction!r}'
            )
        if not self.coulomb_velocity > 0:
            raise ConfigError(
                f'rnea_lq: coulomb_velocity must be > 0 rad/s, got {self.coulomb_velocity}'
            )

    @property
    def parameter_names(self) -> tuple[str, ...]:
        """The per-joint parameters this friction model fits, in regressor column order."""
        names: tuple[str, ...] = ('rotor_inertia_motor_side', 'viscous')
        if self.friction != 'viscous':
            names += ('coulomb',)
        if self.friction == 'viscous_coulomb_offset':
            names += ('offset',)
        return names


class RneaLqModel(_NominalPhysics):
    """The study's RNEA+LQ: the URDF model plus per-joint drive terms fitted by least squares.

    Per joint j, on the training part (fit + validation rows):

        tau_j = RNEA_URDF(q, v, a)_j + I_M,j * gear_ratio_j**2 * a_j + friction_j(v_j)
        friction_j = theta_D,j * v_j [+ F_c,j * tanh(v_j / v_eps)] [+ offset_j]

    with I_M, theta_D and F_c >= 0 (``_solve``): where the unconstrained least squares would
    make one negative (non-physical: loading refuses such a model), it is held at zero, with a
    warning naming the joint and the value the data wanted if the label noise cannot explain it.

    The study's viscous-only friction leaves most friction unexplained: real gearboxes add
    Coulomb (and Stribeck, load-dependent) friction that a linear viscous term cannot follow,
    so 'viscous_coulomb' or 'viscous_coulomb_offset' are offered as options. The rigid-body
    parameters stay the URDF's; nothing here corrects a wrong mass or centre of mass.

    Components: inertial M(q) a, coriolis C(q, v) v and gravity g(q) of the nominal model,
    rotor_inertia I_M N**2 a, friction the velocity-dependent terms; the constant offset, which
    cannot be told apart from a current-sensor offset, is the residual (None without it).
    """

    kind: ClassVar[str] = 'rnea_lq'

    def __init__(self, config: RneaLqConfig, robot: RobotConfig) -> None:
        """Store the settings; no I/O, no fitting."""
        super().__init__(config, robot)
        self.config: RneaLqConfig = config
        self.parameters_: dict[str, np.ndarray] | None = None
        self.training_rmse_: np.ndarray | None = None

    def _columns(self, v: np.ndarray, rotor_basis: np.ndarray) -> dict[str, np.ndarray]:
        """Regressor columns (N, n) per parameter: tau_model = rnea + sum(theta * column)."""
        names = self.config.parameter_names
        columns = {'rotor_inertia_motor_side': rotor_basis, 'viscous': v}
        if 'coulomb' in names:
            columns['coulomb'] = coulomb(v, self.config.coulomb_velocity)
        if 'offset' in names:
            columns['offset'] = np.ones_like(v)
        return columns

    def fit(self, data: TrainingData, *, progress: bool = False) -> Self:
        """Solve the per-joint least-squares problems on the training part of ``data``."""
        data.require_varied(self.kind, inputs=False)
        del progress  # a few small solves
        ds, physics, rows = data.dataset, data.physics, data.train_rows
        columns = self._columns(ds.v, physics.rotor_basis)
        rnea = physics.rnea
        if ds.is_through_filter:
            # Filter whole recordings, as preprocessing filtered the labels, then take the
            # training rows: a slice filtered alone would add start-up transients at its ends.
            rnea = ds.filter_like_labels(rnea)
            columns = {
                name: column if name == 'offset' else ds.filter_like_labels(column)
                for name, column in columns.items()
            }
        target = ds.tau[rows] - rnea[rows]
        names = list(columns)
        n = self.robot.n_joints
        theta = np.zeros((len(names), n))
        rmse = np.zeros(n)
        for j in range(n):
            regressor = np.stack([columns[name][rows, j] for name in names], axis=1)
            gain = label_noise_gain(ds, rows, j)
            theta[:, j] = self._solve(
                regressor, target[:, j], names, j, label=ds.tau[rows, j], noise_gain=gain
            )
            rmse[j] = np.sqrt(np.mean((regressor @ theta[:, j] - target[:, j]) ** 2))
        self.parameters_ = {name: np.zeros(n) for name in LQ_PARAMETERS}
        for name, values in zip(names, theta, strict=True):
            self.parameters_[name] = values
        self.training_rmse_ = rmse
        _LOG.info('rnea_lq: %s, training RMSE %s N*m', self.parameters_, np.round(rmse, 3))
        return self

    def _solve(
        self,
        regressor: np.ndarray,
        target: np.ndarray,
        names: list[str],
        joint: int,
        *,
        label: np.ndarray | None = None,
        noise_gain: NoiseGain | None = None,
    ) -> np.ndarray:
        """One joint's parameters: least squares, the physically signed ones held >= 0.

        A rotor inertia below zero, or friction that drives the joint, is no drive: where the
        unconstrained solution wants one, it is held at zero and the others are fitted around it.
        A warning calls it a finding (the URDF's model of what the joint moves is off, and the term
        soaked that up) only beyond LQ_FINDING_T and LQ_FINDING_SHARE, on ``label`` (default
        ``target``) with noise as ``noise_gain`` (default white). Zero columns get zero.
        """
        # Columns scaled to unit RMS, so that rotor (~1e4 * a) and offset columns are equally
        # well conditioned.
        norm = np.sqrt(np.mean(regressor**2, axis=0))
        used = norm > 0
        out = np.zeros(len(names))
        if not used.any():
            return out
        scaled = regressor[:, used] / norm[used]
        free, *_ = np.linalg.lstsq(scaled, target, rcond=None)
        signed = np.array([name in LQ_NON_NEGATIVE for name in names])[used]
        if np.any(free[signed] < 0):
            from scipy.optimize import lsq_linear

            weights = scaled @ np.linalg.pinv(scaled.T @ scaled)  # free = weights^T target
            gain = np.sum(weights**2, axis=0) if noise_gain is None else noise_gain(weights)
            t = free / np.sqrt(np.maximum(np.mean((target - scaled @ free) ** 2) * gain, 1e-300))
            label_rms = np.sqrt(np.mean((target if label is None else label) ** 2))
            share = np.abs(free) / max(label_rms, 1e-300)  # |free|: the term's torque RMS
            held = {
                f'{name} at {value:.4g} {LQ_PARAMETERS[name]} ({LQ_NON_NEGATIVE[name]}; t = '
                f'{t_i:.3g}, {100 * s_i:.2g} % of the label RMS)': t_i <= LQ_FINDING_T
                and s_i >= LQ_FINDING_SHARE
                for name, value, t_i, s_i in zip(
                    np.array(names)[used], free / norm[used], t, share, strict=True
                )
                if name in LQ_NON_NEGATIVE and value < 0
            }
            lower = np.where(signed, 0.0, -np.inf)
            free = lsq_linear(scaled, target, bounds=(lower, np.inf), method='bvls').x
            joint_name = self.robot.joints[joint]
            if noise := ', '.join(text for text, found in held.items() if not found):
                _LOG.debug('rnea_lq: %s: %s: noise or negligible, held at 0', joint_name, noise)
            if findings := [text for text, found in held.items() if found]:
                _LOG.warning(
                    'rnea_lq: %s: least squares put %s, non-physical: held at 0; the URDF model '
                    'of what this joint moves is likely off, and rnea_lq cannot absorb that',
                    joint_name,
                    ', '.join(findings),
                )
        out[used] = free / norm[used]
        return out

    def _parameters(self) -> dict[str, np.ndarray]:
        require_fitted(self, self.parameters_)
        assert self.parameters_ is not None
        return self.parameters_

    def _drive_terms(self, v: np.ndarray, a: np.ndarray) -> dict[str, np.ndarray]:
        """Rotor inertia, velocity-dependent friction and offset torques, (B, n) [N*m]."""
        p = self._parameters()
        gear = self.robot.drives.gear_ratio
        friction = p['viscous'] * v
        if 'coulomb' in self.config.parameter_names:
            friction = friction + p['coulomb'] * coulomb(v, self.config.coulomb_velocity)
        return {
            'rotor_inertia': rotor_inertia_torque(a, p['rotor_inertia_motor_side'], gear),
            'friction': friction,
            'offset': np.broadcast_to(p['offset'], v.shape),
        }

    def predict(self, q: np.ndarray, v: np.ndarray, a: np.ndarray) -> np.ndarray:
        """Torque (B, n) [N*m] for q, v, a (B, n) [rad, rad/s, rad/s^2]."""
        q, v, a = _states(q, v, a)
        drive = self._drive_terms(v, a)
        rigid_body = self.dynamics.rnea(q, v, a)
        torque: np.ndarray = (
            rigid_body + drive['rotor_inertia'] + drive['friction'] + drive['offset']
        )
        return torque

    def sample_predictor(self) -> SamplePredictor:
        """One sample's torque, the terms of ``predict`` folded: q, v, a (n,) -> tau (n,)."""
        p = self._parameters()
        rotor = rotor_inertia_joint_side(
            p['rotor_inertia_motor_side'], self.robot.drives.gear_ratio
        )
        viscous, level, offset = p['viscous'], p['coulomb'], p['offset']
        has_coulomb = 'coulomb' in self.config.parameter_names
        smoothing = self.config.coulomb_velocity
        rnea = self.sample_rnea()

        def predict_one(q: np.ndarray, v: np.ndarray, a: np.ndarray) -> np.ndarray:
            tau: np.ndarray = rnea(q, v, a) + rotor * a + viscous * v + offset
            if has_coulomb:
                tau += level * coulomb(v, smoothing)
            return tau

        return predict_one

    def components(self, q: np.ndarray, v: np.ndarray, a: np.ndarray) -> TorqueComponents:
        """Nominal rigid-body parts, fitted rotor inertia and friction; offset as residual."""
        q, v, a = _states(q, v, a)
        drive = self._drive_terms(v, a)
        has_offset = 'offset' in self.config.parameter_names
        return TorqueComponents(
            total=self.predict(q, v, a),
            **self.rigid_body_parts(q, v, a),
            rotor_inertia=drive['rotor_inertia'],
            friction=drive['friction'],
            residual=drive['offset'].copy() if has_offset else None,
        )

    def state(self) -> dict[str, np.ndarray]:
        """The fitted parameters, (n,) each, named as in LQ_PARAMETERS (zeros where not fitted)."""
        return {name: values.copy() for name, values in self._parameters().items()}

    def load_state(self, tensors: dict[str, np.ndarray], fitted: dict[str, Any]) -> None:
        """Restore the fitted parameters.

        Raises:
            CheckpointError: a parameter is missing or has the wrong shape.
        """
        n = self.robot.n_joints
        shapes = {name: np.shape(value) for name, value in tensors.items()}
        if shapes != dict.fromkeys(LQ_PARAMETERS, (n,)):
            raise CheckpointError(
                f'rnea_lq: expected tensors {sorted(LQ_PARAMETERS)} of shape ({n},), got {shapes}'
            )
        self.parameters_ = {name: np.asarray(tensors[name], dtype=float) for name in LQ_PARAMETERS}
        rmse = fitted.get('training_rmse_nm')
        self.training_rmse_ = None if rmse is None else np.asarray(rmse, dtype=float)

    def fitted_metadata(self) -> dict[str, Any]:
        """The identified parameters per joint with their units, and the fit's RMSE.

        ``training_rmse_nm`` is the least-squares residual on the training rows, measured on the
        filtered regressors when fitting through the label filter.
        """
        p = self._parameters()
        out: dict[str, Any] = {
            'parameters': {name: p[name].tolist() for name in self.config.parameter_names},
            'units': {name: LQ_PARAMETERS[name] for name in self.config.parameter_names},
        }
        if self.training_rmse_ is not None:
            out['training_rmse_nm'] = self.training_rmse_.tolist()
        return out


# -- RNEA + MLP ----------------------------------------------------------------------------------
@dataclass(frozen=True)
class RneaMlpConfig(NetworkConfig):
    """The Newtonian network's settings: the MLP h(q, v) and its training.

    Attributes:
        width: units per hidden layer of h.
        depth: hidden layers of h.
        activation: hidden activation of h.
    """

    # str, not a Literal: the rnea_id_mlp and rnea_effects_mlp configs extend this one.
    kind: str = 'rnea_mlp'
    width: int = 64
    depth: int = 2
    activation: str = 'tanh'
    stride: int = 2

    def __post_init__(self) -> None:
        """Check ranges, naming the key."""
        check_kind(self)  # 'rnea_mlp', or a subclass's own kind
        super().__post_init__()
        check_mlp_shape(self, self.width, self.depth, self.activation)


class RneaMlpModel(_NominalPhysics, TorchModel[NormalisedMlp]):
    """The study's Newtonian network: tau = RNEA_URDF(q, v, a) + I_M N**2 a + h(q, v).

    The physics parameters are fixed (URDF and the robot config's datasheet rotor inertia); with
    joint-torque labels the physics holds the link-side terms only (no rotor inertia: a joint
    torque sensor at the gear output never sees the motor's inertia). The MLP h learns the
    remainder from (q, v), both scaled with the dataset's input scaler. Its output is scaled by
    the training residual's own range, and it is trained on the study's normalised MSE of the
    whole torque (each joint divided by the target's half range).

    Components: the nominal rigid-body parts and the datasheet rotor inertia, then h split in
    two. friction is h's velocity-dependent part, h(q, v) - h(q, 0): the dissipation the study
    attributes h to, plus any velocity-dependent model error. residual is h(q, 0), the part that
    does not vanish at rest: gravity and payload errors, offsets. Calling all of h friction would
    attribute those to friction; h takes q as well, and learns them too.
    """

    kind: ClassVar[str] = 'rnea_mlp'

    def __init__(self, config: RneaMlpConfig, robot: RobotConfig) -> None:
        """Store the settings; no I/O, no fitting."""
        super().__init__(config, robot)
        self.config: RneaMlpConfig = config
        self.state_scaler_: MinMaxScaler | None = None
        self.residual_scaler_: MinMaxScaler | None = None
        #: The label the model was fitted on: 'motor' (tau_u) or 'joint' (joint torque).
        self.target_ = 'motor'

    def _build(self, state_scaler: MinMaxScaler, residual_scaler: MinMaxScaler) -> NormalisedMlp:
        n, c = self.robot.n_joints, self.config
        network = seeded(c.seed, lambda: NormalisedMlp(2 * n, n, c.width, c.depth, c.activation))
        network.set_scaling(centre_and_half(state_scaler), centre_and_half(residual_scaler))
        self.state_scaler_, self.residual_scaler_ = state_scaler, residual_scaler
        return network

    def physics_torque(self, q: np.ndarray, v: np.ndarray, a: np.ndarray) -> np.ndarray:
        """RNEA_URDF(q, v, a) + I_M N**2 a with datasheet I_M: (B, n) [N*m]."""
        q, v, a = _states(q, v, a)
        torque: np.ndarray = self.dynamics.rnea(q, v, a) + self._rotor_torque(a)
        return torque

    def physics_sample_predictor(self) -> SamplePredictor:
        """``physics_torque`` of one sample, (n,) q, v, a -> (n,) [N*m]: the prior without h."""

        def physics(q: np.ndarray, v: np.ndarray, a: np.ndarray) -> np.ndarray:
            tau: np.ndarray = self.physics_torque(q[None], v[None], a[None])[0]
            return tau

        return physics

    @property
    def _rotor_joint_side(self) -> np.ndarray:
        """J_m N^2 [kg*m^2] per joint for motor labels; zero for joint-torque labels."""
        drives = self.robot.drives
        rotor = rotor_inertia_joint_side(drives.rotor_inertia, drives.gear_ratio)
        return rotor if self.target_ == 'motor' else np.zeros_like(rotor)

    def _rotor_torque(self, a: np.ndarray) -> np.ndarray:
        torque: np.ndarray = self._rotor_joint_side * a
        return torque

    def training_physics(self, data: TrainingData) -> np.ndarray:
        """The physics part's torque on every sample of ``data``; h learns the rest."""
        torque: np.ndarray = data.physics.rnea + self._rotor_torque(data.dataset.a)
        return torque

    def fit(self, data: TrainingData, *, progress: bool = False) -> Self:
        """Fit h on the training residual, with early stopping on the validation tail.

        Through the label filter (the default), the residual is the label minus the physics
        part filtered like it, and h's torque is filtered before it meets that residual.
        """
        data.require_varied(self.kind)
        ds, c, n = data.dataset, self.config, self.robot.n_joints
        device = select_device(c.device)
        self.target_ = ds.target
        physics = self.training_physics(data)
        if ds.is_through_filter:
            physics = ds.filter_like_labels(physics)
        residual = ds.tau - physics
        assert ds.input_scaler.low_ is not None
        assert ds.input_scaler.high_ is not None
        state_scaler = MinMaxScaler(ds.input_scaler.low_[: 2 * n], ds.input_scaler.high_[: 2 * n])
        network = self._build(state_scaler, MinMaxScaler().fit(residual[data.train_rows]))
        states = to_tensor(np.hstack([ds.q, ds.v]), device)

        def predict(rows: torch.Tensor, positions: torch.Tensor) -> torch.Tensor:
            torque: torch.Tensor = network(states[rows[:, positions]])
            return torque

        self._fit_network(
            network,
            predict,
            data,
            residual,
            ds.target_scaler.scale(),
            config=c,
            device=device,
            progress=progress,
        )
        return self

    def residual_torque(self, q: np.ndarray, v: np.ndarray) -> np.ndarray:
        """The learned remainder h(q, v): (B, n) [N*m]."""
        return predict_chunked(self.network(), np.hstack([np.atleast_2d(q), np.atleast_2d(v)]))

    def predict(self, q: np.ndarray, v: np.ndarray, a: np.ndarray) -> np.ndarray:
        """Torque (B, n) [N*m] for q, v, a (B, n) [rad, rad/s, rad/s^2]."""
        q, v, a = _states(q, v, a)
        torque: np.ndarray = self.physics_torque(q, v, a) + self.residual_torque(q, v)
        return torque

    def sample_predictor(self) -> SamplePredictor:
        """One sample's torque, with h in float64 numpy: q, v, a (n,) -> tau (n,) [N*m]."""
        h = NumpyNormalisedMlp(self.network())
        rotor = self._rotor_joint_side
        rnea, concatenate = self.sample_rnea(), np.concatenate

        def predict_one(q: np.ndarray, v: np.ndarray, a: np.ndarray) -> np.ndarray:
            tau: np.ndarray = rnea(q, v, a) + rotor * a + h(concatenate((q, v)))
            return tau

        return predict_one

    def components(self, q: np.ndarray, v: np.ndarray, a: np.ndarray) -> TorqueComponents:
        """Nominal rigid-body parts, datasheet rotor inertia, h split into friction + residual."""
        q, v, a = _states(q, v, a)
        h = self.residual_torque(q, v)
        h_rest = self.residual_torque(q, np.zeros_like(v))
        return TorqueComponents(
            total=self.physics_torque(q, v, a) + h,
            **self.rigid_body_parts(q, v, a),
            rotor_inertia=self._rotor_torque(a) if self.target_ == 'motor' else None,
            friction=h - h_rest,
            residual=h_rest,
        )

    def load_state(self, tensors: dict[str, np.ndarray], fitted: dict[str, Any]) -> None:
        """Rebuild h from the scalers in ``fitted`` and load its weights.

        Raises:
            CheckpointError: the scalers are missing or the tensors do not fit the config.
        """
        scalers = load_scalers(fitted, ('state_scaler', 'residual_scaler'), self.kind)
        self._load_network(self._build(*scalers), tensors, fitted)
        # Artifacts written before the target was recorded were all fitted on tau_u.
        self.target_ = str(fitted.get('target', 'motor'))

    def fitted_metadata(self) -> dict[str, Any]:
        """The scalers of h's inputs (q, v) and output, the physics constants, a fit summary."""
        require_fitted(self, self.state_scaler_)
        assert self.state_scaler_ is not None
        assert self.residual_scaler_ is not None
        out = scalers_metadata(
            state_scaler=self.state_scaler_, residual_scaler=self.residual_scaler_
        )
        out['target'] = self.target_
        out['rotor_inertia_motor_side_kgm2'] = self.robot.drives.rotor_inertia.tolist()
        return {**out, **self._history_metadata()}
