"""The Lagrangian networks' normalisation and their common base class.

Holds what DeLaN (``models.delan``) and the LNNs (``models.lnn``) share: the fixed scaling
between physical units and the networks' unit scale (``LagrangianScaling``, saved with a model
as fitted metadata) and ``LagrangianNetwork``, which keeps that scaling as buffers.

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

Balance (the potential's and the LNN's inputs): a scalar energy serves every joint, and on a
heavy arm the ``e_i`` span three to four orders of magnitude (MABI: 2.3 J wrist roll, 5900 J
shoulder). With plain inputs a joint's normalised torque is ``E / e_i`` times the net's input
gradient: the wrist's error is amplified a hundredfold and its noisy gradients on the shared
weights starve the shoulder, whose gravity is then never learned (supervised on the true
gravity alone: shoulder error 0.46 of its half range after 100 epochs, 0.016 without the wrist
in the loss). So the scalar nets see ``r_i q_s,i`` (and ``r_i v_s,i``) with
``r_i = (e_i / e_max)^b`` and the energy scale is ``E_b = E (e_max / E)^b``: at ``b = 1`` every
joint's normalised torque is equally sensitive to the net's input gradient. DeLaN's factor gets
the same treatment: an entry ``L_ij`` below the diagonal is scaled by
``(min(e_i, e_j) / max(e_i, e_j))^(b / 2)``, so that the optimiser's step noise on the coupling
of a shoulder and a wrist does not leak hundreds of times the wrist's torque scale into it, and
its Cholesky network sees the balanced positions as the potential does: the kinetic energy's
gradient ``1/2 v^T dM/dq_k v`` reaches joint k's torque just as the potential's does, and with
plain inputs the shoulder's inertia varying with the wrist roll angle leaked into the wrist (MABI
rigid-body twin: wrist roll test RMSE 0.32 -> 0.08 N*m, base 122 -> 54 N*m). These
are changes of coordinates, not of model: the first layer (and the fixed entry gains) absorb
them, every Lagrangian stays representable. ``b = 0`` is the plain scaling (models saved before
the balance existed); smaller ``b`` keeps more of a small joint's nonlinear dependence within the
net's reach (its inputs span ``r_i`` of [-1, 1]), larger ``b`` conditions the fit better.
"""

from __future__ import annotations

from abc import abstractmethod
from dataclasses import dataclass
from typing import Any

import numpy as np
import torch
from torch import nn

from id_learning.dataset.preprocess import Dataset, MinMaxScaler
from id_learning.errors import DatasetError
from id_learning.models.base import SamplePredictor
from id_learning.models.torch_utils import float64_array

__all__ = ['LagrangianNetwork', 'LagrangianScaling', 'energy_scale']


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
        energy: E [J], the geometric mean of the joints' energy scales ``e_i``.
        balance: exponent b of the scalar nets' input gains (module docstring); 0 for none.
        balance_inertia: DeLaN's Cholesky network sees the balanced positions too (module
            docstring); False in models saved before it did.
    """

    position: MinMaxScaler
    velocity: MinMaxScaler
    torque: MinMaxScaler
    energy: float
    balance: float = 0.0
    balance_inertia: bool = True

    @property
    def n_dof(self) -> int:
        """Number of joints."""
        return len(self.position.scale())

    def joint_energies(self) -> np.ndarray:
        """e_i = h_tau,i * h_q,i (n,) [J]."""
        out: np.ndarray = self.torque.scale() * self.position.scale()
        return out

    def balanced(self) -> tuple[np.ndarray, float]:
        """The scalar nets' input gains ``r`` (n,) and energy scale ``E_b`` [J]."""
        energies = self.joint_energies()
        peak = float(np.max(energies))
        gains = (energies / peak) ** self.balance
        return gains, self.energy * (peak / self.energy) ** self.balance

    @classmethod
    def from_data(
        cls, q: np.ndarray, v: np.ndarray, tau: np.ndarray, *, balance: float = 0.0
    ) -> LagrangianScaling:
        """Fit the scalers on training arrays (N, n) and derive the energy scale."""
        position = MinMaxScaler().fit(np.asarray(q, float))
        torque = MinMaxScaler().fit(np.asarray(tau, float))
        return cls(
            position,
            MinMaxScaler().fit(np.asarray(v, float)),
            torque,
            energy_scale(position.scale(), torque.scale()),
            balance,
        )

    @classmethod
    def from_dataset(
        cls, dataset: Dataset, *, balance: float = 0.0, torque: MinMaxScaler | None = None
    ) -> LagrangianScaling:
        """Reuse the dataset's scalers (fitted on its training part): q and v columns, target.

        ``torque``: the range of what the network learns where that is not the target (a
        residual on a physics prior); None: the target's.
        """
        inputs = dataset.input_scaler
        if inputs.low_ is None or inputs.high_ is None:
            raise DatasetError('the dataset input scaler is not fitted')
        n = len(dataset.joints)
        position = MinMaxScaler(inputs.low_[:n].copy(), inputs.high_[:n].copy())
        velocity = MinMaxScaler(inputs.low_[n : 2 * n].copy(), inputs.high_[n : 2 * n].copy())
        if torque is None:
            torque = MinMaxScaler.from_dict(dataset.target_scaler.to_dict())
        energy = energy_scale(position.scale(), torque.scale())
        return cls(position, velocity, torque, energy, balance)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready state."""
        return {
            'position': self.position.to_dict(),
            'velocity': self.velocity.to_dict(),
            'torque': self.torque.to_dict(),
            'energy_scale_j': self.energy,
            'energy_balance': self.balance,
            'balance_inertia': self.balance_inertia,
        }

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> LagrangianScaling:
        """Rebuild from ``to_dict`` output.

        A model saved before a setting existed is read as it was fitted: no balance is 0, no
        ``balance_inertia`` is False.
        """
        return cls(
            MinMaxScaler.from_dict(data['position']),
            MinMaxScaler.from_dict(data['velocity']),
            MinMaxScaler.from_dict(data['torque']),
            float(data['energy_scale_j']),
            float(data.get('energy_balance', 0.0)),
            bool(data.get('balance_inertia', False)),
        )


class LagrangianNetwork(nn.Module):
    """Base of the torque networks: maps SI states to torque through a scaled Lagrangian.

    The scaling is kept as non-persistent buffers: they move with ``.to()`` but are not
    weights (they are saved as fitted metadata). ``lagrangian_q_half``, ``lagrangian_v_half``
    and ``lagrangian_energy`` are the balanced maps of the scalar nets (``h / r`` and ``E_b``).
    """

    q_centre: torch.Tensor
    q_half: torch.Tensor
    v_centre: torch.Tensor
    v_half: torch.Tensor
    tau_half: torch.Tensor
    energy: torch.Tensor
    lagrangian_q_half: torch.Tensor
    lagrangian_v_half: torch.Tensor
    lagrangian_energy: torch.Tensor

    def __init__(self, scaling: LagrangianScaling) -> None:
        super().__init__()
        self.scaling = scaling
        self.n_dof = scaling.n_dof

        def centre(scaler: MinMaxScaler) -> np.ndarray:
            assert scaler.low_ is not None
            assert scaler.high_ is not None
            out: np.ndarray = 0.5 * (scaler.low_ + scaler.high_)
            return out

        buffers = {
            'q_centre': centre(scaling.position),
            'q_half': scaling.position.scale(),
            'v_centre': centre(scaling.velocity),
            'v_half': scaling.velocity.scale(),
            'tau_half': scaling.torque.scale(),
            'energy': np.asarray(scaling.energy),
        }
        gains, balanced_energy = scaling.balanced()
        buffers['lagrangian_q_half'] = buffers['q_half'] / gains
        buffers['lagrangian_v_half'] = buffers['v_half'] / gains
        buffers['lagrangian_energy'] = np.asarray(balanced_energy)
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
        names = (
            *('q_centre', 'q_half', 'v_centre', 'v_half', 'tau_half', 'energy'),
            *('lagrangian_q_half', 'lagrangian_v_half', 'lagrangian_energy'),
        )
        return {name: float64_array(getattr(self, name)) for name in names}

    @abstractmethod
    def components(
        self, q: torch.Tensor, v: torch.Tensor, a: torch.Tensor
    ) -> dict[str, torch.Tensor]:
        """The torque split into named parts (B, n) [N*m] that sum to forward()."""
