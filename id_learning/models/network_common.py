"""Plumbing shared by the network models: normalised networks, state I/O, training, prediction.

The black-box baselines (``models.blackbox``) and the physics-plus-network models
(``models.physics``, ``models.effects``, ``models.identified``) all build on these: networks
with the dataset's min-max scalers built in as fixed buffers (``NormalisedMlp``,
``NormalisedLstm`` and a float64 numpy copy of the MLP), seeded construction, saving and loading
of weights and scalers, training on a device and chunked prediction on the CPU. The settings they
share (``NetworkConfig``) stay with the baselines' configs in ``models.blackbox``.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, TypeVar

import numpy as np
import torch
from torch import nn

from id_learning.dataset.preprocess import MinMaxScaler
from id_learning.errors import CheckpointError
from id_learning.models.base import InverseDynamicsModel
from id_learning.models.torch_utils import NumpyMlp, float64_array, make_mlp, to_numpy, to_tensor

__all__ = [
    'PREDICT_CHUNK',
    'NormalisedLstm',
    'NormalisedMlp',
    'NumpyNormalisedMlp',
    'centre_and_half',
    'load_module_state',
    'load_scalers',
    'module_state',
    'predict_chunked',
    'require_fitted',
    'scalers_metadata',
    'seeded',
    'strided_rows',
]

_T = TypeVar('_T')
#: Samples per forward pass when predicting long runs (bounds memory, not results).
PREDICT_CHUNK = 8192


def seeded(seed: int, build: Callable[[], _T]) -> _T:
    """Call ``build`` (which draws initial weights) with torch's RNG seeded, then restore it.

    Module constructors draw from torch's global generator; forking it keeps library code from
    changing the caller's random state while making the initial weights a function of ``seed``.
    """
    with torch.random.fork_rng(devices=[]):
        torch.manual_seed(seed)
        return build()


def strided_rows(rows: slice, stride: int, first: int = 0) -> np.ndarray:
    """Every ``stride``-th row index of a contiguous slice, not before ``first``."""
    start = max(rows.start or 0, first)
    return np.arange(start, rows.stop, stride)


def centre_and_half(scaler: MinMaxScaler) -> tuple[np.ndarray, np.ndarray]:
    """A fitted scaler's centre and half range per column (z = (x - centre) / half)."""
    half = scaler.scale()
    return scaler.inverse_transform(np.zeros_like(half)), half


class _Normalised(nn.Module):
    """Fixed affine maps around a network: physical inputs in, physical outputs out.

    The maps are non-persistent buffers, rebuilt from the scalers in the fitted metadata, so that
    ``state_dict()`` holds the trained weights only.
    """

    input_centre: torch.Tensor
    input_half: torch.Tensor
    output_centre: torch.Tensor
    output_half: torch.Tensor

    def set_scaling(
        self,
        inputs: tuple[np.ndarray, np.ndarray],
        outputs: tuple[np.ndarray, np.ndarray],
    ) -> None:
        """Set (centre, half) of the inputs and of the outputs, each (n_in,) / (n_out,)."""
        for name, value in (
            ('input_centre', inputs[0]),
            ('input_half', inputs[1]),
            ('output_centre', outputs[0]),
            ('output_half', outputs[1]),
        ):
            self.register_buffer(name, to_tensor(value), persistent=False)


class NormalisedMlp(_Normalised):
    """An MLP between fixed input and output scalings; maps (B, n_in) to (B, n_out)."""

    def __init__(self, n_in: int, n_out: int, width: int, depth: int, activation: str) -> None:
        super().__init__()
        self.net = make_mlp(n_in, n_out, width, depth, activation)
        self.set_scaling((np.zeros(n_in), np.ones(n_in)), (np.zeros(n_out), np.ones(n_out)))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """Outputs (B, n_out) in physical units for inputs (B, n_in) in physical units."""
        z = (x - self.input_centre) / self.input_half
        out: torch.Tensor = self.net(z) * self.output_half + self.output_centre
        return out


class NormalisedLstm(_Normalised):
    """An LSTM with a linear head on its last step; maps windows (B, T, n_in) to (B, n_out)."""

    def __init__(self, n_in: int, n_out: int, hidden_size: int, num_layers: int) -> None:
        super().__init__()
        self.lstm = nn.LSTM(n_in, hidden_size, num_layers=num_layers, batch_first=True)
        self.head = nn.Linear(hidden_size, n_out)
        self.set_scaling((np.zeros(n_in), np.ones(n_in)), (np.zeros(n_out), np.ones(n_out)))

    def forward(self, windows: torch.Tensor) -> torch.Tensor:
        """Torque (B, n_out) of each window's last sample; windows (B, T, n_in), oldest first."""
        z = (windows - self.input_centre) / self.input_half
        hidden, _ = self.lstm(z)
        out: torch.Tensor = self.head(hidden[:, -1]) * self.output_half + self.output_centre
        return out


class NumpyNormalisedMlp:
    """A float64 numpy copy of a fitted NormalisedMlp, for one sample at a time."""

    def __init__(self, network: NormalisedMlp) -> None:
        """Copy the weights and the scalings."""
        self.mlp = NumpyMlp.from_sequential(network.net)
        self.input_centre = float64_array(network.input_centre)
        self.input_half = float64_array(network.input_half)
        self.output_centre = float64_array(network.output_centre)
        self.output_half = float64_array(network.output_half)

    def __call__(self, x: np.ndarray) -> np.ndarray:
        """Outputs (n_out,) in physical units for one input x (n_in,) in physical units."""
        out: np.ndarray = (
            self.mlp((x - self.input_centre) / self.input_half) * self.output_half
            + self.output_centre
        )
        return out


def module_state(module: nn.Module) -> dict[str, np.ndarray]:
    """A module's weights as float32 numpy arrays, named like its state_dict keys."""
    return {
        name: value.detach().to('cpu').numpy().copy()
        for name, value in module.state_dict().items()
    }


def load_module_state(module: nn.Module, tensors: dict[str, np.ndarray], kind: str) -> None:
    """Load weights saved by module_state.

    Raises:
        CheckpointError: names or shapes differ from the module the hyper-parameters build.
    """
    expected = {name: tuple(value.shape) for name, value in module.state_dict().items()}
    found = {name: tuple(np.shape(value)) for name, value in tensors.items()}
    if expected != found:
        raise CheckpointError(
            f'{kind}: saved tensors {found} do not match the network its hyper-parameters '
            f'build {expected}'
        )
    module.load_state_dict({name: torch.as_tensor(value) for name, value in tensors.items()})


def scalers_metadata(**scalers: MinMaxScaler) -> dict[str, Any]:
    """JSON-ready scalers by name."""
    return {name: scaler.to_dict() for name, scaler in scalers.items()}


def require_fitted(model: InverseDynamicsModel, value: object) -> None:
    """Raise if a model has neither been fitted nor loaded.

    Raises:
        RuntimeError: ``value`` (the model's fitted network or parameters) is None.
    """
    if value is None:
        raise RuntimeError(f'{model.kind} model is not fitted: call fit() or load_state() first')


def predict_chunked(module: nn.Module, inputs: np.ndarray | torch.Tensor) -> np.ndarray:
    """A CPU module's outputs for inputs of any length, PREDICT_CHUNK samples per pass."""
    with torch.inference_mode():
        x = inputs if isinstance(inputs, torch.Tensor) else to_tensor(inputs)
        if len(x) <= PREDICT_CHUNK:
            return to_numpy(module(x))
        return np.vstack(
            [to_numpy(module(x[k : k + PREDICT_CHUNK])) for k in range(0, len(x), PREDICT_CHUNK)]
        )


def load_scalers(
    fitted: dict[str, Any], names: tuple[str, ...], kind: str
) -> tuple[MinMaxScaler, ...]:
    """The named scalers of a model's fitted metadata.

    Raises:
        CheckpointError: a scaler is missing or malformed.
    """
    missing = [name for name in names if name not in fitted]
    if missing:
        raise CheckpointError(f'{kind}: fitted metadata lacks {missing}; found {sorted(fitted)}')
    try:
        return tuple(MinMaxScaler.from_dict(fitted[name]) for name in names)
    except (KeyError, TypeError, ValueError) as err:
        raise CheckpointError(f'{kind}: invalid scaler in fitted metadata: {err}') from err
