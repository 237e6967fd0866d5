"""Lagrangian networks: DeLaN, the black-box LNN, and the LNN plus a dissipation network.

All three predict the torque through the Euler-Lagrange equations of a learned Lagrangian
``L(q, v)``::

    tau = d/dt (dL/dv) - dL/dq = (d2L/dv2) a + (d2L/dq dv) v - dL/dq

- **DeLaN** (Lutter et al., ICLR 2019): ``L = 1/2 v^T M(q) v - V(q)`` with ``M = L_c L_c^T`` from
  a network for the lower-triangular Cholesky factor ``L_c(q)`` (positive diagonal: softplus
  plus a small epsilon) and a network for the potential ``V(q)``. The torque is
  ``M a + Mdot v - 1/2 d/dq (v^T M v) + dV/dq`` with exact derivatives (AnalyticMLP.jacobian).
- **LNN** (Cranmer et al. 2020; DeLaN's "black box"): one network for ``L(q, v)``; its gradient
  and the Hessian-vector product with ``(v, a)`` (AnalyticMLP.gradient_and_hvp) give the torque.
- **LNN+MLP**: the LNN plus an MLP ``h(q, v)`` for the dissipative torque a Lagrangian cannot
  represent (the reference study's remedy for friction in motor-torque labels).

The networks live in ``models.delan`` and ``models.lnn``, their normalisation (inputs mapped to
[-1, 1] with the dataset's min-max scalers, outputs given physical units by fixed factors built
from the training ranges) in ``models.lagrangian_base``. This module holds the configs and the
model classes that fit, predict, save and load them, and re-exports the network names.

The loss is the mean squared torque error on the study's normalised scale (each joint divided
by its half range ``h_tau``).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import Any, ClassVar, Literal, Self

import numpy as np
import torch

from id_learning.dataset.preprocess import MinMaxScaler
from id_learning.errors import CheckpointError, ConfigError, DatasetError
from id_learning.models.base import (
    ModelConfig,
    SamplePredictor,
    TorqueComponents,
)
from id_learning.models.blackbox import check_kind
from id_learning.models.data import TrainingData
from id_learning.models.delan import DelanNetwork, euler_lagrange_torque
from id_learning.models.fitting import OptimConfig, select_device
from id_learning.models.lagrangian_base import LagrangianNetwork, LagrangianScaling, energy_scale
from id_learning.models.lnn import LnnMlpNetwork, LnnNetwork
from id_learning.models.nets import INITIALISATIONS, SMOOTH_ACTIVATIONS
from id_learning.models.torch_model import TorchModel
from id_learning.models.torch_utils import to_numpy, to_tensor
from id_learning.robot.config import RobotConfig

__all__ = [
    'DelanConfig',
    'DelanModel',
    'DelanNetwork',
    'LagrangianConfig',
    'LagrangianModel',
    'LagrangianNetwork',
    'LagrangianScaling',
    'LnnConfig',
    'LnnMlpConfig',
    'LnnMlpModel',
    'LnnMlpNetwork',
    'LnnModel',
    'LnnNetwork',
    'energy_scale',
    'euler_lagrange_torque',
]

#: predict() evaluates at most this many samples at once (bounds DeLaN's (B, n, n, n) tensors).
_PREDICT_CHUNK = 32768

_DEVICES = ('auto', 'cpu', 'cuda')


@dataclass(frozen=True)
class LagrangianConfig(ModelConfig):
    """Settings shared by the Lagrangian models.

    Defaults: 2 hidden layers of 64 tanh units (the study's and the DeLaN reference's size and
    activation); Adam with learning rate 1e-3, mini-batches of 256, weight decay 1e-3 and
    early stopping after 30 epochs without progress, on every 4th sample: chosen on the
    validation loss of the shipped bag (motor torque target).

    Attributes:
        width: units per hidden layer.
        depth: hidden layers.
        activation: 'tanh' or 'softplus' (needs a smooth second derivative).
        init: the networks' initial weights, 'xavier' (the default) or 'fan_in' (truncated
            normal, std 1 / sqrt(fan_in): the DeLaN reference's; what the LNN needs on the
            character benchmark).
        energy_balance: exponent b of the scalar nets' input gains ``(e_i / e_max)^b``
            (``models.lagrangian_base``): 0 leaves the inputs on [-1, 1]; larger values make the
            joints' normalised torques more equally sensitive to the net, which a heavy arm's
            shoulder needs (its gravity is otherwise never learned). 0.75: on the rigid-body
            MABI twin (10 min, joint torques) DeLaN's test RMSE on joints 2 / 3 is 460 / 147
            N*m at 0.75, 521 / 168 at 1 (the wrist's nonlinear gravity out of reach), and the
            LNN's 516 / 134 at 0.75 against 2760 / 761 unbalanced.
        learning_rate: Adam step size.
        batch_size: samples per mini-batch.
        max_epochs: upper bound on epochs.
        patience: early stopping after this many epochs without a better validation loss.
        weight_decay: Adam's L2 penalty.
        lr_decay: learning-rate factor on a validation plateau (``OptimConfig``); 1 for none.
        lr_decay_patience: epochs without progress before each decay.
        stride: the study's preprocessing: use every stride-th sample (the data are low-pass
            filtered far below the IPO rate, so neighbours carry almost the same information).
        windows_per_batch: through the filter: contiguous windows per mini-batch.
        eval_stride: through the filter: evaluate the network on every eval_stride-th sample
            of a window (``models.through_filter``).
        seed: seeds the initial weights and the batch order.
        max_seconds: wall-clock budget of the fit [s], None for none.
        device: 'auto' (CUDA when available), 'cpu' or 'cuda'. Prediction runs on the CPU.
    """

    kind: str = ''
    width: int = 64
    depth: int = 2
    activation: str = 'tanh'
    init: str = 'xavier'
    energy_balance: float = 0.75
    learning_rate: float = 1e-3
    batch_size: int = 256
    max_epochs: int = 300
    patience: int = 30
    weight_decay: float = 1e-3
    lr_decay: float = 1.0
    lr_decay_patience: int = 15
    stride: int = 4
    windows_per_batch: int = 2
    eval_stride: int = 2
    seed: int = 0
    max_seconds: float | None = None
    device: str = 'auto'

    def __post_init__(self) -> None:
        """Check ranges, naming the key."""
        keys = ('width', 'depth', 'batch_size', 'max_epochs', 'patience', 'stride')
        for key in (*keys, 'windows_per_batch', 'eval_stride'):
            value = getattr(self, key)
            if not isinstance(value, int) or value < 1:
                raise ConfigError(f'{self.kind}: {key} must be an integer >= 1, got {value!r}')
        for key in self._activation_keys():
            if getattr(self, key) not in SMOOTH_ACTIVATIONS:
                raise ConfigError(
                    f'{self.kind}: {key} must be one of {sorted(SMOOTH_ACTIVATIONS)} '
                    f'(a Lagrangian needs smooth second derivatives), got {getattr(self, key)!r}'
                )
        if self.init not in INITIALISATIONS:
            raise ConfigError(
                f'{self.kind}: init must be one of {INITIALISATIONS}, got {self.init!r}'
            )
        if not 0.0 <= self.energy_balance <= 1.0:
            raise ConfigError(
                f'{self.kind}: energy_balance must be in [0, 1], got {self.energy_balance}'
            )
        if not self.learning_rate > 0:
            raise ConfigError(f'{self.kind}: learning_rate must be > 0, got {self.learning_rate}')
        if self.weight_decay < 0:
            raise ConfigError(f'{self.kind}: weight_decay must be >= 0, got {self.weight_decay}')
        if self.max_seconds is not None and not self.max_seconds > 0:
            raise ConfigError(
                f'{self.kind}: max_seconds must be > 0 or None, got {self.max_seconds}'
            )
        if self.device not in _DEVICES:
            raise ConfigError(
                f'{self.kind}: device must be one of {_DEVICES}, got {self.device!r}'
            )
        try:
            self.optim()
        except ConfigError as err:
            raise ConfigError(f'{self.kind}: {err}') from err

    def _activation_keys(self) -> tuple[str, ...]:
        return ('activation',)

    def optim(self) -> OptimConfig:
        """The optimiser settings for train_module."""
        return OptimConfig(
            learning_rate=self.learning_rate,
            batch_size=self.batch_size,
            max_epochs=self.max_epochs,
            patience=self.patience,
            weight_decay=self.weight_decay,
            seed=self.seed,
            max_seconds=self.max_seconds,
            lr_decay=self.lr_decay,
            lr_decay_patience=self.lr_decay_patience,
        )


@dataclass(frozen=True)
class DelanConfig(LagrangianConfig):
    """DeLaN settings (see LagrangianConfig for the shared ones).

    Defaults differ from the shared ones where the heavy arm showed the need (rigid-body
    joint-torque twin recording, 10 min, through the filter; see docs/training.md): the fully
    balanced scaling (``energy_balance`` 1, the Cholesky network on the balanced positions too)
    lets the shoulder's gravity be learned at all, and with it the potential's weights must grow
    to order one, which a strong weight decay fights (test RMSE on joints 2 / 3: 2690 / 716 N*m
    with the plain scaling and decay 1e-2; 363 / 108 balanced with decay 1e-4, 325 / 110 without,
    the wrists slightly better with it); the patience and epoch limit leave room for the slow
    balanced fits.

    Attributes:
        energy_balance: 1 (the shared default is 0.75). Seeds 0 / 1 / 2 beat the MLP on 5 / 4 / 5
            of the 6 joints of that recording (0.75: 3 of 6).
        weight_decay: 1e-4 (the shared default is 1e-3).
        patience: 60 epochs.
        max_epochs: 600.
        diagonal_epsilon: lower bound of the Cholesky diagonal on the unit scale, keeps M(q)
            positive definite (M_ii >= e_i * epsilon^2 / h_v,i^2).
        diagonal_shift: added before the diagonal's softplus (softplus(0) = 0.69 at the start).
    """

    kind: Literal['delan'] = 'delan'
    energy_balance: float = 1.0
    weight_decay: float = 1e-4
    patience: int = 60
    max_epochs: int = 600
    diagonal_epsilon: float = 1e-3
    diagonal_shift: float = 0.0

    def __post_init__(self) -> None:
        """Check ranges, naming the key."""
        super().__post_init__()
        if not self.diagonal_epsilon > 0:
            raise ConfigError(f'delan: diagonal_epsilon must be > 0, got {self.diagonal_epsilon}')


@dataclass(frozen=True)
class LnnConfig(LagrangianConfig):
    """LNN settings (see LagrangianConfig)."""

    kind: Literal['lnn'] = 'lnn'


@dataclass(frozen=True)
class LnnMlpConfig(LagrangianConfig):
    """LNN+MLP settings (see LagrangianConfig for the shared ones).

    Attributes:
        dissipation_width: units per hidden layer of the dissipation MLP.
        dissipation_depth: its hidden layers.
        dissipation_activation: its activation.
    """

    # str, not a Literal: the lnn_mlp_id config extends this one.
    kind: str = 'lnn_mlp'
    dissipation_width: int = 64
    dissipation_depth: int = 2
    dissipation_activation: str = 'tanh'

    def __post_init__(self) -> None:
        """Check ranges, naming the key."""
        check_kind(self)  # 'lnn_mlp', or a subclass's own kind
        super().__post_init__()
        for key in ('dissipation_width', 'dissipation_depth'):
            value = getattr(self, key)
            if not isinstance(value, int) or value < 1:
                raise ConfigError(f'{self.kind}: {key} must be an integer >= 1, got {value!r}')

    def _activation_keys(self) -> tuple[str, ...]:
        return ('activation', 'dissipation_activation')


class LagrangianModel(TorchModel[LagrangianNetwork]):
    """Fit, predict, save and load shared by the Lagrangian models.

    Fitted state: ``network_`` (on the CPU, float32), ``scaling_`` and ``history_``.
    """

    config: LagrangianConfig
    history_key: ClassVar[str] = 'history'
    #: The network the kind builds, and the config's keys it takes as keywords.
    network_class: ClassVar[type[LagrangianNetwork]]
    network_keys: ClassVar[tuple[str, ...]] = ('width', 'depth', 'activation', 'init')

    def __init__(self, config: ModelConfig, robot: RobotConfig) -> None:
        """Store the settings; no I/O, no fitting.

        Raises:
            ConfigError: the config is of another model kind.
        """
        if getattr(config, 'kind', None) != self.kind:
            raise ConfigError(
                f'{type(self).__name__} needs a {self.kind!r} config, got {config!r}'
            )
        super().__init__(config, robot)
        self.scaling_: LagrangianScaling | None = None

    def make_network(
        self, scaling: LagrangianScaling, generator: torch.Generator
    ) -> LagrangianNetwork:
        """Build an untrained network of this configuration, weights drawn from generator."""
        build: Callable[..., LagrangianNetwork] = self.network_class
        settings = {key: getattr(self.config, key) for key in self.network_keys}
        return build(scaling, generator=generator, **settings)

    def fit(self, data: TrainingData, *, progress: bool = False) -> Self:
        """Fit the torque to the labels; early stopping on the validation rows.

        Minimises the mean squared torque error on the normalised scale (``fit_network``):
        through the label filter on contiguous windows (the default), or the study's way on
        every stride-th sample. Trains on ``config.device``; the fitted network is moved to the
        CPU for prediction.

        Raises:
            DatasetError: the dataset's joints are not the robot's.
        """
        data.require_varied(self.kind)
        dataset = data.dataset
        if tuple(dataset.joints) != tuple(self.joint_names):
            raise DatasetError(
                f'{self.kind}: dataset joints {list(dataset.joints)} are not the robot '
                f'joints {list(self.joint_names)}'
            )
        config = self.config
        device = select_device(config.device)
        target, loss_scale, learned = self.training_target(data)
        scaling = LagrangianScaling.from_dataset(
            dataset, balance=config.energy_balance, torque=learned
        )
        network = self.make_network(scaling, torch.Generator().manual_seed(config.seed))
        q, v, a = (to_tensor(x, device) for x in (dataset.q, dataset.v, dataset.a))
        n = len(self.joint_names)

        def predict(rows: torch.Tensor, positions: torch.Tensor) -> torch.Tensor:
            index = rows[:, positions]
            flat = index.reshape(-1)
            torque: torch.Tensor = network(q[flat], v[flat], a[flat])
            return torque.reshape(*index.shape, n)

        self._fit_network(
            network,
            predict,
            data,
            target,
            loss_scale,
            config=config,
            device=device,
            progress=progress,
        )
        self.scaling_ = scaling
        return self

    def training_target(
        self, data: TrainingData
    ) -> tuple[np.ndarray, np.ndarray, MinMaxScaler | None]:
        """What the network learns, for ``fit``: the labels, by default.

        Returns:
            The target (N, n) [N*m] on every sample, the loss's scale per joint (n,) [N*m] (the
            study's: the labels' half range) and the target's range on the training part that
            scales the network's torque (``LagrangianScaling``; None: the labels').
        """
        return data.dataset.tau, data.dataset.target_scaler.scale(), None

    def _evaluate(
        self, q: np.ndarray, v: np.ndarray, a: np.ndarray, *, parts: bool
    ) -> dict[str, np.ndarray]:
        network = self.network()
        chunks: list[dict[str, np.ndarray]] = []
        with torch.inference_mode():
            for start in range(0, max(len(q), 1), _PREDICT_CHUNK):
                rows = slice(start, start + _PREDICT_CHUNK)
                q_t, v_t, a_t = to_tensor(q[rows]), to_tensor(v[rows]), to_tensor(a[rows])
                if parts:
                    out = network.components(q_t, v_t, a_t)
                else:
                    out = {'total': network(q_t, v_t, a_t)}
                chunks.append({name: to_numpy(value) for name, value in out.items()})
        if len(chunks) == 1:
            return chunks[0]
        return {name: np.concatenate([c[name] for c in chunks]) for name in chunks[0]}

    def predict(self, q: np.ndarray, v: np.ndarray, a: np.ndarray) -> np.ndarray:
        """Torque (B, n) [N*m] for q [rad], v [rad/s], a [rad/s^2], each (B, n)."""
        return self._evaluate(q, v, a, parts=False)['total']

    def sample_predictor(self) -> SamplePredictor:
        """One sample's torque in float64 numpy (the networks' analytic derivatives)."""
        return self.network().sample_predictor()

    def components(self, q: np.ndarray, v: np.ndarray, a: np.ndarray) -> TorqueComponents:
        """Inertial, Coriolis/centrifugal and gravity parts (and friction where modelled)."""
        parts = self._evaluate(q, v, a, parts=True)
        return TorqueComponents(total=self.predict(q, v, a), **parts)

    def load_state(self, tensors: dict[str, np.ndarray], fitted: dict[str, Any]) -> None:
        """Rebuild the network from the fitted scaling and load the weights.

        Raises:
            CheckpointError: the scaling is missing or the weights do not fit the network.
        """
        try:
            scaling = LagrangianScaling.from_dict(fitted['scaling'])
        except (KeyError, TypeError, ValueError) as err:
            raise CheckpointError(
                f'{self.kind}: fitted metadata lacks a valid scaling: {err}'
            ) from err
        if scaling.n_dof != len(self.joint_names):
            raise CheckpointError(
                f'{self.kind}: scaling is for {scaling.n_dof} joints, '
                f'the robot has {len(self.joint_names)}'
            )
        if scaling.balance != self.config.energy_balance:
            # An artifact from before the balance (or edited): the scaling it was fitted with
            # rules, and the config says so too.
            self.config = replace(self.config, energy_balance=scaling.balance)
        network = self.make_network(scaling, torch.Generator().manual_seed(self.config.seed))
        self._load_network(network, tensors, fitted)
        self.scaling_ = scaling

    def fitted_metadata(self) -> dict[str, Any]:
        """The scaling (scalers and energy scale) and the training history."""
        if self.scaling_ is None:
            return {}
        return {'scaling': self.scaling_.to_dict(), **self._history_metadata()}


class DelanModel(LagrangianModel):
    """Deep Lagrangian Network: torque from a learned mass matrix M(q) and potential V(q).

    Components: inertial M a, Coriolis/centrifugal, gravity dV/dq; friction None (a
    Lagrangian model has no dissipation).
    """

    kind: ClassVar[str] = 'delan'
    config: DelanConfig
    network_class = DelanNetwork
    network_keys = (*LagrangianModel.network_keys, 'diagonal_epsilon', 'diagonal_shift')

    def mass_matrix(self, q: np.ndarray) -> np.ndarray:
        """M(q) (B, n, n) [kg*m^2] for q (B, n) [rad]."""
        network = self.network()
        assert isinstance(network, DelanNetwork)
        with torch.inference_mode():
            return to_numpy(network.mass_matrix(to_tensor(q)))


class LnnModel(LagrangianModel):
    """Black-box Lagrangian network: torque from the derivatives of one learned L(q, v).

    Components (a convention for a general L): inertial (d2L/dv2) a, gravity -dL/dq at v = 0,
    Coriolis the rest; friction None.
    """

    kind: ClassVar[str] = 'lnn'
    config: LnnConfig
    network_class = LnnNetwork


class LnnMlpModel(LagrangianModel):
    """LNN plus an MLP h(q, v) for dissipative torques; components as LNN, friction = h."""

    kind: ClassVar[str] = 'lnn_mlp'
    config: LnnMlpConfig
    network_class = LnnMlpNetwork
    network_keys = (
        *LagrangianModel.network_keys,
        *('dissipation_width', 'dissipation_depth', 'dissipation_activation'),
    )
