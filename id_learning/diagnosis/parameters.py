"""A fitted effect's physical parameters with intervals, in the twin's terms where one exists."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from id_learning.physics.base_parameters import base_parameters
from id_learning.physics.nominal import NominalModel
from id_learning.physics.terms import PARAMETERS, EffectSpec

__all__ = ['describe_parameters']


def describe_parameters(
    spec: EffectSpec,
    theta: np.ndarray,
    half_width: np.ndarray,
    model: NominalModel,
    interval_covariance: np.ndarray | None = None,
    *,
    settings: dict[str, list[float]] | None = None,
) -> list[dict[str, Any]]:
    """Physical parameters with confidence intervals, in the twin's terms where one exists.

    Args:
        spec: the candidate.
        theta: (k,) fitted column coefficients in physical units.
        half_width: (k,) half widths of their confidence intervals (same units).
        model: the nominal model (datasheet values for scales).
        interval_covariance: (k, k) covariance of theta scaled so that the square roots of its
            diagonal are ``half_width``; needed for parameters that mix coefficients (the
            base parameters of ``inertial_parameter_error``).
        settings: refined settings estimated again beside the fit, name -> [value, low, high]
            (a Stribeck velocity); otherwise the spec's value, as exact.

    Returns:
        One dict per parameter: name, value, ci (low, high), unit.
    """
    robot = model.robot
    j = spec.joint

    def entry(name: str, value: float, low: float, high: float, unit: str) -> dict[str, Any]:
        return {
            'name': name,
            'value': float(value),
            'ci': [float(min(low, high)), float(max(low, high))],
            'unit': unit,
        }

    lo, hi = theta - half_width, theta + half_width
    name = spec.name
    if name == 'inertial_parameter_error':
        return _base_parameter_changes(spec, theta, model, interval_covariance)
    if name == 'rotor_inertia' and j is not None and model.target != 'motor':
        n2 = float(robot.drives.gear_ratio[j]) ** 2
        return [
            entry('axis_inertia_change_link_side', n2 * theta[0], n2 * lo[0], n2 * hi[0], 'kg*m^2')
        ]
    if name == 'rotor_inertia' and j is not None:
        nominal = robot.drives.rotor_inertia[j]
        out = [entry('rotor_inertia_motor_side', nominal + theta[0], nominal + lo[0],
                     nominal + hi[0], 'kg*m^2')]  # fmt: skip
        if nominal > 0:
            out.append(
                entry(
                    'scale',
                    1 + theta[0] / nominal,
                    1 + lo[0] / nominal,
                    1 + hi[0] / nominal,
                    '1',
                )
            )
        return out
    if name == 'torque_constant_scale':
        # tau_u from currents = tau_true / s; the column is the nominal torque, so s = 1 / (1 + c).
        def scale(c: float) -> float:
            return 1.0 / (1.0 + c) if c > -1 else math.inf

        return [entry('scale', scale(theta[0]), scale(hi[0]), scale(lo[0]), '1')]
    if name == 'cogging':
        amplitude = float(np.hypot(theta[0], theta[1]))
        spread = float(np.hypot(half_width[0], half_width[1]))
        return [
            entry('amplitude', amplitude, max(amplitude - spread, 0.0), amplitude + spread, 'N*m'),
            entry(
                'phase', math.atan2(theta[1], theta[0]), -math.pi, math.pi, 'rad'
            ),  # phase interval is not meaningful near zero amplitude
        ]
    if name == 'payload_mass':
        mass = float(theta[0])
        out = [entry('mass', mass, lo[0], hi[0], 'kg')]
        if mass > 0:
            for axis, k in zip('xyz', range(1, 4), strict=True):
                com = theta[k] / mass
                spread = abs(com) * math.hypot(half_width[k] / max(abs(theta[k]), 1e-12),
                                               half_width[0] / mass)  # fmt: skip
                out.append(entry(f'com_{axis}', com, com - spread, com + spread, 'm'))
        for k, axes in enumerate(('xx', 'xy', 'yy', 'xz', 'yz', 'zz'), start=4):
            if k < len(theta):  # rotational inertia about the centre of mass, frame axes
                out.append(entry(f'inertia_{axes}', theta[k], lo[k], hi[k], 'kg*m^2'))
        return out
    if name == 'viscous_friction' and spec.settings.get('exponent', 1.0) != 1.0:
        exponent = float(spec.settings['exponent'])
        power = len(theta) - 1  # after the linear part, if any
        linear = [entry('coefficient', theta[0], lo[0], hi[0], 'N*m*s/rad')] if power else []
        return [
            *linear,
            entry('power_coefficient', theta[power], lo[power], hi[power],
                  f'N*m*(s/rad)^{exponent:g}'),
            entry('exponent', exponent, exponent, exponent, '1'),
        ]  # fmt: skip
    if name == 'stribeck_friction':
        v, v_low, v_high = (settings or {}).get('velocity', [spec.settings['velocity']] * 3)
        return [
            entry('level', theta[0], lo[0], hi[0], 'N*m'),
            entry('velocity', v, v_low, v_high, 'rad/s'),
        ]
    if name == 'gravity_spring':
        if 'ratio' in spec.settings:
            ratio, phase = spec.settings['ratio'], spec.settings['phase_rad']
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
    names = PARAMETERS[name]
    return [entry(names[k][0], theta[k], lo[k], hi[k], names[k][1]) for k in range(len(theta))]


def _base_parameter_changes(
    spec: EffectSpec,
    theta: np.ndarray,
    model: NominalModel,
    interval_covariance: np.ndarray | None,
) -> list[dict[str, Any]]:
    """The base parameters whose interval excludes the URDF's value, and how many there are.

    A change c along the identifiable directions D moves the link parameters by D c and the
    base parameters (``physics.base_parameters``) by E D c; each is named after the parameter
    it stands for, with what it groups.
    """
    directions = np.asarray(spec.settings['base_directions'])
    base = base_parameters(model.dynamics, model.robot.limits)
    mapping = base.matrix @ directions
    urdf = base.matrix @ model.dynamics.inertial_parameters()
    change = mapping @ theta
    if interval_covariance is None:
        half = np.zeros_like(change)
    else:
        half = np.sqrt(
            np.clip(np.einsum('ik,kl,il->i', mapping, interval_covariance, mapping), 0, None)
        )
    changed = np.flatnonzero(np.abs(change) > half)
    out: list[dict[str, Any]] = [
        {
            'name': 'changed_base_parameters',
            'value': int(changed.size),
            'ci': None,
            'unit': f'count of {base.count} (interval excludes the URDF value)',
        }
    ]
    for i in changed:
        value = urdf[i] + change[i]
        out.append(
            {
                'name': base.names[i],
                'value': float(value),
                'ci': [float(value - half[i]), float(value + half[i])],
                'unit': base.units[i],
                'urdf': float(urdf[i]),
            }
        )
    return out
