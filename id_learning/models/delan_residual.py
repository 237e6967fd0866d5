"""DeLaN for what a rigid-body prior leaves: a positive semi-definite mass matrix and a potential.

``ResidualDelanNetwork`` is ``DelanNetwork`` (``models.delan``) changed where a network added to a
prior whose mass matrix M_id(q) is positive definite (``delan_id``) allows and needs it:

- the factor's diagonal is the network's output as it is, without DeLaN's softplus, shift and
  epsilon: ``M_res = L L^T`` is positive semi-definite for any L, so ``M_id + M_res`` stays
  positive definite, and the residual may be (near) zero, which a positive diagonal forbids
  (softplus(0) = 0.69 on the unit scale);
- it starts near zero (``start_near_zero``): the potential's output layer at zero (V_res = 0)
  and the factor's at ``FACTOR_GAIN`` of its usual initial scale. Not at zero: ``L L^T`` has a
  zero gradient at L = 0, where the factor would stay. At 1e-4 the residual torque is of order
  1e-8 of the torque scale, below float32's resolution of the prior's torque, and Adam's steps,
  which do not shrink with the gradient, grow the factor within tens of steps.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import torch
from torch.nn import functional

from id_learning.models.base import SamplePredictor
from id_learning.models.delan import DelanNetwork
from id_learning.models.lagrangian_base import LagrangianScaling
from id_learning.models.nets import AnalyticMLP, NumpyAnalyticMLP
from id_learning.models.torch_utils import float64_array

__all__ = ['FACTOR_GAIN', 'ResidualDelanNetwork', 'euler_lagrange_one', 'zero_output']

#: The factor network's initial output weights relative to their usual scale (module docstring).
FACTOR_GAIN = 1e-4


def zero_output(*networks: AnalyticMLP) -> None:
    """Set the output layers' weights and biases to zero: each network starts at 0.

    The output is linear in these weights, so their gradient does not vanish there (unlike that
    of a product of two outputs, such as ``L L^T``).
    """
    with torch.no_grad():
        for network in networks:
            last = network.linears()[-1]
            last.weight.zero_()
            last.bias.zero_()


def euler_lagrange_one(
    cholesky: np.ndarray, derivative: np.ndarray, v: np.ndarray, a: np.ndarray
) -> np.ndarray:
    """``delan.euler_lagrange_torque`` of one sample: M a + Mdot v - 1/2 d/dq (v^T M v).

    Args:
        cholesky: (n, n) factor L(q) of M = L L^T (any square matrix) [sqrt(kg)*m].
        derivative: (n, n, n) dL/dq_k, index order (k, i, j) for dL_ij / dq_k.
        v: (n,) joint velocities [rad/s].
        a: (n,) joint accelerations [rad/s^2].

    Returns:
        The inertial plus Coriolis/centrifugal torque (n,) [N*m].
    """
    y = cholesky.T @ v
    cholesky_dot = np.einsum('kij,k->ij', derivative, v)
    mass_dot_v = cholesky_dot @ y + cholesky @ (cholesky_dot.T @ v)
    kinetic_gradient = np.einsum('kij,i,j->k', derivative, v, y)
    tau: np.ndarray = cholesky @ (cholesky.T @ a) + mass_dot_v - kinetic_gradient
    return tau


class ResidualDelanNetwork(DelanNetwork):
    """DeLaN's networks for a residual: M_res = L L^T with a free factor, V_res (module docstring).

    State-dict keys as ``DelanNetwork``'s.
    """

    def __init__(self, scaling: LagrangianScaling, **settings: Any) -> None:
        """``DelanNetwork``'s networks (``settings``: its keywords but the diagonal's), near 0."""
        super().__init__(scaling, diagonal_epsilon=0.0, diagonal_shift=0.0, **settings)
        self.start_near_zero()

    def start_near_zero(self) -> None:
        """V_res = 0 and L at ``FACTOR_GAIN`` of its initial scale (module docstring)."""
        zero_output(self.potential_net)
        with torch.no_grad():
            self.cholesky_net.linears()[-1].weight.mul_(FACTOR_GAIN)

    def _cholesky(self, q_scaled: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """The factor and its derivative (``DelanNetwork.cholesky``), diagonal as it comes."""
        n, batch = self.n_dof, q_scaled.shape[0]
        entries, jac_t = self.cholesky_net.jacobian_transposed(q_scaled)
        cholesky = functional.linear(entries, self.placement).view(batch, n, n)
        derivative = functional.linear(jac_t / self.q_half_col, self.placement)
        return cholesky, derivative.view(batch, n, n, n)

    def sample_predictor(self) -> SamplePredictor:
        """forward() for one sample, q, v, a (n,) -> tau (n,), in float64 numpy."""
        n = self.n_dof
        scaling = self.numpy_scaling()
        centre, energy = scaling['q_centre'], scaling['lagrangian_energy']
        factor_half, potential_half = (
            float64_array(self.cholesky_q_half),
            scaling['lagrangian_q_half'],
        )
        factor_net = NumpyAnalyticMLP(self.cholesky_net)
        potential_net = NumpyAnalyticMLP(self.potential_net)
        placement_t = np.ascontiguousarray(float64_array(self.placement).T)

        def predict_one(q: np.ndarray, v: np.ndarray, a: np.ndarray) -> np.ndarray:
            entries, jac_t = factor_net.jacobian_transposed((q - centre) / factor_half)
            cholesky = (entries @ placement_t).reshape(n, n)
            derivative = ((jac_t / factor_half[:, None]) @ placement_t).reshape(n, n, n)
            _, gradient = potential_net.gradient((q - centre) / potential_half)
            tau: np.ndarray = euler_lagrange_one(cholesky, derivative, v, a)
            tau += energy * gradient / potential_half
            return tau

        return predict_one
