"""The study's black-box baselines: an MLP on (q, v, a) and an LSTM on windows of past samples.

Both map physical inputs to the model's target torque [N*m]; the dataset's min-max scalers
(fitted on the training part) are built into the networks as fixed buffers, so a network sees
(q, v, a) on [-1, 1] and emits the torque on the target scaler's [-1, 1] scale. The loss is the
study's normalised MSE: the squared error of each joint divided by that joint's half range.

The settings shared by every network model (optimiser, early stopping, seed, device, row stride)
live in :class:`NetworkConfig`; the Newtonian network in ``physics.py`` uses them too. This
module holds the configs and the two model classes; the normalised networks and the state,
training and prediction helpers that every network model shares are in
``models.network_common``, the LSTM's online predictor (``LstmStreams``) in
``models.lstm_streams``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, ClassVar, Literal, Self

import numpy as np
import torch

from id_learning.dataset.preprocess import MinMaxScaler
from id_learning.errors import ConfigError
from id_learning.models.base import ModelConfig, SamplePredictor
from id_learning.models.data import TrainingData
from id_learning.models.fitting import OptimConfig, select_device
from id_learning.models.lstm_streams import LstmStreams
from id_learning.models.network_common import (
    NormalisedLstm,
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
from id_learning.models.torch_utils import ACTIVATIONS, to_numpy, to_tensor
from id_learning.robot.config import RobotConfig

__all__ = [
    'LstmConfig',
    'LstmModel',
    'LstmStreams',
    'MlpConfig',
    'MlpModel',
    'NetworkConfig',
    'check_kind',
    'check_mlp_shape',
]

DEVICES = ('auto', 'cpu', 'cuda')


# -- configs -------------------------------------------------------------------------------------
@dataclass(frozen=True)
class NetworkConfig(ModelConfig):
    """Training settings shared by the network models.

    Attributes:
        learning_rate: Adam step size.
        batch_size: samples (or windows) per mini-batch.
        max_epochs: upper bound on epochs.
        patience: stop after this many epochs without a better validation loss.
        weight_decay: Adam's L2 penalty.
        seed: seeds the initial weights and the batch order.
        max_seconds: wall-clock budget of the fit [s]; None for none.
        stride: the study's preprocessing: use every stride-th row of the fit and validation
            parts. The data are low-pass filtered at <= 1.2 Hz and sampled at 125 Hz, so
            neighbouring rows carry almost the same information: striding buys a proportional
            speed-up for little accuracy.
        windows_per_batch: through the filter (the default preprocessing): contiguous windows
            per mini-batch (``models.through_filter``; a window holds thousands of samples).
        eval_stride: through the filter: evaluate the network on every eval_stride-th sample of
            a window (an unbiased estimate of the filtered torque at a fraction of the cost).
        device: 'auto' (CUDA when available), 'cpu' or 'cuda'; prediction always runs on the CPU.
    """

    learning_rate: float = 1e-3
    batch_size: int = 256
    max_epochs: int = 300
    patience: int = 25
    weight_decay: float = 0.0
    seed: int = 0
    max_seconds: float | None = None
    stride: int = 4
    windows_per_batch: int = 2
    eval_stride: int = 1
    device: str = 'auto'

    def __post_init__(self) -> None:
        """Check ranges, naming the key."""
        self.optim()  # OptimConfig checks its own keys
        for key in ('stride', 'windows_per_batch', 'eval_stride'):
            if getattr(self, key) < 1:
                raise ConfigError(f'{self.kind}: {key} must be >= 1, got {getattr(self, key)}')
        if self.device not in DEVICES:
            raise ConfigError(f'{self.kind}: device must be one of {DEVICES}, got {self.device!r}')
        if self.max_seconds is not None and self.max_seconds <= 0:
            raise ConfigError(
                f'{self.kind}: max_seconds must be > 0 or None, got {self.max_seconds}'
            )
        if self.weight_decay < 0:
            raise ConfigError(f'{self.kind}: weight_decay must be >= 0, got {self.weight_decay}')

    def optim(self) -> OptimConfig:
        """The optimiser settings of train_module."""
        return OptimConfig(
            learning_rate=self.learning_rate,
            batch_size=self.batch_size,
            max_epochs=self.max_epochs,
            patience=self.patience,
            weight_decay=self.weight_decay,
            seed=self.seed,
            max_seconds=self.max_seconds,
        )


def check_kind(config: ModelConfig, kind: str | None = None) -> None:
    """Refuse a config whose ``kind`` is not its class's registry name.

    ``kind`` defaults to the default of the class's own ``kind`` field, so a subclass with its
    own kind passes the check its parent's ``__post_init__`` makes.

    Raises:
        ConfigError: names the class, the expected and the given kind.
    """
    kind = kind or str(type(config).__dataclass_fields__['kind'].default)
    if config.kind != kind:
        raise ConfigError(f'{type(config).__name__}.kind must be {kind!r}, got {config.kind!r}')


def check_mlp_shape(config: ModelConfig, width: int, depth: int, activation: str) -> None:
    """Refuse an impossible MLP shape, naming the key.

    Raises:
        ConfigError: width or depth < 1, or an unknown activation.
    """
    if width < 1 or depth < 1:
        raise ConfigError(f'{config.kind}: width and depth must be >= 1, got {width}, {depth}')
    if activation not in ACTIVATIONS:
        raise ConfigError(
            f'{config.kind}: activation must be one of {sorted(ACTIVATIONS)}, got {activation!r}'
        )


@dataclass(frozen=True)
class MlpConfig(NetworkConfig):
    """The study's MLP baseline: (q, v, a) -> tau through ``depth`` hidden layers.

    Attributes:
        width: units per hidden layer (study: 64).
        depth: hidden layers (study: 2).
        activation: hidden activation (study: tanh).
    """

    kind: Literal['mlp'] = 'mlp'
    width: int = 64
    depth: int = 2
    activation: str = 'tanh'
    # On the shipped bag (36k fit rows) an epoch at stride 2 takes ~0.15 s on one core; without
    # weight decay the validation loss bottoms out after ~10 epochs and the test error is ~15 %
    # higher (mean normalised RMSE 0.23 -> 0.21 with 1e-3, over two seeds).
    stride: int = 2
    weight_decay: float = 1e-3

    def __post_init__(self) -> None:
        """Check ranges, naming the key."""
        check_kind(self, 'mlp')
        super().__post_init__()
        check_mlp_shape(self, self.width, self.depth, self.activation)


@dataclass(frozen=True)
class LstmConfig(NetworkConfig):
    """The study's LSTM baseline: windows of ``sequence_length`` samples -> the last torque.

    Attributes:
        hidden_size: LSTM units per layer (study: 128).
        num_layers: stacked LSTM layers (study: 2).
        sequence_length: samples per window, at the IPO rate (study: 20).
    """

    kind: Literal['lstm'] = 'lstm'
    hidden_size: int = 128
    num_layers: int = 2
    sequence_length: int = 20
    # A window costs ~1.3 ms of one core per training step: at stride 16 an epoch of the shipped
    # bag (2.3k windows) takes ~2-3 s, and 30 epochs reach the accuracy that stride 8 reaches in
    # 60 (mean normalised test RMSE 0.20; 0.22 without weight decay, which overfits by epoch 4).
    # Through the filter, one LSTM window per 16 samples (128 ms, far finer than the label
    # filter's 0.3-1.2 Hz) keeps an epoch at a few seconds (~0.4 ms per window and step here).
    stride: int = 16
    eval_stride: int = 16
    learning_rate: float = 3e-3
    weight_decay: float = 1e-3
    max_epochs: int = 30
    patience: int = 10

    def __post_init__(self) -> None:
        """Check ranges, naming the key."""
        check_kind(self, 'lstm')
        super().__post_init__()
        if self.hidden_size < 1 or self.num_layers < 1:
            raise ConfigError(
                f'lstm: hidden_size and num_layers must be >= 1, '
                f'got {self.hidden_size}, {self.num_layers}'
            )
        if self.sequence_length < 1:
            raise ConfigError(f'lstm: sequence_length must be >= 1, got {self.sequence_length}')


def _inputs(q: np.ndarray, v: np.ndarray, a: np.ndarray) -> np.ndarray:
    return np.hstack([np.atleast_2d(q), np.atleast_2d(v), np.atleast_2d(a)])


# -- MLP -----------------------------------------------------------------------------------------
class MlpModel(TorchModel[NormalisedMlp]):
    """The study's MLP baseline: tau = MLP(q, v, a), each joint's torque on its [-1, 1] scale.

    No physics and no memory: it separates no torque components.
    """

    kind: ClassVar[str] = 'mlp'

    def __init__(self, config: MlpConfig, robot: RobotConfig) -> None:
        """Store the settings; no I/O, no fitting."""
        super().__init__(config, robot)
        self.config: MlpConfig = config
        self.input_scaler_: MinMaxScaler | None = None
        self.target_scaler_: MinMaxScaler | None = None

    def _build(self, input_scaler: MinMaxScaler, target_scaler: MinMaxScaler) -> NormalisedMlp:
        n, c = self.robot.n_joints, self.config
        network = seeded(c.seed, lambda: NormalisedMlp(3 * n, n, c.width, c.depth, c.activation))
        network.set_scaling(centre_and_half(input_scaler), centre_and_half(target_scaler))
        self.input_scaler_, self.target_scaler_ = input_scaler, target_scaler
        return network

    def fit(self, data: TrainingData, *, progress: bool = False) -> Self:
        """Fit on the training part of ``data`` with early stopping on its validation tail."""
        data.require_varied(self.kind)
        ds, c = data.dataset, self.config
        device = select_device(c.device)
        network = self._build(ds.input_scaler, ds.target_scaler)
        inputs = to_tensor(_inputs(ds.q, ds.v, ds.a), device)

        def predict(rows: torch.Tensor, positions: torch.Tensor) -> torch.Tensor:
            torque: torch.Tensor = network(inputs[rows[:, positions]])
            return torque

        self._fit_network(
            network,
            predict,
            data,
            ds.tau,
            ds.target_scaler.scale(),
            config=c,
            device=device,
            progress=progress,
        )
        return self

    def predict(self, q: np.ndarray, v: np.ndarray, a: np.ndarray) -> np.ndarray:
        """Torque (B, n) [N*m] for q, v, a (B, n) [rad, rad/s, rad/s^2]."""
        return predict_chunked(self.network(), _inputs(q, v, a))

    def sample_predictor(self) -> SamplePredictor:
        """One sample's torque in float64 numpy: q, v, a (n,) -> tau (n,) [N*m]."""
        network = NumpyNormalisedMlp(self.network())
        concatenate = np.concatenate

        def predict_one(q: np.ndarray, v: np.ndarray, a: np.ndarray) -> np.ndarray:
            return network(concatenate((q, v, a)))

        return predict_one

    def load_state(self, tensors: dict[str, np.ndarray], fitted: dict[str, Any]) -> None:
        """Rebuild the network from the scalers in ``fitted`` and load its weights.

        Raises:
            CheckpointError: the scalers are missing or the tensors do not fit the config.
        """
        network = self._build(*load_scalers(fitted, ('input_scaler', 'target_scaler'), 'mlp'))
        self._load_network(network, tensors, fitted)

    def fitted_metadata(self) -> dict[str, Any]:
        """The input and target scalers, and a summary of the fit."""
        require_fitted(self, self.input_scaler_)
        assert self.input_scaler_ is not None
        assert self.target_scaler_ is not None
        scalers = scalers_metadata(
            input_scaler=self.input_scaler_, target_scaler=self.target_scaler_
        )
        return {**scalers, **self._history_metadata()}


# -- LSTM ----------------------------------------------------------------------------------------
class LstmModel(TorchModel[NormalisedLstm]):
    """The study's LSTM baseline: the torque at a sample from the window of samples up to it.

    A window is (T, 3n) with T = ``sequence_length`` (20, 160 ms at the 8 ms IPO rate): rows
    [q, v, a] in physical units, oldest first, the last row the sample whose torque is wanted.
    Each window is processed from a zero state; nothing is carried between windows.

    ``predict(q, v, a)`` takes a contiguous run in time order (B, n) and returns one torque per
    sample (B, n). The first T - 1 samples have fewer than T predecessors in the run; their
    windows are padded at the front by repeating the run's first sample (as if the robot had
    rested there). The online predictor calls ``predict_window`` with its own ring buffer.
    """

    kind: ClassVar[str] = 'lstm'
    is_sequence_model: ClassVar[bool] = True

    def __init__(self, config: LstmConfig, robot: RobotConfig) -> None:
        """Store the settings; no I/O, no fitting."""
        super().__init__(config, robot)
        self.config: LstmConfig = config
        self.input_scaler_: MinMaxScaler | None = None
        self.target_scaler_: MinMaxScaler | None = None

    @property
    def sequence_length(self) -> int:
        """Samples per window."""
        return self.config.sequence_length

    def _build(self, input_scaler: MinMaxScaler, target_scaler: MinMaxScaler) -> NormalisedLstm:
        n, c = self.robot.n_joints, self.config
        network = seeded(c.seed, lambda: NormalisedLstm(3 * n, n, c.hidden_size, c.num_layers))
        network.set_scaling(centre_and_half(input_scaler), centre_and_half(target_scaler))
        self.input_scaler_, self.target_scaler_ = input_scaler, target_scaler
        return network

    def fit(self, data: TrainingData, *, progress: bool = False) -> Self:
        """Fit on windows ending in the training part, early stopping on its validation tail.

        The study's way: window end positions are strided (``stride``), the windows themselves
        keep every sample, and the first window ends at row T - 1. Through the filter: the
        torque of every ``eval_stride``-th sample of a contiguous stretch, each from its own
        window, filtered like the labels. Validation windows may start in the fit part (inputs
        only; their targets lie in the validation part).
        """
        data.require_varied(self.kind)
        ds, c = data.dataset, self.config
        device = select_device(c.device)
        network = self._build(ds.input_scaler, ds.target_scaler)
        inputs = to_tensor(_inputs(ds.q, ds.v, ds.a), device)
        offsets = torch.arange(1 - c.sequence_length, 1, device=device)

        def predict(rows: torch.Tensor, positions: torch.Tensor) -> torch.Tensor:
            index = rows[:, positions[:, None] + offsets]  # (B, P, T): a window per position
            batch, count = index.shape[:2]
            windows = inputs[index].reshape(batch * count, c.sequence_length, -1)
            torque: torch.Tensor = network(windows).reshape(batch, count, -1)
            return torque

        self._fit_network(
            network,
            predict,
            data,
            ds.tau,
            ds.target_scaler.scale(),
            config=c,
            device=device,
            progress=progress,
            history=c.sequence_length - 1,
        )
        return self

    def predict_windows(self, windows: np.ndarray) -> np.ndarray:
        """Torque (B, n) [N*m] at the last sample of each window (B, T, 3n), physical units."""
        windows = np.asarray(windows)
        expected = (self.sequence_length, 3 * self.robot.n_joints)
        if windows.ndim != 3 or windows.shape[1:] != expected:
            raise ValueError(
                f'expected windows of shape (B, {expected[0]}, {expected[1]}), got {windows.shape}'
            )
        if not len(windows):
            return np.empty((0, self.robot.n_joints))
        return predict_chunked(self.network(), windows)

    def predict_window(self, window: np.ndarray) -> np.ndarray:
        """Torque (n,) [N*m] at the last sample of a window (T, 3n): rows [q, v, a], oldest first.

        Raises:
            ValueError: the window is not (T, 3n).
        """
        window = np.asarray(window)
        expected = (self.sequence_length, 3 * self.robot.n_joints)
        if window.shape != expected:
            raise ValueError(f'expected a window of shape {expected}, got {window.shape}')
        with torch.inference_mode():
            torque: np.ndarray = to_numpy(self.network()(to_tensor(window)[None]))[0]
        return torque

    def predict(self, q: np.ndarray, v: np.ndarray, a: np.ndarray) -> np.ndarray:
        """Torque (B, n) [N*m] of each sample of a contiguous run q, v, a (B, n), in time order.

        The first T - 1 windows are padded by repeating the run's first sample.
        """
        inputs = _inputs(q, v, a)
        pad = np.repeat(inputs[:1], self.sequence_length - 1, axis=0)
        padded = to_tensor(np.vstack([pad, inputs]))
        # unfold: (B, 3n, T) views of consecutive rows; transpose to (B, T, 3n).
        windows = padded.unfold(0, self.sequence_length, 1).transpose(1, 2)
        return predict_chunked(self.network(), windows)

    def sequence_predictor(self, dtype: type[np.floating] = np.float32) -> LstmStreams:
        """The online form of ``predict``: one sample in, its torque out.

        ``dtype``: the arithmetic's precision. float32 (the default) is the network's own, as in
        ``predict``, at half the cost of float64 (0.1 against 0.2 ms per sample here).
        """
        return LstmStreams(self.network(), self.sequence_length, dtype)

    def load_state(self, tensors: dict[str, np.ndarray], fitted: dict[str, Any]) -> None:
        """Rebuild the network from the scalers in ``fitted`` and load its weights.

        Raises:
            CheckpointError: the scalers are missing or the tensors do not fit the config.
        """
        network = self._build(*load_scalers(fitted, ('input_scaler', 'target_scaler'), 'lstm'))
        self._load_network(network, tensors, fitted)

    def fitted_metadata(self) -> dict[str, Any]:
        """The input and target scalers, and a summary of the fit."""
        require_fitted(self, self.input_scaler_)
        assert self.input_scaler_ is not None
        assert self.target_scaler_ is not None
        scalers = scalers_metadata(
            input_scaler=self.input_scaler_, target_scaler=self.target_scaler_
        )
        return {**scalers, **self._history_metadata()}
