"""The black-box Lagrangian torque networks: the LNN and the LNN plus a dissipation MLP.

``LnnNetwork`` (Cranmer et al. 2020) learns one scalar ``L(q, v)`` and takes the torque from its
gradient and Hessian-vector product; ``LnnMlpNetwork`` adds an MLP ``h(q, v)`` for the
dissipative torque a Lagrangian cannot represent. The model classes that fit and save them are
in ``models.lagrangian``.
"""

from __future__ import annotations

import numpy as np
import torch

from id_learning.models.base import SamplePredictor
from id_learning.models.lagrangian_base import LagrangianNetwork, LagrangianScaling
from id_learning.models.nets import AnalyticMLP, NumpyAnalyticMLP

__all__ = ['LnnMlpNetwork', 'LnnNetwork']


class LnnNetwork(LagrangianNetwork):
    """Black-box Lagrangian network: one scalar network l(q_s, v_s), ``L = E l``.

    State-dict keys: ``lagrangian_net.layers.<i>.{weight,bias}``.
    """

    def __init__(
        self,
        scaling: LagrangianScaling,
        *,
        width: int = 64,
        depth: int = 2,
        activation: str = 'softplus',
        generator: torch.Generator | None = None,
        init: str = 'xavier',
    ) -> None:
        super().__init__(scaling)
        self.lagrangian_net = AnalyticMLP(
            2 * self.n_dof, 1, width, depth, activation, generator=generator, init=init
        )

    def _parts(
        self, q: torch.Tensor, v: torch.Tensor, v_direction: torch.Tensor, a: torch.Tensor
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """(d2L/dv2) a + (d2L/dq dv) v_direction and dL/dq at (q, v), physical units."""
        n = self.n_dof
        q_half, v_half = self.lagrangian_q_half, self.lagrangian_v_half
        q_s, v_s = (q - self.q_centre) / q_half, (v - self.v_centre) / v_half
        # The Hessian in physical units is D H_s D with D = diag(1/h_q, 1/h_v) (the balanced
        # half ranges), so [H u]_v = (1/h_v) [H_s (D u)]_v and dL/dq = (1/h_q) [grad_s]_q.
        direction = torch.cat([v_direction / q_half, a / v_half], dim=1)
        _, gradient, hvp = self.lagrangian_net.gradient_and_hvp(
            torch.cat([q_s, v_s], dim=1), direction
        )
        energy = self.lagrangian_energy
        return energy * hvp[:, n:] / v_half, energy * gradient[:, :n] / q_half

    def forward(self, q: torch.Tensor, v: torch.Tensor, a: torch.Tensor) -> torch.Tensor:
        """Torque (B, n) [N*m]: (d2L/dv2) a + (d2L/dq dv) v - dL/dq, one analytic pass."""
        hvp, gradient_q = self._parts(q, v, v, a)
        return hvp - gradient_q

    def sample_predictor(self) -> SamplePredictor:
        """forward() for one sample, q, v, a (n,) -> tau (n,), in float64 numpy."""
        n = self.n_dof
        s = self.numpy_scaling()
        q_half, v_half = s['lagrangian_q_half'], s['lagrangian_v_half']
        centre = np.concatenate([s['q_centre'], s['v_centre']])
        half = np.concatenate([q_half, v_half])
        energy = s['lagrangian_energy']
        hvp_scale, gradient_scale = energy / v_half, energy / q_half
        net = NumpyAnalyticMLP(self.lagrangian_net)
        concatenate = np.concatenate

        def predict_one(q: np.ndarray, v: np.ndarray, a: np.ndarray) -> np.ndarray:
            state = (concatenate((q, v)) - centre) / half
            _, gradient, hvp = net.gradient_and_hvp(state, concatenate((v, a)) / half)
            tau: np.ndarray = hvp_scale * hvp[n:] - gradient_scale * gradient[:n]
            return tau

        return predict_one

    def components(
        self, q: torch.Tensor, v: torch.Tensor, a: torch.Tensor
    ) -> dict[str, torch.Tensor]:
        """Inertial (d2L/dv2) a, gravity -dL/dq at v = 0, Coriolis the rest; (B, n) [N*m].

        For a Lagrangian of the form 1/2 v^T M(q) v - V(q) these are exactly M a, c(q, v) and
        dV/dq; for a general learned L they are a convention.
        """
        zeros = torch.zeros_like(v)
        inertial, _ = self._parts(q, v, zeros, a)
        _, gradient_q_at_rest = self._parts(q, zeros, zeros, zeros)
        total = self.forward(q, v, a)
        gravity = -gradient_q_at_rest
        return {'inertial': inertial, 'coriolis': total - inertial - gravity, 'gravity': gravity}


class LnnMlpNetwork(LagrangianNetwork):
    """LNN plus an MLP h(q, v) for dissipative torques: tau = tau_LNN + h_tau * h(q_s, v_s).

    State-dict keys: ``lnn.lagrangian_net.layers.<i>.*`` and ``dissipation_net.layers.<i>.*``.
    """

    def __init__(
        self,
        scaling: LagrangianScaling,
        *,
        width: int = 64,
        depth: int = 2,
        activation: str = 'softplus',
        dissipation_width: int = 64,
        dissipation_depth: int = 2,
        dissipation_activation: str = 'tanh',
        generator: torch.Generator | None = None,
        init: str = 'xavier',
    ) -> None:
        super().__init__(scaling)
        self.lnn = LnnNetwork(
            scaling,
            width=width,
            depth=depth,
            activation=activation,
            generator=generator,
            init=init,
        )
        self.dissipation_net = AnalyticMLP(
            2 * self.n_dof,
            self.n_dof,
            dissipation_width,
            dissipation_depth,
            dissipation_activation,
            generator=generator,
            init=init,
        )

    def dissipation(self, q: torch.Tensor, v: torch.Tensor) -> torch.Tensor:
        """Dissipative (friction) torque h(q, v) (B, n) [N*m]."""
        q_s, v_s = self.scaled_state(q, v)
        out: torch.Tensor = self.tau_half * self.dissipation_net(torch.cat([q_s, v_s], dim=1))
        return out

    def forward(self, q: torch.Tensor, v: torch.Tensor, a: torch.Tensor) -> torch.Tensor:
        """Torque (B, n) [N*m]: the LNN's plus the dissipative torque."""
        out: torch.Tensor = self.lnn(q, v, a) + self.dissipation(q, v)
        return out

    def sample_predictor(self) -> SamplePredictor:
        """forward() for one sample, q, v, a (n,) -> tau (n,), in float64 numpy."""
        lnn = self.lnn.sample_predictor()
        s = self.numpy_scaling()
        centre = np.concatenate([s['q_centre'], s['v_centre']])
        half = np.concatenate([s['q_half'], s['v_half']])
        tau_half = s['tau_half']
        net = NumpyAnalyticMLP(self.dissipation_net)
        concatenate = np.concatenate

        def predict_one(q: np.ndarray, v: np.ndarray, a: np.ndarray) -> np.ndarray:
            dissipation = tau_half * net((concatenate((q, v)) - centre) / half)
            tau: np.ndarray = lnn(q, v, a) + dissipation
            return tau

        return predict_one

    def components(
        self, q: torch.Tensor, v: torch.Tensor, a: torch.Tensor
    ) -> dict[str, torch.Tensor]:
        """The LNN's parts and friction h(q, v), each (B, n) [N*m]."""
        return {**self.lnn.components(q, v, a), 'friction': self.dissipation(q, v)}
