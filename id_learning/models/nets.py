"""An MLP whose input derivatives are computed in closed form, batched, with plain tensor ops.

The Lagrangian models need derivatives of networks with respect to their inputs inside the loss
and at prediction time. Nested autograd (``torch.func.hessian`` of ``jacrev``) costs milliseconds
per sample; here the derivatives are propagated layer by layer instead:

- ``jacobian``: forward-mode propagation of the input Jacobian,
  ``J_l = diag(s'(z_l)) W_l J_{l-1}``;
- ``gradient``: the backward pass written out, ``delta_l = g_l * s'(z_l)``,
  ``g_{l-1} = W_l^T delta_l``;
- ``gradient_and_hvp``: the backward pass plus its directional derivative along ``u``
  (forward-over-reverse), which gives the Hessian-vector product ``H u`` for about the cost of
  four forward passes, whatever the input size.

Everything is ordinary differentiable tensor algebra, so autograd can still differentiate the
results with respect to the weights for training.

``NumpyAnalyticMLP`` is a float64 numpy copy of a fitted net with the same derivatives, for
one sample at a time (the online predictor), where torch's per-operator overhead dominates.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Callable
from typing import cast

import numpy as np
import torch
from torch import nn
from torch.nn import functional

from id_learning.models.torch_utils import float64_array, numpy_softplus

__all__ = ['SMOOTH_ACTIVATIONS', 'AnalyticMLP', 'NumpyAnalyticMLP']

# Each activation returns (s(z), s'(z)); s''(z) is then a cheap function of those two.
_ValueSlope = tuple[torch.Tensor, torch.Tensor]


def _tanh(z: torch.Tensor) -> _ValueSlope:
    value = torch.tanh(z)
    return value, 1.0 - value * value


def _tanh_curvature(value: torch.Tensor, slope: torch.Tensor) -> torch.Tensor:
    return -2.0 * value * slope


def _softplus(z: torch.Tensor) -> _ValueSlope:
    return functional.softplus(z), torch.sigmoid(z)


def _softplus_curvature(value: torch.Tensor, slope: torch.Tensor) -> torch.Tensor:
    del value
    return slope - slope * slope


#: Activations with continuous second derivatives: name -> ((s, s') of z, s'' of (s, s')).
SMOOTH_ACTIVATIONS: dict[
    str,
    tuple[
        Callable[[torch.Tensor], _ValueSlope],
        Callable[[torch.Tensor, torch.Tensor], torch.Tensor],
    ],
] = {
    'tanh': (_tanh, _tanh_curvature),
    'softplus': (_softplus, _softplus_curvature),
}


#: Initialisations of AnalyticMLP's weights.
INITIALISATIONS = ('xavier', 'fan_in')


class AnalyticMLP(nn.Module):
    """``depth`` hidden layers of ``width`` units with a smooth activation, and a linear output.

    The layers are ``layers.0 ... layers.depth`` (``nn.Linear``), so the state_dict keys are
    ``layers.<i>.weight`` and ``layers.<i>.bias``. Weights are Xavier-uniform and biases zero,
    drawn from ``generator`` (the global RNG is not touched); ``output_gain`` scales the output
    layer's initial weights.
    """

    def __init__(
        self,
        n_in: int,
        n_out: int,
        width: int = 64,
        depth: int = 2,
        activation: str = 'tanh',
        *,
        output_gain: float = 1.0,
        generator: torch.Generator | None = None,
        init: str = 'xavier',
    ) -> None:
        """Build the layers and draw the initial weights.

        ``init``: 'xavier' (uniform, bound sqrt(6 / (fan_in + fan_out))) or 'fan_in' (truncated
        normal at two std, std 1 / sqrt(fan_in): the DeLaN reference's, which starts tanh units
        out of their linear range).

        Raises:
            ValueError: an unknown activation or initialisation, or a size below 1.
        """
        super().__init__()
        if activation not in SMOOTH_ACTIVATIONS:
            raise ValueError(
                f'activation {activation!r} has no smooth second derivative; '
                f'use one of {sorted(SMOOTH_ACTIVATIONS)}'
            )
        if init not in INITIALISATIONS:
            raise ValueError(f'init must be one of {INITIALISATIONS}, got {init!r}')
        if min(n_in, n_out, width, depth) < 1:
            raise ValueError(
                f'n_in, n_out, width and depth must be >= 1, got {n_in}, {n_out}, {width}, {depth}'
            )
        self.n_in, self.n_out = n_in, n_out
        self.activation = activation
        self._value_slope, self._curvature = SMOOTH_ACTIVATIONS[activation]
        self._plain = torch.tanh if activation == 'tanh' else functional.softplus
        sizes = [n_in] + [width] * depth + [n_out]
        self.layers = nn.ModuleList(
            nn.utils.skip_init(nn.Linear, fan_in, fan_out)
            for fan_in, fan_out in itertools.pairwise(sizes)
        )
        generator = generator or torch.Generator().manual_seed(0)
        with torch.no_grad():
            for index, layer in enumerate(self.linears()):
                fan_out, fan_in = layer.weight.shape
                gain = output_gain if index == depth else 1.0
                if init == 'fan_in':
                    std = 1.0 / math.sqrt(fan_in)
                    nn.init.trunc_normal_(
                        layer.weight, std=std, a=-2 * std, b=2 * std, generator=generator
                    )
                    layer.weight.mul_(gain)
                else:
                    bound = gain * math.sqrt(6.0 / (fan_in + fan_out))
                    layer.weight.uniform_(-bound, bound, generator=generator)
                layer.bias.zero_()

    def _weights_and_biases(self) -> list[tuple[torch.Tensor, torch.Tensor]]:
        # Plain (weight, bias) pairs: cheaper per call than nn.Linear.__call__ or slicing the
        # ModuleList, which matters for one-sample prediction.
        return [(layer.weight, layer.bias) for layer in self.linears()]

    def linears(self) -> list[nn.Linear]:
        """The layers, input to output."""
        return [cast(nn.Linear, layer) for layer in self.layers]

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """Output (B, n_out) for inputs x (B, n_in)."""
        *hidden, (weight, bias) = self._weights_and_biases()
        for w, b in hidden:
            x = self._plain(functional.linear(x, w, b))
        return functional.linear(x, weight, bias)

    def jacobian(self, x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """Output and its Jacobian by forward propagation of the input Jacobian.

        Args:
            x: (B, n_in) inputs.

        Returns:
            Output (B, n_out) and Jacobian d output / d x (B, n_out, n_in).
        """
        out, jac_t = self.jacobian_transposed(x)
        return out, jac_t.transpose(1, 2)

    def jacobian_transposed(self, x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """Like ``jacobian``, with the Jacobian as (B, n_in, n_out): the layout it is built in.

        Carried transposed, each layer's Jacobian update is one matrix product over all samples
        and input directions: ``J_l^T = (J_{l-1}^T W_l^T) diag(s'(z_l))``.
        """
        (w, b), *hidden, (weight, bias) = self._weights_and_biases()
        a, slope = self._value_slope(functional.linear(x, w, b))
        # Layer 1: (d a / d x)^T = W_1^T diag(s'(z)), without materialising the identity.
        jac_t = w.T * slope.unsqueeze(1)
        for w, b in hidden:
            a, slope = self._value_slope(functional.linear(a, w, b))
            jac_t = functional.linear(jac_t, w) * slope.unsqueeze(1)
        return functional.linear(a, weight, bias), functional.linear(jac_t, weight)

    def _forward_with_tangent(
        self, x: torch.Tensor, u: torch.Tensor | None
    ) -> tuple[torch.Tensor, list[_ValueSlope], list[torch.Tensor]]:
        """Forward pass keeping (s(z_l), s'(z_l)) and, when u is given, the tangents dz_l[u]."""
        *hidden, (weight, bias) = self._weights_and_biases()
        activations: list[_ValueSlope] = []
        tangents: list[torch.Tensor] = []
        a, a_dot = x, u
        for w, b in hidden:
            a, slope = self._value_slope(functional.linear(a, w, b))
            activations.append((a, slope))
            if a_dot is not None:
                z_dot = functional.linear(a_dot, w)
                tangents.append(z_dot)
                a_dot = slope * z_dot
        return functional.linear(a, weight, bias), activations, tangents

    def gradient(self, x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """Value and input gradient of a scalar-output net by the analytic backward pass.

        Args:
            x: (B, n_in) inputs.

        Returns:
            f (B,) and d f / d x (B, n_in).

        Raises:
            ValueError: the net has more than one output.
        """
        self._require_scalar()
        f, activations, _ = self._forward_with_tangent(x, None)
        *hidden, (weight, _) = self._weights_and_biases()
        g = weight  # (1, width): d f / d a_L, the same for every sample
        for (w, _), (_, slope) in zip(reversed(hidden), reversed(activations), strict=True):
            g = torch.matmul(g * slope, w)
        return f.squeeze(-1), g

    def gradient_and_hvp(
        self, x: torch.Tensor, u: torch.Tensor
    ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """Value, input gradient and Hessian-vector product of a scalar-output net.

        Forward-over-reverse: the backward pass ``delta_l = g_l * s'(z_l)``,
        ``g_{l-1} = W_l^T delta_l`` is differentiated along ``u`` by hand, using the forward
        tangents ``dz_l[u]``: ``d delta_l = dg_l * s'(z_l) + g_l * s''(z_l) * dz_l[u]``.

        Args:
            x: (B, n_in) inputs.
            u: (B, n_in) direction.

        Returns:
            f (B,), d f / d x (B, n_in) and (d2 f / d x2) u (B, n_in).

        Raises:
            ValueError: the net has more than one output.
        """
        self._require_scalar()
        f, activations, tangents = self._forward_with_tangent(x, u)
        *hidden, (weight, _) = self._weights_and_biases()
        g = weight  # (1, width)
        g_dot: torch.Tensor | None = None  # the output layer is linear: its tangent is zero
        for (w, _), (value, slope), z_dot in zip(
            reversed(hidden), reversed(activations), reversed(tangents), strict=True
        ):
            delta = g * slope
            delta_dot = g * self._curvature(value, slope) * z_dot
            if g_dot is not None:
                delta_dot = delta_dot + g_dot * slope
            g = torch.matmul(delta, w)
            g_dot = torch.matmul(delta_dot, w)
        assert g_dot is not None  # there is at least one hidden layer
        return f.squeeze(-1), g, g_dot

    def _require_scalar(self) -> None:
        if self.n_out != 1:
            raise ValueError(f'gradients need a scalar-output net, this one has {self.n_out}')


# -- numpy twin ----------------------------------------------------------------------------------
_NumpyValueSlope = tuple[np.ndarray, np.ndarray]


def _numpy_tanh(z: np.ndarray) -> _NumpyValueSlope:
    value = np.tanh(z)
    return value, 1.0 - value * value


def _numpy_tanh_curvature(value: np.ndarray, slope: np.ndarray) -> np.ndarray:
    result: np.ndarray = -2.0 * value * slope
    return result


def numpy_sigmoid(z: np.ndarray) -> np.ndarray:
    """The logistic function, as (1 + tanh(z / 2)) / 2 (no overflow for any z)."""
    result: np.ndarray = 0.5 + 0.5 * np.tanh(0.5 * z)
    return result


def _numpy_softplus(z: np.ndarray) -> _NumpyValueSlope:
    return numpy_softplus(z), numpy_sigmoid(z)


def _numpy_softplus_curvature(value: np.ndarray, slope: np.ndarray) -> np.ndarray:
    del value
    result: np.ndarray = slope - slope * slope
    return result


#: Per activation: (value and slope of z, curvature from value and slope, the plain function).
_NUMPY_SMOOTH: dict[
    str,
    tuple[
        Callable[[np.ndarray], _NumpyValueSlope],
        Callable[[np.ndarray, np.ndarray], np.ndarray],
        Callable[[np.ndarray], np.ndarray],
    ],
] = {
    'tanh': (_numpy_tanh, _numpy_tanh_curvature, np.tanh),
    'softplus': (_numpy_softplus, _numpy_softplus_curvature, numpy_softplus),
}


class NumpyAnalyticMLP:
    """A float64 numpy copy of a fitted AnalyticMLP, for one input x (n_in,) at a time.

    Same formulas as AnalyticMLP (see there), each with a single sample: vectors instead of
    (B, ...) batches.
    """

    def __init__(self, net: AnalyticMLP) -> None:
        """Copy the weights; later changes to ``net`` are not seen."""
        self.n_in, self.n_out = net.n_in, net.n_out
        self.layers = [
            (float64_array(layer.weight), float64_array(layer.bias)) for layer in net.linears()
        ]
        self._value_slope, self._curvature, self._plain = _NUMPY_SMOOTH[net.activation]

    def __call__(self, x: np.ndarray) -> np.ndarray:
        """Output (n_out,) for x (n_in,)."""
        *hidden, (weight, bias) = self.layers
        for w, b in hidden:
            x = self._plain(w @ x + b)
        out: np.ndarray = weight @ x + bias
        return out

    def jacobian_transposed(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Output (n_out,) and the transposed Jacobian d output / d x, (n_in, n_out)."""
        (w, b), *hidden, (weight, bias) = self.layers
        a, slope = self._value_slope(w @ x + b)
        jac_t = w.T * slope
        for w, b in hidden:
            a, slope = self._value_slope(w @ a + b)
            jac_t = (jac_t @ w.T) * slope
        return weight @ a + bias, jac_t @ weight.T

    def gradient(self, x: np.ndarray) -> tuple[float, np.ndarray]:
        """Value and input gradient (n_in,) of a scalar-output net."""
        *hidden, (weight, bias) = self.layers
        slopes = []
        a = x
        for w, b in hidden:
            a, slope = self._value_slope(w @ a + b)
            slopes.append(slope)
        g = weight[0]
        for (w, _), slope in zip(reversed(hidden), reversed(slopes), strict=True):
            g = (g * slope) @ w
        return float(weight[0] @ a + bias[0]), g

    def gradient_and_hvp(
        self, x: np.ndarray, u: np.ndarray
    ) -> tuple[float, np.ndarray, np.ndarray]:
        """Value, input gradient (n_in,) and Hessian-vector product H u (n_in,) (scalar net)."""
        *hidden, (weight, bias) = self.layers
        saved = []
        a, a_dot = x, u
        for w, b in hidden:
            a, slope = self._value_slope(w @ a + b)
            z_dot = w @ a_dot
            saved.append((a, slope, z_dot))
            a_dot = slope * z_dot
        g = weight[0]
        g_dot: np.ndarray | None = None
        for (w, _), (value, slope, z_dot) in zip(reversed(hidden), reversed(saved), strict=True):
            delta = g * slope
            delta_dot = g * self._curvature(value, slope) * z_dot
            if g_dot is not None:
                delta_dot += g_dot * slope
            g = delta @ w
            g_dot = delta_dot @ w
        assert g_dot is not None  # there is at least one hidden layer
        return float(weight[0] @ a + bias[0]), g, g_dot
