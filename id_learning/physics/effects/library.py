"""The library's thirteen effects, each one object with its parameters, label and columns.

Torques are joint side [N*m]; parameters are in the units each names. The friction laws come
from ``physics.friction`` (written once), the balancer's basis from ``physics.balancer``.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import numpy as np

import id_learning.physics.friction as laws
from id_learning.physics.balancer import BALANCER_TERMS, balancer_basis
from id_learning.physics.base_parameters import base_parameters
from id_learning.physics.effects.base import (
    Effect,
    FittedTerm,
    JointColumns,
    JointEffect,
    Parameter,
    entry,
)
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

    def describe(self, fit: FittedTerm, model: NominalModel) -> list[dict[str, Any]]:
        exponent = float(fit.settings.get('exponent', 1.0))
        if exponent == 1.0:
            return super().describe(fit, model)
        theta, lo, hi = fit.theta, fit.low, fit.high
        power = len(theta) - 1  # after the linear part, if any
        linear = [entry('coefficient', theta[0], lo[0], hi[0], 'N*m*s/rad')] if power else []
        return [
            *linear,
            entry('power_coefficient', theta[power], lo[power], hi[power],
                  f'N*m*(s/rad)^{exponent:g}'),
            entry('exponent', exponent, exponent, exponent, '1'),
        ]  # fmt: skip


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

    def describe(self, fit: FittedTerm, model: NominalModel) -> list[dict[str, Any]]:
        exact = [fit.settings['velocity']] * 3
        v, v_low, v_high = (fit.refined or {}).get('velocity', exact)
        return [
            entry('level', fit.theta[0], fit.low[0], fit.high[0], 'N*m'),
            entry('velocity', v, v_low, v_high, 'rad/s'),
        ]


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

    def describe(self, fit: FittedTerm, model: NominalModel) -> list[dict[str, Any]]:
        """On joint-torque labels the axis inertia seen link side; on motor labels the rotor's."""
        j = fit.joint
        if j is None:
            return super().describe(fit, model)
        theta, lo, hi = fit.theta[0], fit.low[0], fit.high[0]
        drives = model.robot.drives
        if model.target != 'motor':
            n2 = float(drives.gear_ratio[j]) ** 2
            return [entry('axis_inertia_change_link_side', n2 * theta, n2 * lo, n2 * hi, 'kg*m^2')]
        nominal = drives.rotor_inertia[j]
        out = [entry('rotor_inertia_motor_side', nominal + theta, nominal + lo, nominal + hi,
                     'kg*m^2')]  # fmt: skip
        if nominal > 0:
            out.append(
                entry('scale', 1 + theta / nominal, 1 + lo / nominal, 1 + hi / nominal, '1')
            )
        return out


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

    def describe(self, fit: FittedTerm, model: NominalModel) -> list[dict[str, Any]]:
        theta, lo, hi = fit.theta, fit.low, fit.high
        if 'ratio' in fit.settings:
            ratio, phase = fit.settings['ratio'], fit.settings['phase_rad']
            return [
                entry('arm_ratio', ratio, ratio, ratio, '1'),
                entry('phase', phase, phase, phase, 'rad'),
                *[entry(f'f{k}', theta[k], lo[k], hi[k], 'N*m') for k in range(len(theta))],
            ]
        unit = {1: 'N*m/rad'}
        return [
            entry(f'c{k}', theta[k - 1], lo[k - 1], hi[k - 1], unit.get(k, f'N*m/rad^{k}'))
            for k in range(1, len(theta) + 1)
        ]


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

    def describe(self, fit: FittedTerm, model: NominalModel) -> list[dict[str, Any]]:
        theta, half = fit.theta, fit.half_width
        mass = float(theta[0])
        out = [entry('mass', mass, fit.low[0], fit.high[0], 'kg')]
        if mass > 0:
            for axis, k in zip('xyz', range(1, 4), strict=True):
                com = theta[k] / mass
                spread = abs(com) * math.hypot(half[k] / max(abs(theta[k]), 1e-12), half[0] / mass)
                out.append(entry(f'com_{axis}', com, com - spread, com + spread, 'm'))
        for k, axes in enumerate(('xx', 'xy', 'yy', 'xz', 'yz', 'zz'), start=4):
            if k < len(theta):  # rotational inertia about the centre of mass, frame axes
                out.append(entry(f'inertia_{axes}', theta[k], fit.low[k], fit.high[k], 'kg*m^2'))
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

    def describe(self, fit: FittedTerm, model: NominalModel) -> list[dict[str, Any]]:
        """The torque constant's scale s: tau_u from currents = tau_true / s = (1 + c) tau."""

        def scale(c: float) -> float:
            return 1.0 / (1.0 + c) if c > -1 else math.inf

        return [entry('scale', scale(fit.theta[0]), scale(fit.high[0]), scale(fit.low[0]), '1')]


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

    def describe(self, fit: FittedTerm, model: NominalModel) -> list[dict[str, Any]]:
        amplitude = float(np.hypot(fit.theta[0], fit.theta[1]))
        spread = float(np.hypot(fit.half_width[0], fit.half_width[1]))
        phase = math.atan2(fit.theta[1], fit.theta[0])
        return [
            entry('amplitude', amplitude, max(amplitude - spread, 0.0), amplitude + spread, 'N*m'),
            # The phase's interval means nothing near zero amplitude: the whole circle.
            entry('phase', phase, -math.pi, math.pi, 'rad'),
        ]


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

    def describe(self, fit: FittedTerm, model: NominalModel) -> list[dict[str, Any]]:
        """The base parameters whose interval excludes the URDF's value, and how many there are.

        A change c along the identifiable directions D moves the link parameters by D c and the
        base parameters (``physics.base_parameters``) by E D c; each is named after the
        parameter it stands for, with what it groups.
        """
        directions = np.asarray(fit.settings['base_directions'])
        base = base_parameters(model.dynamics, model.robot.limits)
        mapping = base.matrix @ directions
        urdf = base.matrix @ model.dynamics.inertial_parameters()
        change = mapping @ fit.theta
        covariance = fit.interval_covariance
        if covariance is None:
            half = np.zeros_like(change)
        else:
            half = np.sqrt(
                np.clip(np.einsum('ik,kl,il->i', mapping, covariance, mapping), 0, None)
            )
        changed = np.flatnonzero(np.abs(change) > half)
        out: list[dict[str, Any]] = [{
            'name': 'changed_base_parameters',
            'value': int(changed.size),
            'ci': None,
            'unit': f'count of {base.count} (interval excludes the URDF value)',
        }]  # fmt: skip
        for i in changed:
            value = urdf[i] + change[i]
            out.append(
                entry(base.names[i], value, value - half[i], value + half[i], base.units[i])
            )
            out[-1]['urdf'] = float(urdf[i])
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
