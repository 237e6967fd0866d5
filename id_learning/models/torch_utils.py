"""Small torch helpers shared by the network models, and their float64 numpy twins.

The numpy twins (``NumpyMlp``, ``numpy_activation``) evaluate fitted networks on one sample
for the online predictor: at batch size one, torch's per-operator overhead (~5-10 us) is most of
the cost, and a plain numpy matrix-vector product is several times cheaper. The weights are
copied to float64 at export, so a twin equals the torch module run in float64 to rounding.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
import torch
from torch import nn

__all__ = [
    'ACTIVATIONS',
    'NumpyMlp',
    'make_mlp',
    'normalised_mse',
    'numpy_activation',
    'numpy_softplus',
    'to_numpy',
    'to_tensor',
]

ACTIVATIONS: dict[str, type[nn.Module]] = {
    'tanh': nn.Tanh,
    'softplus': nn.Softplus,
    'relu': nn.ReLU,
}


def make_mlp(
    n_in: int, n_out: int, width: int, depth: int, activation: str = 'tanh'
) -> nn.Sequential:
    """A plain MLP: ``depth`` hidden layers of ``width`` units, linear output."""
    if activation not in ACTIVATIONS:
        raise ValueError(f'unknown activation {activation!r}; known: {sorted(ACTIVATIONS)}')
    layers: list[nn.Module] = []
    size = n_in
    for _ in range(depth):
        layers += [nn.Linear(size, width), ACTIVATIONS[activation]()]
        size = width
    layers.append(nn.Linear(size, n_out))
    return nn.Sequential(*layers)


def to_tensor(
    x: np.ndarray, device: torch.device | str = 'cpu', dtype: torch.dtype = torch.float32
) -> torch.Tensor:
    """Convert numpy to a contiguous torch tensor of ``dtype`` on a device."""
    return torch.as_tensor(np.ascontiguousarray(x), dtype=dtype, device=device)


def to_numpy(x: torch.Tensor) -> np.ndarray:
    """Convert a torch tensor to float64 numpy on the CPU."""
    return x.detach().to('cpu', torch.float64).numpy()


def normalised_mse(
    prediction: torch.Tensor, target: torch.Tensor, scale: torch.Tensor
) -> torch.Tensor:
    """Mean squared error on the study's normalised scale: each joint divided by its half range."""
    return torch.mean(((prediction - target) / scale) ** 2)


# -- numpy twins ---------------------------------------------------------------------------------
def numpy_softplus(x: np.ndarray) -> np.ndarray:
    """Softplus as torch computes it (beta 1, linear above 20), in float64."""
    return np.where(x > 20.0, x, np.log1p(np.exp(np.minimum(x, 20.0))))


def _relu(x: np.ndarray) -> np.ndarray:
    out: np.ndarray = np.maximum(x, 0.0)
    return out


_NUMPY_ACTIVATIONS: dict[str, Callable[[np.ndarray], np.ndarray]] = {
    'tanh': np.tanh,
    'softplus': numpy_softplus,
    'relu': _relu,
}


def numpy_activation(name: str) -> Callable[[np.ndarray], np.ndarray]:
    """The numpy function of an activation in ACTIVATIONS.

    Raises:
        ValueError: an unknown activation.
    """
    if name not in _NUMPY_ACTIVATIONS:
        raise ValueError(f'unknown activation {name!r}; known: {sorted(_NUMPY_ACTIVATIONS)}')
    return _NUMPY_ACTIVATIONS[name]


def float64_array(tensor: torch.Tensor) -> np.ndarray:
    """A contiguous float64 numpy copy of a tensor (weights exported at load time)."""
    return np.ascontiguousarray(tensor.detach().to('cpu', torch.float64).numpy())


@dataclass(frozen=True, eq=False)
class NumpyMlp:
    """An MLP's weights in float64: hidden layers with one activation, then a linear output.

    Attributes:
        weights_t: per layer the transposed weight (n_in, n_out), so that a layer is x @ w + b.
        biases: per layer (n_out,).
        activation: the hidden activation's name (see ACTIVATIONS).
    """

    weights_t: tuple[np.ndarray, ...]
    biases: tuple[np.ndarray, ...]
    activation: str

    @classmethod
    def from_linears(cls, layers: Sequence[nn.Linear], activation: str) -> NumpyMlp:
        """Copy the weights of ``layers`` (hidden ones first, the linear output last)."""
        numpy_activation(activation)  # fail on export, not on the first sample
        return cls(
            tuple(np.ascontiguousarray(float64_array(layer.weight).T) for layer in layers),
            tuple(float64_array(layer.bias) for layer in layers),
            activation,
        )

    @classmethod
    def from_sequential(cls, net: nn.Sequential) -> NumpyMlp:
        """Copy a ``make_mlp`` network.

        Raises:
            ValueError: the network is not linear layers with one activation between them.
        """
        linears = [module for module in net if isinstance(module, nn.Linear)]
        activations = {
            name for module in net for name, kind in ACTIVATIONS.items() if type(module) is kind
        }
        if len(activations) != 1 or 2 * len(linears) - 1 != len(net):
            raise ValueError(f'not a make_mlp network: {net}')
        return cls.from_linears(linears, activations.pop())

    def __call__(self, x: np.ndarray) -> np.ndarray:
        """Outputs (n_out,) for one input x (n_in,), or (B, n_out) for (B, n_in)."""
        act = _NUMPY_ACTIVATIONS[self.activation]
        last = len(self.biases) - 1
        for index, (weight_t, bias) in enumerate(zip(self.weights_t, self.biases, strict=True)):
            x = x @ weight_t + bias
            if index < last:
                x = act(x)
        return x
