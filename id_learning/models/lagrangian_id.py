"""Physics-initialised Lagrangian networks: DeLaN and LNN+MLP on the identified physics.

Both kinds predict ::

    tau = rnea_id(q, v, a) + (1 + g) * tau_res(q, v, a)

with ``rnea_id`` the physics identified on the training part (``models.identified_prior``; its
rigid body M_theta(q), C, g(q), rotor inertias, label gains g, friction, balancer, offsets and
delay, shared with the ``rnea_id`` kind) and ``tau_res`` a Lagrangian network of the study's
structure trained on what the physics leaves:

- ``delan_id``: DeLaN's ``L_res(q)`` and ``V_res(q)`` (``models.delan_residual``): the link-side
  mass matrix is ``M(q) = M_id(q) + L_res L_res^T``, ``M_id = M_theta + diag(N^2 r)``, symmetric
  positive definite by construction, and the potential ``V_id + V_res``;
- ``lnn_mlp_id``: the LNN's ``L_res(q, v)`` plus the dissipation MLP ``h(q, v)``.

The residual sits inside the label gain, like the identified rigid body: ``(1 + g)`` turns a
link-side torque into the label's (the torque constant's error, zero for joint-torque labels),
so ``M(q)`` is the arm's physical mass matrix. Each network starts at (near) zero, the model at
``rnea_id``: DeLaN's factor at ``FACTOR_GAIN`` of its usual scale and its potential at zero, the
LNN's Lagrangian and the dissipation MLP at zero (zeroed output layers). Its scaling
(``LagrangianScaling``) takes the torque range of the residual, not the labels'; the loss is the
study's normalised torque error of the whole model, as for the other kinds. The study-faithful
``delan``, ``lnn`` and ``lnn_mlp`` stay as they are (``models.lagrangian``).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, ClassVar, Literal

import numpy as np
import torch

from id_learning.dataset.preprocess import MinMaxScaler
from id_learning.models import lagrangian
from id_learning.models.base import SamplePredictor, TorqueComponents
from id_learning.models.data import TrainingData
from id_learning.models.delan_residual import ResidualDelanNetwork, zero_output
from id_learning.models.identified_prior import IdentificationSettings, IdentifiedPrior
from id_learning.models.lagrangian_base import LagrangianNetwork, LagrangianScaling
from id_learning.models.lnn import LnnMlpNetwork
from id_learning.models.torch_utils import to_numpy, to_tensor

__all__ = ['DelanIdConfig', 'DelanIdModel', 'LnnMlpIdConfig', 'LnnMlpIdModel']


@dataclass(frozen=True)
class DelanIdConfig(IdentificationSettings, lagrangian.LagrangianConfig):
    """delan_id settings: DeLaN's network and training, and the identification's.

    The factor has no positive diagonal to set (``models.delan_residual``), so DeLaN's
    ``diagonal_epsilon`` and ``diagonal_shift`` are no settings here.

    Attributes:
        energy_balance: 1, as DeLaN's (``DelanConfig``).
        weight_decay: 1e-4, as DeLaN's; it draws the residual towards zero, the model towards
            the identified physics.
        patience: 60 epochs, as DeLaN's.
        max_epochs: 600, as DeLaN's.
        max_seconds: the budget of the identification (where the run has not identified yet)
            and then of the network's fit [s], None for none.
    """

    kind: Literal['delan_id'] = 'delan_id'
    energy_balance: float = 1.0
    weight_decay: float = 1e-4
    patience: int = 60
    max_epochs: int = 600

    def __post_init__(self) -> None:
        """Check the network's and the identification's settings, naming the key."""
        super().__post_init__()
        self.check_identification()


@dataclass(frozen=True)
class LnnMlpIdConfig(IdentificationSettings, lagrangian.LnnMlpConfig):
    """lnn_mlp_id settings: LNN+MLP's network and training, and the identification's."""

    kind: Literal['lnn_mlp_id'] = 'lnn_mlp_id'

    def __post_init__(self) -> None:
        """Check the network's and the identification's settings, naming the key."""
        super().__post_init__()
        self.check_identification()


class _IdentifiedLagrangian(IdentifiedPrior, lagrangian.LagrangianModel):
    """tau = rnea_id + (1 + g) * the Lagrangian network's torque (module docstring).

    Components: the identified physics' parts plus the network's of the same name, scaled by
    ``1 + g`` (its inertial, Coriolis and gravity; the LNN+MLP's dissipation as friction).
    """

    def label_scale(self) -> np.ndarray:
        """1 + g (n,): the identified label gain g as a scale, link side to label [-]."""
        return 1.0 + self.identified_physics().gain

    def training_target(
        self, data: TrainingData
    ) -> tuple[np.ndarray, np.ndarray, MinMaxScaler | None]:
        """Identify; the residual (tau - rnea_id) / (1 + g) the network learns, and its range.

        Through the label filter (the default), the physics' torque is filtered like the labels
        before it is subtracted, as ``rnea_id_mlp`` does. The loss scale is the labels' half
        range over 1 + g, so that the loss is the study's normalised error of the whole torque.
        """
        ds = data.dataset
        prior = self.identify(data).torque(ds.q, ds.v, ds.a)
        if ds.is_through_filter:
            prior = ds.filter_like_labels(prior)
        gain = self.label_scale()
        residual = (ds.tau - prior) / gain
        residual_range = MinMaxScaler().fit(residual[data.train_rows])
        return residual, ds.target_scaler.scale() / gain, residual_range

    def residual_torque(self, q: np.ndarray, v: np.ndarray, a: np.ndarray) -> np.ndarray:
        """The network's torque on the label side, (1 + g) * tau_res (B, n) [N*m]."""
        torque: np.ndarray = self.label_scale() * super().predict(q, v, a)
        return torque

    def predict(self, q: np.ndarray, v: np.ndarray, a: np.ndarray) -> np.ndarray:
        """Torque (B, n) [N*m] for q [rad], v [rad/s], a [rad/s^2], each (B, n)."""
        q, v, a = (np.atleast_2d(np.asarray(x, dtype=float)) for x in (q, v, a))
        torque: np.ndarray = self.physics_torque(q, v, a) + self.residual_torque(q, v, a)
        return torque

    def sample_predictor(self) -> SamplePredictor:
        """One sample's torque: the identified physics' path plus the network's, float64 numpy."""
        network, gain = self.network().sample_predictor(), self.label_scale()

        def residual_one(q: np.ndarray, v: np.ndarray, a: np.ndarray) -> np.ndarray:
            tau: np.ndarray = gain * network(q, v, a)
            return tau

        return self.with_physics(residual_one)

    def components(self, q: np.ndarray, v: np.ndarray, a: np.ndarray) -> TorqueComponents:
        """The identified physics' parts plus the network's (class docstring)."""
        q, v, a = (np.atleast_2d(np.asarray(x, dtype=float)) for x in (q, v, a))
        gain = self.label_scale()
        parts = self._evaluate(q, v, a, parts=True)
        return self.with_physics_parts(q, v, a, {k: gain * x for k, x in parts.items()})

    def state(self) -> dict[str, np.ndarray]:
        """The network's weights and the identified values."""
        return self.with_physics_state(super().state())

    def load_state(self, tensors: dict[str, np.ndarray], fitted: dict[str, Any]) -> None:
        """Rebuild the identified physics and the network.

        Raises:
            CheckpointError: the physics, the scaling or the weights do not fit.
        """
        super().load_state(self.load_physics(tensors, fitted), fitted)

    def fitted_metadata(self) -> dict[str, Any]:
        """The network's scaling and training history, the identification's settings and report."""
        return {**super().fitted_metadata(), **self.physics_metadata()}


class DelanIdModel(_IdentifiedLagrangian):
    """DeLaN on the identified physics: M = M_id + L_res L_res^T, V = V_id + V_res."""

    kind: ClassVar[str] = 'delan_id'
    config: DelanIdConfig
    network_class = ResidualDelanNetwork  # starts near zero

    def mass_matrix(self, q: np.ndarray) -> np.ndarray:
        """M(q) = M_id(q) + L_res L_res^T (B, n, n) [kg*m^2], symmetric positive definite.

        The link side: the torque's inertial part is (1 + g) * M(q) a.
        """
        q = np.atleast_2d(np.asarray(q, dtype=float))
        network = self.network()
        assert isinstance(network, ResidualDelanNetwork)
        with torch.inference_mode():
            residual = to_numpy(network.mass_matrix(to_tensor(q)))
        mass: np.ndarray = self.identified_mass_matrix(q) + residual
        return mass


class LnnMlpIdModel(_IdentifiedLagrangian, lagrangian.LnnMlpModel):
    """LNN+MLP on the identified physics: L = L_id + L_res(q, v), friction + h(q, v)."""

    kind: ClassVar[str] = 'lnn_mlp_id'
    config: LnnMlpIdConfig

    def make_network(
        self, scaling: LagrangianScaling, generator: torch.Generator
    ) -> LagrangianNetwork:
        """Build LNN+MLP's networks with their outputs at zero, hidden weights drawn as its."""
        network = super().make_network(scaling, generator)
        assert isinstance(network, LnnMlpNetwork)
        zero_output(network.lnn.lagrangian_net, network.dissipation_net)
        return network

    def mass_matrix(self, q: np.ndarray, v: np.ndarray) -> np.ndarray:
        """M(q, v) = M_id(q) + d2L_res/dv2 (B, n, n) [kg*m^2], link side.

        The LNN's Hessian is not held positive definite (the study's LNN's is not either).
        """
        q, v = (np.atleast_2d(np.asarray(x, dtype=float)) for x in (q, v))
        batch, n = q.shape
        network = self.network()
        assert isinstance(network, LnnMlpNetwork)
        q_rows, v_rows = (to_tensor(np.repeat(x, n, axis=0)) for x in (q, v))
        unit = to_tensor(np.tile(np.eye(n), (batch, 1)))  # row b * n + k: a = e_k
        with torch.inference_mode():
            columns = network.lnn.components(q_rows, v_rows, unit)['inertial']
        residual = to_numpy(columns).reshape(batch, n, n).transpose(0, 2, 1)
        mass: np.ndarray = self.identified_mass_matrix(q) + residual
        return mass
