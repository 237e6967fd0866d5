"""The DeLaN torque network: a learned mass matrix M(q) = L L^T and potential V(q).

Holds ``DelanNetwork`` and ``euler_lagrange_torque``, the Euler-Lagrange torque of
``T = 1/2 v^T M(q) v`` from the Cholesky factor and its derivative (Lutter et al., ICLR 2019).
The model class that fits and saves it is ``models.lagrangian.DelanModel``.
"""

from __future__ import annotations

import numpy as np
import torch
from torch.nn import functional

from id_learning.models.base import SamplePredictor
from id_learning.models.lagrangian_base import LagrangianNetwork, LagrangianScaling
from id_learning.models.nets import AnalyticMLP, NumpyAnalyticMLP, numpy_sigmoid
from id_learning.models.torch_utils import float64_array, numpy_softplus

__all__ = ['DelanNetwork', 'euler_lagrange_torque']


def euler_lagrange_torque(
    cholesky: torch.Tensor,
    cholesky_derivative: torch.Tensor,
    v: torch.Tensor,
    a: torch.Tensor,
) -> tuple[torch.Tensor, torch.Tensor]:
    """Inertial and Coriolis/centrifugal torque of ``T = 1/2 v^T M(q) v`` with ``M = L L^T``.

    ``M a`` and ``Mdot v - 1/2 d/dq (v^T M v)``, from the Cholesky factor and its derivative,
    without forming ``dM/dq``: with ``y = L^T v`` and ``Ldot = sum_k dL/dq_k v_k``,
    ``Mdot v = Ldot y + L Ldot^T v`` and ``1/2 d/dq_k (v^T M v) = v^T (dL/dq_k) y``.

    Args:
        cholesky: (B, n, n) lower-triangular L(q) [sqrt(kg)*m].
        cholesky_derivative: (B, n, n, n) dL/dq_k, index order (b, k, i, j) for dL_ij / dq_k.
        v: (B, n) joint velocities [rad/s].
        a: (B, n) joint accelerations [rad/s^2].

    Returns:
        Inertial torque M a and Coriolis/centrifugal torque, each (B, n) [N*m].
    """
    # Batched products of n x n matrices written as broadcasts and sums: for small n this is
    # much faster than bmm over a large batch, and no slower for one sample.
    inertial = _matvec(cholesky, _rmatvec(cholesky, a))
    cholesky_dot = (cholesky_derivative * v[:, :, None, None]).sum(1)
    y = _rmatvec(cholesky, v)
    mass_dot_v = _matvec(cholesky_dot, y) + _matvec(cholesky, _rmatvec(cholesky_dot, v))
    outer = v.unsqueeze(2) * y.unsqueeze(1)  # (B, i, j) = v_i y_j
    kinetic_gradient = (cholesky_derivative * outer.unsqueeze(1)).sum((2, 3))
    return inertial, mass_dot_v - kinetic_gradient


def _matvec(matrix: torch.Tensor, vector: torch.Tensor) -> torch.Tensor:
    """(B, n, n) @ (B, n) -> (B, n)."""
    return (matrix * vector.unsqueeze(1)).sum(2)


def _rmatvec(matrix: torch.Tensor, vector: torch.Tensor) -> torch.Tensor:
    """(B, n, n)^T @ (B, n) -> (B, n)."""
    return (matrix * vector.unsqueeze(2)).sum(1)


class DelanNetwork(LagrangianNetwork):
    """DeLaN: networks for the Cholesky factor of M(q) and for the potential V(q).

    The Cholesky network outputs the n diagonal entries first (made positive by
    ``softplus(x + diagonal_shift) + diagonal_epsilon``), then the strictly lower entries row by
    row, forming the dimensionless factor ``L_s``; ``L = S (G * L_s)`` with
    ``S = diag(sqrt(e_i) / h_v,i)`` and ``G`` the fixed entry gains of the energy balance (see
    ``models.lagrangian_base``). State-dict keys:
    ``cholesky_net.layers.<i>.{weight,bias}``, ``potential_net.layers.<i>.{weight,bias}``.
    """

    placement: torch.Tensor
    cholesky_q_half: torch.Tensor
    q_half_col: torch.Tensor

    def __init__(
        self,
        scaling: LagrangianScaling,
        *,
        width: int = 64,
        depth: int = 2,
        activation: str = 'tanh',
        diagonal_epsilon: float = 1e-3,
        diagonal_shift: float = 0.0,
        generator: torch.Generator | None = None,
        init: str = 'xavier',
    ) -> None:
        super().__init__(scaling)
        n = self.n_dof
        n_entries = n * (n + 1) // 2
        self.diagonal_epsilon = diagonal_epsilon
        self.diagonal_shift = diagonal_shift
        self.cholesky_net = AnalyticMLP(
            n, n_entries, width, depth, activation, generator=generator, init=init
        )
        self.potential_net = AnalyticMLP(
            n, 1, width, depth, activation, generator=generator, init=init
        )
        # placement[i * n + j, e] = g_ij sqrt(e_i) / h_v[i] where entry e of the network's output
        # goes to L[i, j]: placing, balancing and scaling the rows is one matrix product.
        rows, cols = torch.tril_indices(n, n, offset=-1)
        targets = [i * n + i for i in range(n)] + (rows * n + cols).tolist()
        row_of_target = list(range(n)) + rows.tolist()
        placement = torch.zeros(n * n, n_entries, dtype=self.energy.dtype)
        joint_energy = self.tau_half * self.q_half
        placement[targets, range(n_entries)] = (torch.sqrt(joint_energy) / self.v_half)[
            row_of_target
        ] * self._entry_gains(rows, cols)
        self.register_buffer('placement', placement, persistent=False)
        self.register_buffer(
            'cholesky_q_half',
            self.lagrangian_q_half if scaling.balance_inertia else self.q_half.clone(),
            persistent=False,
        )
        self.register_buffer('q_half_col', self.cholesky_q_half.unsqueeze(-1), persistent=False)

    def _entry_gains(self, rows: torch.Tensor, cols: torch.Tensor) -> torch.Tensor:
        """Fixed gains of the factor's entries, diagonal first, then below it row by row.

        1 on the diagonal, ``(e_lo / e_hi)^(b / 2)`` below it (``e_lo``, ``e_hi`` the smaller and
        larger of the two joints' energies). An entry ``L_ij`` couples joints ``i`` and ``j``;
        unscaled, its effect on the smaller joint's normalised torque is ``sqrt(e_hi / e_lo)``
        times larger than on its own scale, so the optimiser's step noise on it swamps a wrist
        (MABI wrist roll: 0.5 N*m of leakage on a 0.46 N*m half range). The gain brings that
        sensitivity to order one at b = 1; a fixed non-zero factor leaves every positive
        definite M representable.
        """
        energy = self.tau_half * self.q_half
        low = torch.minimum(energy[rows], energy[cols])
        high = torch.maximum(energy[rows], energy[cols])
        below = (low / high) ** (0.5 * self.scaling.balance)
        return torch.cat([torch.ones(self.n_dof, dtype=below.dtype), below])

    def cholesky(self, q: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """Cholesky factor of M(q) and its derivative, physical units.

        Args:
            q: (B, n) joint positions [rad].

        Returns:
            L (B, n, n) with M = L L^T, and dL/dq (B, n, n, n) indexed (b, k, i, j) for
            dL_ij / dq_k.
        """
        return self._cholesky((q - self.q_centre) / self.cholesky_q_half)

    def _cholesky(self, q_scaled: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        n = self.n_dof
        batch = q_scaled.shape[0]
        entries, jac_t = self.cholesky_net.jacobian_transposed(q_scaled)
        raw_diagonal = entries[:, :n] + self.diagonal_shift
        diagonal = functional.softplus(raw_diagonal) + self.diagonal_epsilon
        diagonal_jac_t = torch.sigmoid(raw_diagonal).unsqueeze(1) * jac_t[:, :, :n]
        entries = torch.cat([diagonal, entries[:, n:]], dim=1)
        # jac_t (B, k, entry) / h_q[k]: the chain rule to physical q. The placement matrix puts
        # the entries into L and scales the rows by sqrt(E) / h_v (M = E D_v L_s L_s^T D_v).
        jac_t = torch.cat([diagonal_jac_t, jac_t[:, :, n:]], dim=2) / self.q_half_col
        cholesky = functional.linear(entries, self.placement).view(batch, n, n)
        derivative = functional.linear(jac_t, self.placement).view(batch, n, n, n)
        return cholesky, derivative

    def mass_matrix(self, q: torch.Tensor) -> torch.Tensor:
        """M(q) (B, n, n) [kg*m^2], symmetric positive definite."""
        cholesky, _ = self.cholesky(q)
        return torch.matmul(cholesky, cholesky.transpose(1, 2))

    def potential(self, q: torch.Tensor) -> torch.Tensor:
        """V(q) (B,) [J]."""
        x = (q - self.q_centre) / self.lagrangian_q_half
        out: torch.Tensor = self.lagrangian_energy * self.potential_net(x).squeeze(-1)
        return out

    def gravity(self, q: torch.Tensor) -> torch.Tensor:
        """dV/dq (B, n) [N*m]."""
        _, gradient = self.potential_net.gradient((q - self.q_centre) / self.lagrangian_q_half)
        return self.lagrangian_energy * gradient / self.lagrangian_q_half

    def components(
        self, q: torch.Tensor, v: torch.Tensor, a: torch.Tensor
    ) -> dict[str, torch.Tensor]:
        """Inertial M a, Coriolis/centrifugal, and gravity dV/dq, each (B, n) [N*m]."""
        q_scaled = (q - self.q_centre) / self.cholesky_q_half
        cholesky, derivative = self._cholesky(q_scaled)
        inertial, coriolis = euler_lagrange_torque(cholesky, derivative, v, a)
        return {'inertial': inertial, 'coriolis': coriolis, 'gravity': self.gravity(q)}

    def forward(self, q: torch.Tensor, v: torch.Tensor, a: torch.Tensor) -> torch.Tensor:
        """Torque (B, n) [N*m] from q, v, a (B, n) in SI units."""
        parts = self.components(q, v, a)
        return parts['inertial'] + parts['coriolis'] + parts['gravity']

    def sample_predictor(self) -> SamplePredictor:
        """forward() for one sample, q, v, a (n,) -> tau (n,), in float64 numpy."""
        n = self.n_dof
        scaling = self.numpy_scaling()
        q_centre, potential_half = scaling['q_centre'], scaling['lagrangian_q_half']
        energy = scaling['lagrangian_energy']
        q_half = float64_array(self.cholesky_q_half)
        q_half_col = q_half[:, None]
        cholesky_net = NumpyAnalyticMLP(self.cholesky_net)
        potential_net = NumpyAnalyticMLP(self.potential_net)
        placement_t = np.ascontiguousarray(float64_array(self.placement).T)
        shift, epsilon = self.diagonal_shift, self.diagonal_epsilon

        def predict_one(q: np.ndarray, v: np.ndarray, a: np.ndarray) -> np.ndarray:
            q_scaled = (q - q_centre) / q_half
            entries, jac_t = cholesky_net.jacobian_transposed(q_scaled)
            raw_diagonal = entries[:n] + shift
            entries[:n] = numpy_softplus(raw_diagonal) + epsilon
            jac_t[:, :n] *= numpy_sigmoid(raw_diagonal)
            jac_t /= q_half_col
            cholesky = (entries @ placement_t).reshape(n, n)
            derivative = (jac_t @ placement_t).reshape(n, n, n)  # (k, i, j): dL_ij / dq_k
            # As euler_lagrange_torque, for one sample.
            inertial = cholesky @ (a @ cholesky)
            cholesky_dot = v @ derivative.reshape(n, n * n)
            cholesky_dot = cholesky_dot.reshape(n, n)
            y = v @ cholesky
            mass_dot_v = cholesky_dot @ y + cholesky @ (v @ cholesky_dot)
            kinetic_gradient = (derivative @ y) @ v
            _, gradient = potential_net.gradient((q - q_centre) / potential_half)
            gravity = energy * gradient / potential_half
            tau: np.ndarray = inertial + (mass_dot_v - kinetic_gradient) + gravity
            return tau

        return predict_one
