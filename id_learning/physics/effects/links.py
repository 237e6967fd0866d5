"""The link-side effects: what changes the torque the links put on the joints.

A balancer (gravity spring), a payload, an encoder offset and errors of the links' inertial
parameters; load-dependent friction grows with what they add (``Effect.link_side``).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import numpy as np

from id_learning.physics.balancer import (
    BALANCER_PHASES,
    BALANCER_RATIOS,
    BALANCER_TERMS,
    balancer_basis,
)
from id_learning.physics.base_parameters import CadPrior, base_parameters
from id_learning.physics.effects.base import (
    Effect,
    FittedTerm,
    JointColumns,
    JointEffect,
    Parameter,
    SettingAxis,
    entry,
)
from id_learning.physics.effects.judgement import CandidateGrid, PlausibilityFacts, Trial, Verdict
from id_learning.physics.inertial import inertial_base_directions
from id_learning.physics.nominal import NominalModel, NominalQuantities
from id_learning.physics.rigid_body import N_INERTIAL_PARAMETERS

__all__ = [
    'GRAVITY_SPRING',
    'INERTIAL_PARAMETER_ERROR',
    'JOINT_OFFSET',
    'PAYLOAD_COM_LIMIT_M',
    'PAYLOAD_MASS',
]

#: Farthest a payload's centre of mass may lie from its frame [m]: a tool or a spindle, not a
#: lever arm.
PAYLOAD_COM_LIMIT_M = 1.0
#: The largest encoder zero error plausible at all [rad]: mastering marks are read to a fraction
#: of a degree, and an error of ten degrees is seen on the arm by eye.
JOINT_OFFSET_MAX_RAD = 0.15


class GravitySpring(JointEffect):
    """What holds a link against gravity besides the motor, in one of its forms.

    - balancer (settings ``ratio``, ``phase_rad``): a spring or gas spring between the link
      and its predecessor (``physics.balancer``), three force coefficients;
    - ``form: counterweight``: a mass on the link's far side, a cos q + b sin q (any phase);
    - ``form: torsion``: a torsion spring about the axis, -k (q - q0): a slope and a constant
      about ``reference_rad`` (the middle of the joint's range), so its neutral is linear too.

    The forms are exclusive variants: held-out evidence picks one per joint. Terms written
    before the forms hold a polynomial in (q - reference_rad) of their ``degree``.
    """

    name = 'gravity_spring'
    parameters = (Parameter('f0', 'N*m'), Parameter('f1', 'N*m'), Parameter('f2', 'N*m'))
    claims_hardware = True
    link_side = True
    exclusive_variants = True

    def label_parts(self, settings: Mapping[str, Any]) -> list[str]:
        form = settings.get('form')
        if form == 'counterweight':
            return ['counterweight']
        if form == 'torsion':
            return ['torsion']
        if 'ratio' not in settings:
            return []
        return [f'r={settings["ratio"]:.3g}, phi={settings["phase_rad"]:.3g}']

    def joint_columns(
        self, quantities: NominalQuantities, joint: Any, settings: Mapping[str, Any],
        model: NominalModel,
    ) -> JointColumns:  # fmt: skip
        q = quantities.q[:, joint]
        form = settings.get('form')
        if form == 'counterweight':
            return (np.cos(q), np.sin(q))
        if form == 'torsion':
            return (q - settings['reference_rad'], np.ones_like(q))
        if 'ratio' in settings:
            basis = balancer_basis(q, settings['ratio'], settings['phase_rad'])
            return tuple(basis[..., k] for k in range(BALANCER_TERMS))
        dq = q - settings['reference_rad']
        return tuple(dq**k for k in range(1, int(settings['degree']) + 1))

    def tuned_settings(self, settings: Mapping[str, Any]) -> tuple[SettingAxis, ...]:
        """A balancer's geometry: arm ratio and phase, tuned together.

        An encoder zero error shifts the phase by milliradians. The ratio stays in the grid's
        range: towards 0 the three columns merge into sin and sin 2 of the angle, an ill-posed
        pair that fits the training part's noise, not a balancer. A counterweight, a torsion
        spring (linear in their coefficients) and terms of the polynomial form have nothing to
        tune.
        """
        if 'ratio' not in settings or 'form' in settings:
            return ()
        low, high = min(BALANCER_RATIOS), max(BALANCER_RATIOS)
        return (
            SettingAxis('ratio', BALANCER_RATIOS, low, high, 0.05),
            SettingAxis('phase_rad', BALANCER_PHASES, -math.inf, math.inf, 0.05),
        )

    def describe(self, fit: FittedTerm, model: NominalModel) -> list[dict[str, Any]]:
        theta, lo, hi = fit.theta, fit.low, fit.high
        form = fit.settings.get('form')
        if form == 'counterweight':
            return _counterweight(fit, model)
        if form == 'torsion':
            return _torsion(fit)
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

    def plausibility(self, trial: Trial, model: NominalModel, facts: PlausibilityFacts) -> Verdict:
        """Mounted to carry the arm's weight, and no stronger than 1.5 times gravity there.

        It falls where gravity's torque rises, or it takes load off on average (a balancer on
        joint 3 turns with q3, gravity there with q2 + q3: their shapes may rise together while
        the balancer's mean still opposes gravity's). Both are linear in theta: refused only
        where both add to gravity beyond the margin.
        """
        j = trial.joint
        assert j is not None
        x = trial.columns[:, j, :]
        theta, covariance, margin = trial.theta, trial.covariance, trial.margin
        spring, gravity = x @ theta, facts.gravity[:, j]
        if np.std(spring) == 0 or np.std(gravity) == 0:
            return False, 'no gravity torque to balance'
        about_mean, about_zero = (g @ x / len(x) for g in (gravity - gravity.mean(), gravity))
        if all(c @ theta - margin * math.sqrt(max(c @ covariance @ c, 0.0)) > 0
               for c in (about_mean, about_zero)):  # fmt: skip
            shape = about_mean @ theta / (np.std(spring) * np.std(gravity))
            mean = about_zero @ theta / math.sqrt(np.mean(spring**2) * np.mean(gravity**2))
            return False, (
                f'it would add to gravity (correlation {shape:+.2f}, {mean:+.2f} about zero), '
                'not balance'
            )
        if np.sqrt(np.mean(spring**2)) > 1.5 * np.sqrt(np.mean(gravity**2)):
            return False, 'it would exceed 1.5 times the gravity torque it balances'
        return True, ''

    def candidates(
        self, model: NominalModel, grid: CandidateGrid
    ) -> list[tuple[int | None, dict[str, Any]]]:
        """Each form on each joint that may carry one.

        A balancer of a middling geometry (refined when selected), a counterweight, a torsion
        spring about the middle of the joint's range.
        """
        limits = model.robot.limits
        out: list[tuple[int | None, dict[str, Any]]] = []
        for j in grid.spring_joints:
            low = max(float(limits.position_lower[j]), -math.pi)
            middle = round(0.5 * (low + min(float(limits.position_upper[j]), math.pi)), 3)
            out += [
                (j, {'ratio': 0.5, 'phase_rad': 0.0}),
                (j, {'form': 'counterweight'}),
                (j, {'form': 'torsion', 'reference_rad': middle}),
            ]
        return out


class PayloadMass(Effect):
    """A payload at the payload frame: its mass and first moments (and inertia if asked)."""

    fit_sets_settings = True
    name = 'payload_mass'
    parameters = (
        Parameter('mass', 'kg'),
        Parameter('first_moment_x', 'kg*m'),
        Parameter('first_moment_y', 'kg*m'),
        Parameter('first_moment_z', 'kg*m'),
    )
    special_case_of = 'inertial_parameter_error'
    stands_in_for_hardware = True
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

    def plausibility(self, trial: Trial, model: NominalModel, facts: PlausibilityFacts) -> Verdict:
        """A positive mass up to the robot's moving mass, its centre near the frame."""
        mass, spread = float(trial.theta[0]), trial.margin * float(trial.sd[0])
        if not (mass + spread > 0.0 and mass - spread <= facts.moving_mass_kg):
            return False, (
                f'mass {mass:.3g} kg outside (0, {facts.moving_mass_kg:.3g}] kg (moving mass)'
            )
        if mass == 0.0:
            return True, ''  # no mass to place: no centre to judge
        com = np.asarray(trial.theta[1:4]) / mass
        if np.linalg.norm(com) > PAYLOAD_COM_LIMIT_M:
            return False, (
                f'centre of mass {np.linalg.norm(com):.2f} m from the frame '
                f'(> {PAYLOAD_COM_LIMIT_M:g} m)'
            )
        return True, ''

    def candidates(
        self, model: NominalModel, grid: CandidateGrid
    ) -> list[tuple[int | None, dict[str, Any]]]:
        """One at the robot's payload frame, its centre of mass guessed there (refined)."""
        return [(None, {'frame': model.robot.payload_frame, 'com_guess_m': [0.0, 0.0, 0.0]})]

    def settings_from_fit(
        self, theta: np.ndarray, settings: Mapping[str, Any]
    ) -> dict[str, Any] | None:
        """The centre of mass its first moments give; none for a payload of no mass.

        Refitted until it settles. A weakly determined mass runs away: a centre of mass further
        out gives the mass column more inertia, the fit a smaller mass, the next centre further
        out. Beyond ``PAYLOAD_COM_LIMIT_M`` the guess stays where it was.
        """
        if theta[0] <= 0:
            return None
        com = (np.asarray(theta[1:4]) / theta[0]).tolist()
        settled = np.allclose(com, settings['com_guess_m'], atol=1e-4)
        if settled or np.linalg.norm(com) > PAYLOAD_COM_LIMIT_M:
            return dict(settings)
        return {**settings, 'com_guess_m': com}

    def richer_form(self, settings: Mapping[str, Any]) -> tuple[dict[str, Any], int] | None:
        """A body with its own rotational inertia (a spindle, a gripper): six more columns."""
        if settings.get('inertia'):
            return None
        return {**settings, 'inertia': True}, 6


class JointOffset(Effect):
    """An encoder offset: the links sit at q + offset, d tau / d q times it."""

    name = 'joint_offset'
    parameters = (Parameter('offset', 'rad'),)
    stands_in_for_hardware = True
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

    def plausible_bound(self, joint: int | None, model: NominalModel) -> float | None:
        """The largest encoder zero error plausible on any joint [rad]."""
        del joint, model
        return JOINT_OFFSET_MAX_RAD

    def plausibility(self, trial: Trial, model: NominalModel, facts: PlausibilityFacts) -> Verdict:
        """Within what the data and the URDF allow (``offset_range``)."""
        assert trial.joint is not None
        low, high = offset_range(trial.joint, model, facts.positions)
        return trial.first_within(low, high, 'rad')


def offset_range(joint: int, model: NominalModel, positions: np.ndarray) -> tuple[float, float]:
    """The encoder offsets [rad] that keep every measured angle of ``joint`` inside its limits.

    The links sit at q + offset: an offset that would put them beyond the URDF's limits where
    the recording went is no offset. Bounded by ``JOINT_OFFSET_MAX_RAD`` either way, and never
    excluding zero (a recording that grazes a limit does not condemn the URDF's zero).
    """
    limits = model.robot.limits
    room_low = float(limits.position_lower[joint] - positions[0, joint])
    room_high = float(limits.position_upper[joint] - positions[1, joint])
    low = min(0.0, max(-JOINT_OFFSET_MAX_RAD, room_low))
    high = max(0.0, min(JOINT_OFFSET_MAX_RAD, room_high))
    return low, high


class InertialParameterError(Effect):
    """The links' inertial parameters off their CAD values, along the base directions given."""

    datasheet_value = True
    name = 'inertial_parameter_error'
    parameters = (Parameter('base_parameter', 'SI'),)
    stands_in_for_hardware = True
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

    def prior_precision(
        self, joint: int | None, settings: Mapping[str, Any], model: NominalModel, *,
        as_datasheet: bool,
    ) -> np.ndarray | None:  # fmt: skip
        """CAD's: a change d theta ~ N(0, diag(std^2)) has base coordinates pinv(D) d theta."""
        del joint, as_datasheet
        std = CadPrior().std(model.dynamics.inertial_parameters())
        mapping = np.linalg.pinv(np.asarray(settings['base_directions']))
        covariance = (mapping * std**2) @ mapping.T
        out: np.ndarray = np.linalg.inv(covariance)
        return out

    def tolerance_text(self) -> str:
        return 'link parameters the CAD prior'

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

    def plausibility(self, trial: Trial, model: NominalModel, facts: PlausibilityFacts) -> Verdict:
        """CAD-derived link data are off by tens of per cent at most, not by the whole link.

        Bounds on the change of each body's parameters: mass 15 % + 0.5 kg; first moment 10 %
        + 3 cm times the mass; inertia about the joint frame 20 % (Frobenius norm) + the mass
        times (5 cm)^2; each beyond the margin. The data fix only the identifiable
        combinations, so the change judged is the most plausible one that produces the same
        torques: the fitted change plus the null-space shift that minimises its size relative
        to these bounds.
        """
        directions = np.asarray(trial.settings['base_directions'])
        null = np.asarray(trial.settings.get('null_directions', np.zeros((len(directions), 0))))
        bounds = np.concatenate([_body_bounds(nominal) for nominal in facts.body_parameters])
        weight = 1.0 / bounds
        mapping = directions
        if null.shape[1]:
            # min_z |W (D theta + N z)|: project D theta off the weighted null space.
            weighted_null = weight[:, None] * null
            shift, *_ = np.linalg.lstsq(weighted_null, -(weight[:, None] * directions), rcond=None)
            mapping = directions + null @ shift
        change_all = mapping @ np.asarray(trial.theta)
        covariance_all = mapping @ trial.covariance @ mapping.T
        for body, nominal in enumerate(facts.body_parameters):
            rows = slice(N_INERTIAL_PARAMETERS * body, N_INERTIAL_PARAMETERS * (body + 1))
            ok, reason = _plausible_body_change(
                change_all[rows], covariance_all[rows, rows], nominal, trial.margin
            )
            if not ok:
                return False, f'body {body + 1}: {reason}'
        return True, ''

    def candidates(
        self, model: NominalModel, grid: CandidateGrid
    ) -> list[tuple[int | None, dict[str, Any]]]:
        """One along the identifiable (base) directions of the links' parameters."""
        base, null = inertial_base_directions(model.dynamics, model.robot.limits)
        return [(None, {'base_directions': base.tolist(), 'null_directions': null.tolist()})]


GRAVITY_SPRING = GravitySpring()
PAYLOAD_MASS = PayloadMass()
JOINT_OFFSET = JointOffset()
INERTIAL_PARAMETER_ERROR = InertialParameterError()


def _torsion(fit: FittedTerm) -> list[dict[str, Any]]:
    """A torsion spring s (q - r) + c as -k (q - q0): stiffness k = -s, neutral q0 = r - c / s.

    The neutral's interval by the delta method on the interval covariance (the coefficients'
    own half widths, uncorrelated, where there is none).
    """
    slope, constant = (float(x) for x in fit.theta)
    out = [entry('stiffness', -slope, -fit.high[0], -fit.low[0], 'N*m/rad')]
    if slope == 0.0:
        return out
    covariance = _interval_covariance(fit)
    neutral = float(fit.settings['reference_rad']) - constant / slope
    gradient = np.array([constant / slope**2, -1.0 / slope])
    half = math.sqrt(max(float(gradient @ covariance @ gradient), 0.0))
    out.append(entry('neutral', neutral, neutral - half, neutral + half, 'rad'))
    return out


def _interval_covariance(fit: FittedTerm) -> np.ndarray:
    """The fit's interval covariance, or its half widths' squares where it has none."""
    if fit.interval_covariance is not None:
        return np.asarray(fit.interval_covariance, dtype=float)
    return np.diag(np.asarray(fit.half_width, dtype=float) ** 2)


def _counterweight(fit: FittedTerm, model: NominalModel) -> list[dict[str, Any]]:
    """A counterweight a cos q + b sin q as -m r g cos(q + phi): moment m r [kg*m], phase.

    Intervals by the delta method on the coefficients' interval covariance (their own half
    widths, uncorrelated, where there is none).
    """
    a, b = (float(x) for x in fit.theta)
    covariance = _interval_covariance(fit)
    g = float(np.linalg.norm(model.dynamics.model.gravity.linear))
    amplitude = math.hypot(a, b)
    out = [
        entry(f'c_{name}', fit.theta[k], fit.low[k], fit.high[k], 'N*m')
        for k, name in enumerate(('cos', 'sin'))
    ]
    if amplitude == 0.0 or g == 0.0:
        return out
    phase = math.atan2(b, -a)
    for name, value, gradient, unit, scale in (
        ('moment', amplitude, np.array([a, b]) / amplitude, 'kg*m', 1.0 / g),
        ('phase', phase, np.array([b, -a]) / amplitude**2, 'rad', 1.0),
    ):
        half = math.sqrt(max(float(gradient @ covariance @ gradient), 0.0))
        low, high = scale * (value - half), scale * (value + half)
        out.append(entry(name, scale * value, low, high, unit))
    return out


def _body_limits(nominal: np.ndarray) -> tuple[float, float, float]:
    """Plausible change of a body's mass [kg], first moment [kg*m], inertia [kg*m^2]."""
    mass = float(nominal[0])
    return (
        0.15 * mass + 0.5,
        0.1 * float(np.linalg.norm(nominal[1:4])) + 0.03 * mass,
        0.2 * float(np.linalg.norm(nominal[4:])) + mass * 0.05**2,
    )


def _body_bounds(nominal: np.ndarray) -> np.ndarray:
    """The limits spread over the 10 parameters (vector parts share their norm's limit)."""
    mass, first, inertia = _body_limits(nominal)
    return np.array([mass, *[first / math.sqrt(3)] * 3, *[inertia / math.sqrt(6)] * 6])


def _plausible_body_change(
    change: np.ndarray, change_covariance: np.ndarray, nominal: np.ndarray, margin: float
) -> Verdict:
    mass_limit, first_limit, inertia_limit = _body_limits(nominal)
    checks = (
        ('mass', slice(0, 1), mass_limit, 'kg'),
        ('first moment', slice(1, 4), first_limit, 'kg*m'),
        ('inertia', slice(4, 10), inertia_limit, 'kg*m^2'),
    )
    for what, part, bound, unit in checks:
        vector = change[part]
        size = float(np.linalg.norm(vector))
        # Standard error of the size along the change's own direction.
        direction = vector / size if size > 0 else vector
        spread = float(np.sqrt(max(direction @ change_covariance[part, part] @ direction, 0.0)))
        if size - margin * spread > bound:
            return False, (
                f'the {what} of the link would change by {size:.3g} {unit}, more than a '
                f'plausible data error ({bound:.3g} {unit})'
            )
    return True, ''
