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

Normalisation (fixed when fitting and saved with the model as fitted metadata): the networks see
``q`` and ``v`` mapped to [-1, 1] with the dataset's min-max scalers (``q_s = (q - c_q) / h_q``,
``v_s = (v - c_v) / h_v``), so derivatives with respect to the physical ``q``, ``v`` are those
with respect to the network inputs divided by the half ranges ``h_q``, ``h_v``. The networks work
at unit scale and their outputs are given physical units by fixed factors built from the
training ranges. A torque is an energy per radian, so joint ``i`` has the energy scale
``e_i = h_tau,i * h_q,i`` (torque half range times position half range) and the whole arm
``E = geometric mean of e_i`` [J]:

- LNN: ``L(q, v) = E * l(q_s, v_s)``.
- DeLaN: ``V(q) = E * v(q_s)`` and ``M(q) = S L_s(q_s) L_s(q_s)^T S`` with
  ``S = diag(sqrt(e_i) / h_v,i)``: the kinetic energy of joint ``i`` at its velocity half range
  is of order ``e_i``. A per-joint ``S`` keeps each row of ``M a`` at its joint's torque scale.
  With one ``E`` a wrist's entries of ``L_s`` must be tens of times smaller than the base's,
  and the errors the shared network leaks into them dominate the wrist's normalised loss
  (300 s joint-torque twin: validation loss 1.6 with one ``E``, 0.24 with ``S``; wrist test
  RMSE 2.67 and 1.02 of its half range). ``S`` is fixed and invertible, so every symmetric
  positive definite ``M`` stays representable.
- LNN+MLP: the dissipation network's output is multiplied by the torque half ranges ``h_tau``.

The loss is the mean squared torque error on the study's normalised scale (each joint divided
by its half range ``h_tau``).
"""

from __future__ import annotations

from abc import abstractmethod
from dataclasses import dataclass
from typing import Any, ClassVar, Literal, Self

import numpy as np
import torch
from torch import nn
from torch.nn import functional

from id_learning.dataset.preprocess import Dataset, MinMaxScaler
from id_learning.errors import CheckpointError, ConfigError, DatasetError
from id_learning.models.base import (
    InverseDynamicsModel,
    ModelConfig,
    SamplePredictor,
    TorqueComponents,
)
from id_learning.models.data import TrainingData
from id_learning.models.fitting import OptimConfig, fit_network, select_device
from id_learning.models.nets import (
    SMOOTH_ACTIVATIONS,
    AnalyticMLP,
    NumpyAnalyticMLP,
    numpy_sigmoid,
)
from id_learning.models.torch_utils import (
    float64_array,
    numpy_softplus,
    to_numpy,
    to_tensor,
)
from id_learning.robot.config import RobotConfig

__all__ = [
    'DelanConfig',
    'DelanModel',
    'DelanNetwork',
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


# --------------------------------------------------------------------------------------------
# Normalisation


def energy_scale(position_half_range: np.ndarray, torque_half_range: np.ndarray) -> float:
    """Geometric mean over joints of torque half range times position half range [J]."""
    product = np.asarray(torque_half_range, float) * np.asarray(position_half_range, float)
    return float(np.exp(np.mean(np.log(product))))


@dataclass(frozen=True, eq=False)
class LagrangianScaling:
    """Fixed maps between physical units and the networks' unit scale.

    Attributes:
        position: q [rad] -> [-1, 1], per joint.
        velocity: v [rad/s] -> [-1, 1], per joint.
        torque: tau [N*m] -> [-1, 1], per joint: the loss scale and the dissipation output scale.
        energy: E [J], the factor from the networks' dimensionless Lagrangian to joules.
    """

    position: MinMaxScaler
    velocity: MinMaxScaler
    torque: MinMaxScaler
    energy: float

    @property
    def n_dof(self) -> int:
        """Number of joints."""
        return len(self.position.scale())

    @classmethod
    def from_data(cls, q: np.ndarray, v: np.ndarray, tau: np.ndarray) -> LagrangianScaling:
        """Fit the scalers on training arrays (N, n) and derive the energy scale."""
        position = MinMaxScaler().fit(np.asarray(q, float))
        torque = MinMaxScaler().fit(np.asarray(tau, float))
        return cls(
            position,
            MinMaxScaler().fit(np.asarray(v, float)),
            torque,
            energy_scale(position.scale(), torque.scale()),
        )

    @classmethod
    def from_dataset(cls, dataset: Dataset) -> LagrangianScaling:
        """Reuse the dataset's scalers (fitted on its training part): q and v columns, target."""
        inputs = dataset.input_scaler
        if inputs.low_ is None or inputs.high_ is None:
            raise DatasetError('the dataset input scaler is not fitted')
        n = len(dataset.joints)
        position = MinMaxScaler(inputs.low_[:n].copy(), inputs.high_[:n].copy())
        velocity = MinMaxScaler(inputs.low_[n : 2 * n].copy(), inputs.high_[n : 2 * n].copy())
        torque = MinMaxScaler.from_dict(dataset.target_scaler.to_dict())
        return cls(position, velocity, torque, energy_scale(position.scale(), torque.scale()))

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready state."""
        return {
            'position': self.position.to_dict(),
            'velocity': self.velocity.to_dict(),
            'torque': self.torque.to_dict(),
            'energy_scale_j': self.energy,
        }

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> LagrangianScaling:
        """Rebuild from ``to_dict`` output."""
        return cls(
            MinMaxScaler.from_dict(data['position']),
            MinMaxScaler.from_dict(data['velocity']),
            MinMaxScaler.from_dict(data['torque']),
            float(data['energy_scale_j']),
        )


class LagrangianNetwork(nn.Module):
    """Base of the torque networks: maps SI states to torque through a scaled Lagrangian.

    The scaling is kept as non-persistent buffers: they move with ``.to()`` but are not
    weights (they are saved as fitted metadata).
    """

    q_centre: torch.Tensor
    q_half: torch.Tensor
    v_centre: torch.Tensor
    v_half: torch.Tensor
    tau_half: torch.Tensor
    energy: torch.Tensor

    def __init__(self, scaling: LagrangianScaling) -> None:
        super().__init__()
        self.scaling = scaling
        self.n_dof = scaling.n_dof

        def centre(scaler: MinMaxScaler) -> np.ndarray:
            assert scaler.low_ is not None
            assert scaler.high_ is not None
            return 0.5 * (scaler.low_ + scaler.high_)

        buffers = {
            'q_centre': centre(scaling.position),
            'q_half': scaling.position.scale(),
            'v_centre': centre(scaling.velocity),
            'v_half': scaling.velocity.scale(),
            'tau_half': scaling.torque.scale(),
            'energy': np.asarray(scaling.energy),
        }
        dtype = torch.get_default_dtype()
        for name, value in buffers.items():
            self.register_buffer(name, torch.as_tensor(value, dtype=dtype), persistent=False)

    def scaled_state(self, q: torch.Tensor, v: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """Map q and v to [-1, 1]."""
        return (q - self.q_centre) / self.q_half, (v - self.v_centre) / self.v_half

    @abstractmethod
    def forward(self, q: torch.Tensor, v: torch.Tensor, a: torch.Tensor) -> torch.Tensor:
        """Torque (B, n) [N*m] from q, v, a (B, n) in SI units."""

    @abstractmethod
    def sample_predictor(self) -> SamplePredictor:
        """forward() for one sample in float64 numpy, from a copy of the current weights."""

    def numpy_scaling(self) -> dict[str, np.ndarray]:
        """The scaling buffers as float64 numpy arrays, by name (energy as a 0-d array)."""
        names = ('q_centre', 'q_half', 'v_centre', 'v_half', 'tau_half', 'energy')
        return {name: float64_array(getattr(self, name)) for name in names}

    @abstractmethod
    def components(
        self, q: torch.Tensor, v: torch.Tensor, a: torch.Tensor
    ) -> dict[str, torch.Tensor]:
        """The torque split into named parts (B, n) [N*m] that sum to forward()."""


# --------------------------------------------------------------------------------------------
# DeLaN


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
    row, forming the dimensionless factor ``L_s``; ``L = S L_s`` with
    ``S = diag(sqrt(e_i) / h_v,i)`` (see the module docstring). State-dict keys:
    ``cholesky_net.layers.<i>.{weight,bias}``, ``potential_net.layers.<i>.{weight,bias}``.
    """

    placement: torch.Tensor
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
    ) -> None:
        super().__init__(scaling)
        n = self.n_dof
        n_entries = n * (n + 1) // 2
        self.diagonal_epsilon = diagonal_epsilon
        self.diagonal_shift = diagonal_shift
        self.cholesky_net = AnalyticMLP(
            n, n_entries, width, depth, activation, generator=generator
        )
        self.potential_net = AnalyticMLP(n, 1, width, depth, activation, generator=generator)
        # placement[i * n + j, e] = sqrt(e_i) / h_v[i] where entry e of the network's output goes
        # to L[i, j]: placing the entries and scaling the rows is one matrix product.
        rows, cols = torch.tril_indices(n, n, offset=-1)
        targets = [i * n + i for i in range(n)] + (rows * n + cols).tolist()
        row_of_target = list(range(n)) + rows.tolist()
        placement = torch.zeros(n * n, n_entries, dtype=self.energy.dtype)
        joint_energy = self.tau_half * self.q_half
        placement[targets, range(n_entries)] = (torch.sqrt(joint_energy) / self.v_half)[
            row_of_target
        ]
        self.register_buffer('placement', placement, persistent=False)
        self.register_buffer('q_half_col', self.q_half.unsqueeze(-1), persistent=False)

    def cholesky(self, q: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """Cholesky factor of M(q) and its derivative, physical units.

        Args:
            q: (B, n) joint positions [rad].

        Returns:
            L (B, n, n) with M = L L^T, and dL/dq (B, n, n, n) indexed (b, k, i, j) for
            dL_ij / dq_k.
        """
        return self._cholesky((q - self.q_centre) / self.q_half)

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
        return self.energy * self.potential_net((q - self.q_centre) / self.q_half).squeeze(-1)

    def gravity(self, q: torch.Tensor) -> torch.Tensor:
        """dV/dq (B, n) [N*m]."""
        return self._gravity((q - self.q_centre) / self.q_half)

    def _gravity(self, q_scaled: torch.Tensor) -> torch.Tensor:
        _, gradient = self.potential_net.gradient(q_scaled)
        return self.energy * gradient / self.q_half

    def components(
        self, q: torch.Tensor, v: torch.Tensor, a: torch.Tensor
    ) -> dict[str, torch.Tensor]:
        """Inertial M a, Coriolis/centrifugal, and gravity dV/dq, each (B, n) [N*m]."""
        q_scaled = (q - self.q_centre) / self.q_half
        cholesky, derivative = self._cholesky(q_scaled)
        inertial, coriolis = euler_lagrange_torque(cholesky, derivative, v, a)
        return {'inertial': inertial, 'coriolis': coriolis, 'gravity': self._gravity(q_scaled)}

    def forward(self, q: torch.Tensor, v: torch.Tensor, a: torch.Tensor) -> torch.Tensor:
        """Torque (B, n) [N*m] from q, v, a (B, n) in SI units."""
        parts = self.components(q, v, a)
        return parts['inertial'] + parts['coriolis'] + parts['gravity']

    def sample_predictor(self) -> SamplePredictor:
        """forward() for one sample, q, v, a (n,) -> tau (n,), in float64 numpy."""
        n = self.n_dof
        scaling = self.numpy_scaling()
        q_centre, q_half, energy = scaling['q_centre'], scaling['q_half'], scaling['energy']
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
            _, gradient = potential_net.gradient(q_scaled)
            gravity = energy * gradient / q_half
            tau: np.ndarray = inertial + (mass_dot_v - kinetic_gradient) + gravity
            return tau

        return predict_one


# --------------------------------------------------------------------------------------------
# LNN


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
    ) -> None:
        super().__init__(scaling)
        self.lagrangian_net = AnalyticMLP(
            2 * self.n_dof, 1, width, depth, activation, generator=generator
        )

    def _parts(
        self, q: torch.Tensor, v: torch.Tensor, v_direction: torch.Tensor, a: torch.Tensor
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """(d2L/dv2) a + (d2L/dq dv) v_direction and dL/dq at (q, v), physical units."""
        n = self.n_dof
        q_s, v_s = self.scaled_state(q, v)
        # The Hessian in physical units is D H_s D with D = diag(1/h_q, 1/h_v), so
        # [H u]_v = (1/h_v) [H_s (D u)]_v and dL/dq = (1/h_q) [grad_s]_q.
        direction = torch.cat([v_direction / self.q_half, a / self.v_half], dim=1)
        _, gradient, hvp = self.lagrangian_net.gradient_and_hvp(
            torch.cat([q_s, v_s], dim=1), direction
        )
        return (
            self.energy * hvp[:, n:] / self.v_half,
            self.energy * gradient[:, :n] / self.q_half,
        )

    def forward(self, q: torch.Tensor, v: torch.Tensor, a: torch.Tensor) -> torch.Tensor:
        """Torque (B, n) [N*m]: (d2L/dv2) a + (d2L/dq dv) v - dL/dq, one analytic pass."""
        hvp, gradient_q = self._parts(q, v, v, a)
        return hvp - gradient_q

    def sample_predictor(self) -> SamplePredictor:
        """forward() for one sample, q, v, a (n,) -> tau (n,), in float64 numpy."""
        n = self.n_dof
        s = self.numpy_scaling()
        centre = np.concatenate([s['q_centre'], s['v_centre']])
        half = np.concatenate([s['q_half'], s['v_half']])
        hvp_scale, gradient_scale = s['energy'] / s['v_half'], s['energy'] / s['q_half']
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
    ) -> None:
        super().__init__(scaling)
        self.lnn = LnnNetwork(
            scaling, width=width, depth=depth, activation=activation, generator=generator
        )
        self.dissipation_net = AnalyticMLP(
            2 * self.n_dof,
            self.n_dof,
            dissipation_width,
            dissipation_depth,
            dissipation_activation,
            generator=generator,
        )

    def dissipation(self, q: torch.Tensor, v: torch.Tensor) -> torch.Tensor:
        """Dissipative (friction) torque h(q, v) (B, n) [N*m]."""
        q_s, v_s = self.scaled_state(q, v)
        return self.tau_half * self.dissipation_net(torch.cat([q_s, v_s], dim=1))

    def forward(self, q: torch.Tensor, v: torch.Tensor, a: torch.Tensor) -> torch.Tensor:
        """Torque (B, n) [N*m]: the LNN's plus the dissipative torque."""
        return self.lnn(q, v, a) + self.dissipation(q, v)

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


# --------------------------------------------------------------------------------------------
# Models


_DEVICES = ('auto', 'cpu', 'cuda')


@dataclass(frozen=True)
class _LagrangianConfig(ModelConfig):
    """Settings shared by the Lagrangian models.

    Defaults: 2 hidden layers of 64 tanh units (the study's and the DeLaN reference's size and
    activation); Adam with learning rate 1e-3, mini-batches of 256, weight decay 1e-3 and
    early stopping after 30 epochs without progress, on every 4th sample: chosen on the
    validation loss of the shipped bag (motor torque target).

    Attributes:
        width: units per hidden layer.
        depth: hidden layers.
        activation: 'tanh' or 'softplus' (needs a smooth second derivative).
        learning_rate: Adam step size.
        batch_size: samples per mini-batch.
        max_epochs: upper bound on epochs.
        patience: early stopping after this many epochs without a better validation loss.
        weight_decay: Adam's L2 penalty.
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
    learning_rate: float = 1e-3
    batch_size: int = 256
    max_epochs: int = 300
    patience: int = 30
    weight_decay: float = 1e-3
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
        )


@dataclass(frozen=True)
class DelanConfig(_LagrangianConfig):
    """DeLaN settings (see _LagrangianConfig for the shared ones).

    Attributes:
        weight_decay: 1e-2 (1e-3 for the LNNs): on the shipped bag the mass-matrix and potential
            networks generalise better with the stronger penalty (validation loss 0.147 vs 0.173).
        diagonal_epsilon: lower bound of the Cholesky diagonal on the unit scale, keeps M(q)
            positive definite (M_ii >= e_i * epsilon^2 / h_v,i^2).
        diagonal_shift: added before the diagonal's softplus (softplus(0) = 0.69 at the start).
    """

    kind: Literal['delan'] = 'delan'
    weight_decay: float = 1e-2
    diagonal_epsilon: float = 1e-3
    diagonal_shift: float = 0.0

    def __post_init__(self) -> None:
        """Check ranges, naming the key."""
        super().__post_init__()
        if not self.diagonal_epsilon > 0:
            raise ConfigError(f'delan: diagonal_epsilon must be > 0, got {self.diagonal_epsilon}')


@dataclass(frozen=True)
class LnnConfig(_LagrangianConfig):
    """LNN settings (see _LagrangianConfig)."""

    kind: Literal['lnn'] = 'lnn'


@dataclass(frozen=True)
class LnnMlpConfig(_LagrangianConfig):
    """LNN+MLP settings (see _LagrangianConfig for the shared ones).

    Attributes:
        dissipation_width: units per hidden layer of the dissipation MLP.
        dissipation_depth: its hidden layers.
        dissipation_activation: its activation.
    """

    kind: Literal['lnn_mlp'] = 'lnn_mlp'
    dissipation_width: int = 64
    dissipation_depth: int = 2
    dissipation_activation: str = 'tanh'

    def __post_init__(self) -> None:
        """Check ranges, naming the key."""
        super().__post_init__()
        for key in ('dissipation_width', 'dissipation_depth'):
            value = getattr(self, key)
            if not isinstance(value, int) or value < 1:
                raise ConfigError(f'lnn_mlp: {key} must be an integer >= 1, got {value!r}')

    def _activation_keys(self) -> tuple[str, ...]:
        return ('activation', 'dissipation_activation')


class _LagrangianModel(InverseDynamicsModel):
    """Fit, predict, save and load shared by the three Lagrangian models.

    Fitted state: ``network_`` (on the CPU, float32), ``scaling_`` and ``history_``.
    """

    config: _LagrangianConfig

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
        self.network_: LagrangianNetwork | None = None
        self.scaling_: LagrangianScaling | None = None
        self.history_: dict[str, Any] | None = None

    @abstractmethod
    def make_network(
        self, scaling: LagrangianScaling, generator: torch.Generator
    ) -> LagrangianNetwork:
        """Build an untrained network of this configuration, weights drawn from generator."""

    @property
    def is_fitted(self) -> bool:
        """Whether the model has weights (fitted or loaded)."""
        return self.network_ is not None

    def _network(self) -> LagrangianNetwork:
        if self.network_ is None:
            raise RuntimeError(f'{self.kind} model is not fitted: call fit() or load_state()')
        return self.network_

    def fit(self, data: TrainingData, *, progress: bool = False) -> Self:
        """Fit the torque to the labels; early stopping on the validation rows.

        Minimises the mean squared torque error on the normalised scale (``fit_network``):
        through the label filter on contiguous windows (the default), or the study's way on
        every stride-th sample. Trains on ``config.device``; the fitted network is moved to the
        CPU for prediction.

        Raises:
            DatasetError: the dataset's joints are not the robot's.
        """
        dataset = data.dataset
        if tuple(dataset.joints) != tuple(self.joint_names):
            raise DatasetError(
                f'{self.kind}: dataset joints {list(dataset.joints)} are not the robot '
                f'joints {list(self.joint_names)}'
            )
        config = self.config
        device = select_device(config.device)
        scaling = LagrangianScaling.from_dataset(dataset)
        network = self.make_network(scaling, torch.Generator().manual_seed(config.seed))
        q, v, a = (to_tensor(x, device) for x in (dataset.q, dataset.v, dataset.a))
        n = len(self.joint_names)

        def predict(rows: torch.Tensor, positions: torch.Tensor) -> torch.Tensor:
            index = rows[:, positions]
            flat = index.reshape(-1)
            torque: torch.Tensor = network(q[flat], v[flat], a[flat])
            return torque.reshape(*index.shape, n)

        history = fit_network(
            network,
            predict,
            data,
            dataset.tau,
            scaling.torque.scale(),
            config=config,
            device=device,
            progress=progress,
        )
        self.network_ = network
        self.scaling_ = scaling
        self.history_ = history.to_dict()
        return self

    def _evaluate(
        self, q: np.ndarray, v: np.ndarray, a: np.ndarray, *, parts: bool
    ) -> dict[str, np.ndarray]:
        network = self._network()
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
        return self._network().sample_predictor()

    def components(self, q: np.ndarray, v: np.ndarray, a: np.ndarray) -> TorqueComponents:
        """Inertial, Coriolis/centrifugal and gravity parts (and friction where modelled)."""
        parts = self._evaluate(q, v, a, parts=True)
        return TorqueComponents(total=self.predict(q, v, a), **parts)

    def state(self) -> dict[str, np.ndarray]:
        """Weights as numpy arrays named like the network's state_dict keys."""
        return {
            name: value.detach().cpu().numpy().copy()
            for name, value in self._network().state_dict().items()
        }

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
        network = self.make_network(scaling, torch.Generator().manual_seed(self.config.seed))
        try:
            network.load_state_dict(
                {name: torch.as_tensor(np.asarray(value)) for name, value in tensors.items()},
                strict=True,
            )
        except RuntimeError as err:
            raise CheckpointError(f'{self.kind}: weights do not fit the network: {err}') from err
        self.network_ = network.eval()
        self.scaling_ = scaling
        self.history_ = fitted.get('history')

    def fitted_metadata(self) -> dict[str, Any]:
        """The scaling (scalers and energy scale) and the training history."""
        if self.scaling_ is None:
            return {}
        return {'scaling': self.scaling_.to_dict(), 'history': self.history_}


class DelanModel(_LagrangianModel):
    """Deep Lagrangian Network: torque from a learned mass matrix M(q) and potential V(q).

    Components: inertial M a, Coriolis/centrifugal, gravity dV/dq; friction None (a
    Lagrangian model has no dissipation).
    """

    kind: ClassVar[str] = 'delan'
    config: DelanConfig

    def make_network(
        self, scaling: LagrangianScaling, generator: torch.Generator
    ) -> LagrangianNetwork:
        """Build an untrained network of this configuration, weights drawn from generator."""
        config = self.config
        return DelanNetwork(
            scaling,
            width=config.width,
            depth=config.depth,
            activation=config.activation,
            diagonal_epsilon=config.diagonal_epsilon,
            diagonal_shift=config.diagonal_shift,
            generator=generator,
        )

    def mass_matrix(self, q: np.ndarray) -> np.ndarray:
        """M(q) (B, n, n) [kg*m^2] for q (B, n) [rad]."""
        network = self._network()
        assert isinstance(network, DelanNetwork)
        with torch.inference_mode():
            return to_numpy(network.mass_matrix(to_tensor(q)))


class LnnModel(_LagrangianModel):
    """Black-box Lagrangian network: torque from the derivatives of one learned L(q, v).

    Components (a convention for a general L): inertial (d2L/dv2) a, gravity -dL/dq at v = 0,
    Coriolis the rest; friction None.
    """

    kind: ClassVar[str] = 'lnn'
    config: LnnConfig

    def make_network(
        self, scaling: LagrangianScaling, generator: torch.Generator
    ) -> LagrangianNetwork:
        """Build an untrained network of this configuration, weights drawn from generator."""
        config = self.config
        return LnnNetwork(
            scaling,
            width=config.width,
            depth=config.depth,
            activation=config.activation,
            generator=generator,
        )


class LnnMlpModel(_LagrangianModel):
    """LNN plus an MLP h(q, v) for dissipative torques; components as LNN, friction = h."""

    kind: ClassVar[str] = 'lnn_mlp'
    config: LnnMlpConfig

    def make_network(
        self, scaling: LagrangianScaling, generator: torch.Generator
    ) -> LagrangianNetwork:
        """Build an untrained network of this configuration, weights drawn from generator."""
        config = self.config
        return LnnMlpNetwork(
            scaling,
            width=config.width,
            depth=config.depth,
            activation=config.activation,
            dissipation_width=config.dissipation_width,
            dissipation_depth=config.dissipation_depth,
            dissipation_activation=config.dissipation_activation,
            generator=generator,
        )
