"""Small torch helpers shared by the network models."""

from __future__ import annotations

import numpy as np
import torch
from torch import nn

__all__ = ['ACTIVATIONS', 'make_mlp', 'normalised_mse', 'to_numpy', 'to_tensor']

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
