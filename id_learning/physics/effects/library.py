"""The library's thirteen effects, each one object with its parameters, label and columns.

Torques are joint side [N*m]; parameters are in the units each names. The friction laws come
from ``physics.friction`` (written once), the balancer's basis from ``physics.balancer``.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

import id_learning.physics.friction as laws
from id_learning.physics.balancer import BALANCER_TERMS, balancer_basis
from id_learning.physics.effects.base import Effect, JointColumns, JointEffect, Parameter
from id_learning.physics.nominal import NominalModel, NominalQuantities
from id_learning.physics.rigid_body import N_INERTIAL_PARAMETERS

__all__ = ['LIBRARY']


class ViscousFriction(JointEffect):
    """d v; or a power law sign(v) |v|^delta, after v where the settings say ``linear``."""

    name = 'viscous_friction'
    parameters = (Parameter('coefficient', 'N*m*s/rad'),)

    def label_parts(self, settings: Mapping[str, Any]) -> list[str]:
        if settings.get('exponent', 1.0) == 1.0:
            return []
        linear = 'v + ' if settings.get('linear') else ''
        return [f'{linear}|v|^{settings["exponent"]:g}']

    def joint_columns(
        self, quantities: NominalQuantities, joint: Any, settings: Mapping[str, Any],
        model: NominalModel,
    ) -> JointColumns:  # fmt: skip
        exponent = settings.get('exponent', 1.0)
        return laws.viscous(quantities.v[:, joint], exponent, linear=bool(settings.get('linear')))


class CoulombFriction(JointEffect):
    """F_c tanh(v / v_eps)."""

    name = 'coulomb_friction'
    parameters = (Parameter('level', 'N*m'),)

    def joint_columns(
        self, quantities: NominalQuantities, joint: Any, settings: Mapping[str, Any],
        model: NominalModel,
    ) -> JointColumns:  # fmt: skip
        return (laws.coulomb(quantities.v[:, joint], settings['smoothing_velocity']),)


class StribeckFriction(JointEffect):
    """F_s exp(-(v / v_s)^2) tanh(v / v_eps), one candidate per Stribeck velocity v_s."""

    name = 'stribeck_friction'
    parameters = (Parameter('level', 'N*m'),)

    def label_parts(self, settings: Mapping[str, Any]) -> list[str]:
        return [f'v_s={settings["velocity"]:g}']

    def joint_columns(
        self, quantities: NominalQuantities, joint: Any, settings: Mapping[str, Any],
        model: NominalModel,
    ) -> JointColumns:  # fmt: skip
        v = quantities.v[:, joint]
        return (laws.stribeck(v, settings['velocity'], settings['smoothing_velocity']),)


class LoadDependentFriction(JointEffect):
    """mu |L| tanh(v / v_eps), L the link torque on the joint.

    Its 'model' form grows with the whole model's link torque (nominal plus the link-side
    effects): with a payload or a balancer the URDF's alone is far off. Terms written before
    that form (no 'load' setting) take the URDF's rigid-body torque.
    """

    name = 'load_dependent_friction'
    parameters = (Parameter('coefficient', '1'),)

    def label_parts(self, settings: Mapping[str, Any]) -> list[str]:
        return ['model load'] if self.uses_model_load(settings) else []

    def uses_model_load(self, settings: Mapping[str, Any]) -> bool:
        return settings.get('load') == 'model'

    def joint_columns(
        self, quantities: NominalQuantities, joint: Any, settings: Mapping[str, Any],
        model: NominalModel,
    ) -> JointColumns:  # fmt: skip
        v, load = quantities.v[:, joint], quantities.tau_rigid[:, joint]
        return (laws.load_dependent(v, load, settings['smoothing_velocity']),)


class RotorInertia(JointEffect):
    """A change J of the rotor inertia (motor side): J N^2 a on the joint."""

    name = 'rotor_inertia'
    parameters = (Parameter('rotor_inertia_change_motor_side', 'kg*m^2'),)

    def joint_columns(
        self, quantities: NominalQuantities, joint: Any, settings: Mapping[str, Any],
        model: NominalModel,
    ) -> JointColumns:  # fmt: skip
        return (model.robot.drives.gear_ratio[joint] ** 2 * quantities.a[:, joint],)


class GravitySpring(JointEffect):
    """A balancer's torque (``physics.balancer``) for its geometry in the settings.

    Terms written before the balancer form hold a polynomial in (q - reference_rad) instead.
    """

    name = 'gravity_spring'
    parameters = (Parameter('f0', 'N*m'), Parameter('f1', 'N*m'), Parameter('f2', 'N*m'))
    link_side = True

    def label_parts(self, settings: Mapping[str, Any]) -> list[str]:
        if 'ratio' not in settings:
            return []
        return [f'r={settings["ratio"]:.3g}, phi={settings["phase_rad"]:.3g}']

    def joint_columns(
        self, quantities: NominalQuantities, joint: Any, settings: Mapping[str, Any],
        model: NominalModel,
    ) -> JointColumns:  # fmt: skip
        q = quantities.q[:, joint]
        if 'ratio' in settings:
            basis = balancer_basis(q, settings['ratio'], settings['phase_rad'])
            return tuple(basis[..., k] for k in range(BALANCER_TERMS))
        dq = q - settings['reference_rad']
        return tuple(dq**k for k in range(1, int(settings['degree']) + 1))


class PayloadMass(Effect):
    """A payload at the payload frame: its mass and first moments (and inertia if asked)."""

    name = 'payload_mass'
    parameters = (
        Parameter('mass', 'kg'),
        Parameter('first_moment_x', 'kg*m'),
        Parameter('first_moment_y', 'kg*m'),
        Parameter('first_moment_z', 'kg*m'),
    )
    robot_wide = True
    link_side = True
    needs_regressor = True

    def label_parts(self, settings: Mapping[str, Any]) -> list[str]:
        return [str(settings['frame']), *(['with inertia'] if settings.get('inertia') else [])]

    def columns(
        self, quantities: NominalQuantities, joint: int | None, settings: Mapping[str, Any],
        model: NominalModel,
    ) -> np.ndarray:  # fmt: skip
        if quantities.regressor is None:
            raise ValueError('payload_mass needs quantities evaluated with regressor=True')
        body, mapping = model.payload_map(
            str(settings['frame']), settings['com_guess_m'], bool(settings.get('inertia'))
        )
        rows = slice(N_INERTIAL_PARAMETERS * body, N_INERTIAL_PARAMETERS * (body + 1))
        out: np.ndarray = quantities.regressor[:, :, rows] @ mapping
        return out


class JointOffset(Effect):
    """An encoder offset: the links sit at q + offset, d tau / d q times it."""

    name = 'joint_offset'
    parameters = (Parameter('offset', 'rad'),)
    link_side = True

    def needs_derivatives(self, settings: Mapping[str, Any]) -> bool:
        return True

    def columns(
        self, quantities: NominalQuantities, joint: int | None, settings: Mapping[str, Any],
        model: NominalModel,
    ) -> np.ndarray:  # fmt: skip
        if joint is None:
            raise ValueError('joint_offset needs a joint')
        if quantities.dtau_dq is None:
            raise ValueError('joint_offset needs quantities evaluated with derivatives=True')
        return quantities.dtau_dq[:, :, joint : joint + 1].copy()


class TorqueConstantScale(JointEffect):
    """The label's gain off on a joint: the torque it reads is (1 + c) times the delivered."""

    name = 'torque_constant_scale'
    parameters = (Parameter('label_gain_change', '1'),)
    whole_model_key = 'of'
    scales_the_label = True

    def label_parts(self, settings: Mapping[str, Any]) -> list[str]:
        return ['whole model'] if self.is_whole_model(settings) else []

    def joint_columns(
        self, quantities: NominalQuantities, joint: Any, settings: Mapping[str, Any],
        model: NominalModel,
    ) -> JointColumns:  # fmt: skip
        return (quantities.tau_nominal[:, joint],)


class SignalDelay(Effect):
    """Currents at t belong to the motion at t - d: tau(t - d) ~ tau(t) - d dtau/dt.

    The diagnosis' 'whole model' form adds the other effects' rate along the recording
    (``ResidualProblem``); on single states only the nominal torque's rate is known. A fit
    takes the column about its last estimate (``about``), so that a delay of several IPO
    cycles is fitted on the torque it actually shifts; the coefficient is the delay either way.
    """

    name = 'signal_delay'
    parameters = (Parameter('delay', 's'),)
    robot_wide = True
    whole_model_key = 'rate_of'
    delays_the_label = True

    def label_parts(self, settings: Mapping[str, Any]) -> list[str]:
        return ['whole model'] if self.is_whole_model(settings) else []

    def needs_derivatives(self, settings: Mapping[str, Any]) -> bool:
        # A delay of the whole model's form is evaluated at the state it holds back.
        return not self.is_whole_model(settings)

    def linearised_about(self, settings: Mapping[str, Any]) -> float:
        return float(settings.get('about', 0.0))

    def columns(
        self, quantities: NominalQuantities, joint: int | None, settings: Mapping[str, Any],
        model: NominalModel,
    ) -> np.ndarray:  # fmt: skip
        out: np.ndarray = -model.nominal_rate(quantities)[:, :, None]
        return out


class Cogging(JointEffect):
    """Torque ripple periodic in the motor angle: sin and cos of p N q."""

    name = 'cogging'
    parameters = (Parameter('sine', 'N*m'), Parameter('cosine', 'N*m'))

    def label_parts(self, settings: Mapping[str, Any]) -> list[str]:
        return [f'p={settings["periods_per_motor_turn"]}']

    def joint_columns(
        self, quantities: NominalQuantities, joint: Any, settings: Mapping[str, Any],
        model: NominalModel,
    ) -> JointColumns:  # fmt: skip
        gear = model.robot.drives.gear_ratio[joint]
        phase = settings['periods_per_motor_turn'] * gear * quantities.q[:, joint]
        return np.sin(phase), np.cos(phase)


class TorqueOffset(JointEffect):
    """A constant torque on the joint (a current sensor's offset)."""

    name = 'torque_offset'
    parameters = (Parameter('offset', 'N*m'),)
    label_offset = True

    def joint_columns(
        self, quantities: NominalQuantities, joint: Any, settings: Mapping[str, Any],
        model: NominalModel,
    ) -> JointColumns:  # fmt: skip
        return (np.ones_like(quantities.q[:, joint]),)


class InertialParameterError(Effect):
    """The links' inertial parameters off their CAD values, along the base directions given."""

    name = 'inertial_parameter_error'
    parameters = (Parameter('base_parameter', 'SI'),)
    robot_wide = True
    link_side = True
    needs_regressor = True

    def columns(
        self, quantities: NominalQuantities, joint: int | None, settings: Mapping[str, Any],
        model: NominalModel,
    ) -> np.ndarray:  # fmt: skip
        if quantities.regressor is None:
            raise ValueError('inertial_parameter_error needs quantities with regressor=True')
        out: np.ndarray = quantities.regressor @ np.asarray(settings['base_directions'])
        return out


#: Every effect, in the library's stable order.
LIBRARY: tuple[Effect, ...] = (
    ViscousFriction(),
    CoulombFriction(),
    StribeckFriction(),
    LoadDependentFriction(),
    RotorInertia(),
    GravitySpring(),
    PayloadMass(),
    JointOffset(),
    TorqueConstantScale(),
    SignalDelay(),
    Cogging(),
    TorqueOffset(),
    InertialParameterError(),
)
