"""The diagnosis' library of candidate effects, and the rules it judges them by.

Every effect term of the physics layer (``physics.terms``) on every joint where it can act is a
candidate. Each candidate carries the condition under which the excitation can show it at all
(``testability``) and a sign/size rule for a physical value (``plausibility``);
``parameters.describe_parameters`` turns fitted coefficients into physical parameters.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import stats

from id_learning.diagnosis.config import DiagnosisConfig
from id_learning.errors import ConfigError
from id_learning.physics.inertial import inertial_base_directions
from id_learning.physics.nominal import NominalModel, NominalQuantities
from id_learning.physics.rigid_body import N_INERTIAL_PARAMETERS
from id_learning.physics.terms import (
    PARAMETERS,
    EffectSpec,
    gravity_loaded_joints,
)

__all__ = [
    'PAYLOAD_COM_LIMIT_M',
    'SPECIAL_CASES',
    'ExcitationFacts',
    'PlausibilityFacts',
    'build_library',
    'plausibility',
    'spring_joints',
    'testability',
]


#: Farthest a payload's centre of mass may lie from its frame [m]: a tool or a spindle, not a
#: lever arm.
PAYLOAD_COM_LIMIT_M = 1.0

#: How far an encoder zero error may move the payload frame before a cell notices it [m]
#: (every taught point off by as much), and the largest joint offset plausible at all [rad].
MASTERING_TOLERANCE_M = 0.03
JOINT_OFFSET_MAX_RAD = 0.2

#: Effects that are special cases of a more general one: the same physics with fewer columns. A
#: payload is a mass at the flange and a rotor inertia the inertia of a moving part, both errors
#: of the mass distribution that ``inertial_parameter_error`` (every link's base parameters) can
#: also take. The general effect is then no alternative explanation but the same one with more
#: freedom: where the special case explains what the data show, it is named and the general
#: effect is not listed as its alias (parsimony; a kinematic joint offset or a balancer spring,
#: which the link parameters can only mimic, stay aliases).
SPECIAL_CASES = {
    'payload_mass': 'inertial_parameter_error',
    'rotor_inertia': 'inertial_parameter_error',
}


def spring_joints(
    model: NominalModel, quantities: NominalQuantities, config: DiagnosisConfig
) -> list[int]:
    """Joints that may carry a gravity spring (config, or where gravity sweeps a real torque)."""
    joints = model.robot.joints
    if config.gravity_spring_joints is not None:
        unknown = sorted(set(config.gravity_spring_joints) - set(joints))
        if unknown:
            raise ConfigError(
                f'diagnosis.gravity_spring_joints: {unknown} are not joints of {list(joints)}'
            )
        return [joints.index(name) for name in config.gravity_spring_joints]
    return gravity_loaded_joints(model, quantities.q, config.gravity_spring_min_share)


def build_library(
    model: NominalModel, quantities: NominalQuantities, config: DiagnosisConfig
) -> list[EffectSpec]:
    """Every candidate of the enabled effects for this robot, in the effects' stable order."""
    robot = model.robot
    joints = robot.joints
    eps = config.smoothing_velocity
    specs: list[EffectSpec] = []
    springs = spring_joints(model, quantities, config)
    for name in config.effects:
        if name == 'signal_delay':
            specs.append(EffectSpec(name))
        elif name == 'inertial_parameter_error':
            base, null = inertial_base_directions(model.dynamics, model.robot.limits)
            specs.append(
                EffectSpec(
                    name,
                    settings={'base_directions': base.tolist(), 'null_directions': null.tolist()},
                )
            )
        elif name == 'payload_mass':
            specs.append(
                EffectSpec(
                    name, settings={'frame': robot.payload_frame, 'com_guess_m': [0.0, 0.0, 0.0]}
                )
            )
        else:
            for j, joint in enumerate(joints):
                if name == 'stribeck_friction':
                    specs += [
                        EffectSpec(name, j, joint, {'velocity': vs, 'smoothing_velocity': eps})
                        for vs in config.stribeck_velocities
                    ]
                elif name == 'cogging':
                    specs += [
                        EffectSpec(name, j, joint, {'periods_per_motor_turn': p})
                        for p in config.cogging_periods
                    ]
                elif name == 'gravity_spring':
                    if j in springs:
                        # A middling geometry; a selected balancer's is refined (pipeline).
                        settings = {'ratio': 0.5, 'phase_rad': 0.0}
                        specs.append(EffectSpec(name, j, joint, settings))
                elif name in ('coulomb_friction', 'load_dependent_friction'):
                    specs.append(EffectSpec(name, j, joint, {'smoothing_velocity': eps}))
                else:
                    specs.append(EffectSpec(name, j, joint))
    return specs


# -- testability and plausibility -----------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class ExcitationFacts:
    """What the (training) excitation and the filter allow; arrays (N, n).

    Attributes:
        v: filtered joint velocities [rad/s].
        cutoff_hz: (n,) cut-offs [Hz].
        column_norm: effective-weighted norm of each filtered column (k,), per candidate label.
        retention: share of a candidate's column energy the filter keeps, per label.
    """

    v: np.ndarray
    cutoff_hz: np.ndarray
    column_norm: dict[str, np.ndarray]
    retention: dict[str, float]


def _moving(v: np.ndarray, eps: float) -> np.ndarray:
    return np.abs(v) > 2.0 * eps


#: Effects preferred over a gravity spring that they mimic (an alias set): no hardware claimed.
SPRING_STAND_INS = ('joint_offset', 'torque_offset', 'inertial_parameter_error', 'payload_mass')
#: Effects that exist in tau_u from currents only, not in a torque measured after the gear.
#: (A rotor is not seen after the gear either, but the same column is then an error of the
#: URDF's inertia about the joint axis: described link side, as a change.)
MOTOR_SIDE_EFFECTS = ('torque_constant_scale',)


def testability(
    spec: EffectSpec, facts: ExcitationFacts, model: NominalModel, config: DiagnosisConfig
) -> tuple[bool, str]:
    """Whether this excitation can show the effect at all; the reason when it cannot."""
    robot = model.robot
    j = spec.joint
    eps = config.smoothing_velocity
    norm = facts.column_norm[spec.label]
    if model.target != 'motor' and spec.name in MOTOR_SIDE_EFFECTS:
        return False, (
            'measured joint torques are taken after the gear: no motor torque constant is in '
            'the label'
        )
    if not np.any(norm > 0):
        return False, 'its regressor is zero on this recording'
    if j is not None and spec.name in (
        'viscous_friction',
        'coulomb_friction',
        'stribeck_friction',
        'load_dependent_friction',
        'cogging',
        'rotor_inertia',
    ):
        v = facts.v[:, j]
        moving = _moving(v, eps)
        if moving.mean() < config.min_moving_fraction:
            return False, (
                f'{spec.joint_name} moves (|v| > {2 * eps:g} rad/s) in only '
                f'{100 * moving.mean():.0f} % of the samples'
            )
        if spec.name not in ('rotor_inertia', 'viscous_friction'):
            both = min(np.mean(v > 2 * eps), np.mean(v < -2 * eps))
            if both < 0.25 * config.min_moving_fraction:
                return False, f'{spec.joint_name} hardly moves in both directions'
        if spec.name == 'stribeck_friction':
            vs = spec.settings['velocity']
            slow = moving & (np.abs(v) < vs)
            share = slow.sum() / max(moving.sum(), 1)
            if share < config.min_slow_fraction:
                return False, (
                    f'too little slow motion: {100 * share:.1f} % of the moving samples of '
                    f'{spec.joint_name} are slower than v_s = {vs:g} rad/s '
                    f'(needs {100 * config.min_slow_fraction:g} %)'
                )
        if spec.name == 'cogging':
            p = spec.settings['periods_per_motor_turn']
            frequency = p * robot.drives.gear_ratio[j] * np.abs(v[moving]) / (2 * math.pi)
            share = float(np.mean(frequency < facts.cutoff_hz[j]))
            if share < config.min_below_cutoff_fraction:
                return False, (
                    f'above the filter cut-off: its frequency p N |v| / (2 pi) is below the '
                    f'{facts.cutoff_hz[j]:g} Hz cut-off in only {100 * share:.1f} % of the moving '
                    f'samples of {spec.joint_name}'
                )
    retention = facts.retention[spec.label]
    if retention < config.min_retention:
        return False, (
            f'above the filter cut-off: the filter keeps only {100 * retention:.1f} % of its '
            'signature'
        )
    if spec.name in ('joint_offset', 'signal_delay'):
        bound = _single_parameter_bound(spec, model)
        smallest = 5.0 / float(norm[0])  # 5 standard errors from zero, noise only
        if smallest > bound:
            unit = PARAMETERS[spec.name][0][1]
            if not smallest < 10.0 * bound:  # a number that large means nothing to a reader
                return False, (
                    'not detectable on this excitation: its signature is at the noise level '
                    f'(it would take a value over 10 times the plausible bound {bound:.3g} '
                    f'{unit} to show)'
                )
            return False, (
                f'too weak on this excitation: the smallest detectable value {smallest:.3g} '
                f'{unit} exceeds the plausible bound {bound:.3g} {unit}'
            )
    return True, ''


def _single_parameter_bound(spec: EffectSpec, model: NominalModel) -> float:
    if spec.name == 'joint_offset':
        assert spec.joint is not None
        # Judged by what it does at the payload frame: taught points off by up to the offset
        # times the frame's farthest distance from the axis. A heavy axis 2 m from the flange
        # may hide 1 degree, a wrist axis 0.25 m from it several.
        lever = float(model.lever_arms()[spec.joint])
        return min(JOINT_OFFSET_MAX_RAD, MASTERING_TOLERANCE_M / max(lever, 1e-9))
    if spec.name == 'signal_delay':
        return max(0.05, 10.0 * model.robot.ipo_period_s)  # s
    raise ValueError(spec.name)


def _viscous_curve(
    theta: np.ndarray,
    covariance: np.ndarray,
    margin: float,
    *,
    exponent: float,
    max_velocity: float,
    limit: float,
) -> tuple[bool, str]:
    """A linear-plus-power viscous law b v + c v^delta: dissipative and within the limit.

    Its torque at each speed up to the joint's limit is linear in (b, c): it must not be
    negative, nor exceed the torque limit, beyond its margin (from 2 % of the top speed on:
    below, the Coulomb level holds the curve up).
    """
    speeds = max_velocity * np.linspace(0.02, 1.0, 50)
    basis = np.stack([speeds, speeds**exponent], axis=1)
    torque = basis @ theta
    spread = margin * np.sqrt(np.clip(np.einsum('ik,kl,il->i', basis, covariance, basis), 0, None))
    law = f'viscous law {theta[0]:.4g} v + {theta[1]:.4g} v^{exponent:g} gives'
    low = int(np.argmin(torque + spread))
    if torque[low] + spread[low] < 0:
        return False, (
            f'{law} {torque[low]:.4g} +- {spread[low] / margin:.2g} N*m at '
            f'{speeds[low]:.3g} rad/s: friction that drives the joint'
        )
    high = int(np.argmax(torque - spread))
    if torque[high] - spread[high] > limit:
        return False, (
            f'{law} {torque[high]:.4g} N*m at {speeds[high]:.3g} rad/s, beyond the torque '
            f'limit {limit:g}'
        )
    return True, ''


@dataclass(frozen=True, eq=False)
class PlausibilityFacts:
    """Nominal torque levels the size rules compare against; (n,) arrays [N*m].

    Attributes:
        rigid_rms: RMS of the URDF rigid-body torque per joint.
        gravity: (N, n) nominal gravity torque along the training motion (for the spring's sign).
        moving_mass_kg: total moving mass of the URDF [kg].
        body_parameters: (bodies, 10) the URDF's inertial parameters (pinocchio's order).
    """

    rigid_rms: np.ndarray
    gravity: np.ndarray
    moving_mass_kg: float
    body_parameters: np.ndarray


def plausibility(
    spec: EffectSpec,
    theta: np.ndarray,
    columns: np.ndarray,
    model: NominalModel,
    facts: PlausibilityFacts,
    *,
    covariance: np.ndarray | None = None,
) -> tuple[bool, str]:
    """Whether a fitted value is physically plausible; the reason when it is not.

    A value is implausible when it lies outside the plausible range by more than its
    simultaneous 95 % confidence margin: sqrt(chi^2_k(0.95)) standard errors for a group of k
    parameters (1.96 for one), so a weakly determined value is not condemned for its noise.

    Args:
        spec: the candidate.
        theta: (k,) its parameters in physical units.
        columns: (N, n, k) its columns along the training motion (unfiltered): the torque it
            adds is columns @ theta [N*m].
        model: the nominal model (robot limits, drives).
        facts: nominal torque levels.
        covariance: (k, k) covariance of theta; exact values if None.
    """
    robot = model.robot
    j = spec.joint
    limit = robot.limits.torque[j] if j is not None else None
    k = len(theta)
    covariance = np.zeros((k, k)) if covariance is None else np.asarray(covariance)
    sd = np.sqrt(np.clip(np.diag(covariance), 0.0, None))
    margin = math.sqrt(float(stats.chi2.ppf(0.95, k)))
    value = float(theta[0])
    name = spec.name

    def _in_range(value: float, low: float, high: float, unit: str) -> tuple[bool, str]:
        return _within(value, margin * float(sd[0]), low, high, unit)

    if name == 'viscous_friction':
        assert limit is not None
        assert j is not None
        exponent = float(spec.settings.get('exponent', 1.0))
        if k == 1:
            bound = limit / robot.limits.velocity[j] ** exponent
            unit = 'N*m*s/rad' if exponent == 1.0 else f'N*m*(s/rad)^{exponent:g}'
            return _in_range(value, 0.0, bound, unit)
        return _viscous_curve(
            theta,
            covariance,
            margin,
            exponent=exponent,
            max_velocity=float(robot.limits.velocity[j]),
            limit=limit,
        )
    if name in ('coulomb_friction', 'stribeck_friction'):
        assert limit is not None
        return _in_range(value, 0.0, 0.5 * limit, 'N*m')
    if name == 'load_dependent_friction':
        return _in_range(value, 0.0, 0.5, '')
    if name == 'rotor_inertia':
        assert j is not None
        nominal = robot.drives.rotor_inertia[j]
        # A brake or gear stage adds inertia; a datasheet is rarely off by more than 3x.
        low = -0.9 * nominal if nominal > 0 else 0.0
        high = 3.0 * nominal if nominal > 0 else 1e-3
        return _in_range(value, low, high, 'kg*m^2')
    if name == 'gravity_spring':
        assert j is not None
        x = columns[:, j, :]
        spring, gravity = x @ theta, facts.gravity[:, j]
        if np.std(spring) == 0 or np.std(gravity) == 0:
            return False, 'no gravity torque to balance'
        # Mounted to carry the arm's weight: it falls where gravity's torque rises, or it takes
        # load off on average (a balancer on joint 3 turns with q3, gravity there with q2 + q3:
        # their shapes may rise together while the balancer's mean still opposes gravity's).
        # Both are linear in theta: refused only where both add to gravity beyond the margin.
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
    if name == 'payload_mass':
        mass = value
        if not (mass + margin * sd[0] > 0.0 and mass - margin * sd[0] <= facts.moving_mass_kg):
            return False, (
                f'mass {mass:.3g} kg outside (0, {facts.moving_mass_kg:.3g}] kg (moving mass)'
            )
        com = np.asarray(theta[1:4]) / mass
        if np.linalg.norm(com) > PAYLOAD_COM_LIMIT_M:
            return False, (
                f'centre of mass {np.linalg.norm(com):.2f} m from the frame '
                f'(> {PAYLOAD_COM_LIMIT_M:g} m)'
            )
        return True, ''
    if name == 'joint_offset':
        bound = _single_parameter_bound(spec, model)
        return _in_range(value, -bound, bound, 'rad')
    if name == 'torque_constant_scale':
        return _in_range(value, -0.3, 0.3, '')
    if name == 'signal_delay':
        return _in_range(value, 0.0, _single_parameter_bound(spec, model), 's')
    if name == 'cogging':
        assert limit is not None
        amplitude = float(np.hypot(theta[0], theta[1]))
        spread = margin * float(np.hypot(sd[0], sd[1]))
        return _within(amplitude, spread, 0.0, 0.05 * limit, 'N*m amplitude')
    if name == 'torque_offset':
        assert limit is not None
        return _in_range(value, -0.1 * limit, 0.1 * limit, 'N*m')
    if name == 'inertial_parameter_error':
        return _plausible_inertial_change(spec, theta, covariance, facts, margin)
    raise ValueError(f'unknown effect {name!r}')


def _plausible_inertial_change(
    spec: EffectSpec,
    theta: np.ndarray,
    covariance: np.ndarray,
    facts: PlausibilityFacts,
    margin: float,
) -> tuple[bool, str]:
    """CAD-derived link data are off by tens of per cent at most, not by the whole link.

    Bounds on the change of each body's parameters: mass 15 % + 0.5 kg; first moment 10 % + 3 cm
    times the mass; inertia about the joint frame 20 % (Frobenius norm) + the mass times
    (5 cm)^2; each beyond ``margin`` standard errors. The data fix only the identifiable
    combinations, so the change judged is the most plausible one that produces the same
    torques: the fitted change plus the null-space shift that minimises its size relative to
    these bounds.
    """
    directions = np.asarray(spec.settings['base_directions'])
    null = np.asarray(spec.settings.get('null_directions', np.zeros((len(directions), 0))))
    bounds = np.concatenate([_body_bounds(nominal) for nominal in facts.body_parameters])
    weight = 1.0 / bounds
    mapping = directions
    if null.shape[1]:
        # min_z |W (D theta + N z)|: project D theta off the weighted null space.
        weighted_null = weight[:, None] * null
        shift, *_ = np.linalg.lstsq(weighted_null, -(weight[:, None] * directions), rcond=None)
        mapping = directions + null @ shift
    change_all = mapping @ np.asarray(theta)
    covariance_all = mapping @ covariance @ mapping.T
    for body, nominal in enumerate(facts.body_parameters):
        rows = slice(N_INERTIAL_PARAMETERS * body, N_INERTIAL_PARAMETERS * (body + 1))
        ok, reason = _plausible_body_change(
            change_all[rows], covariance_all[rows, rows], nominal, margin
        )
        if not ok:
            return False, f'body {body + 1}: {reason}'
    return True, ''


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
) -> tuple[bool, str]:
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


def _within(value: float, spread: float, low: float, high: float, unit: str) -> tuple[bool, str]:
    if value + spread >= low and value - spread <= high:
        return True, ''
    return False, (
        f'value {value:.4g} +- {spread:.2g} {unit} outside the plausible range '
        f'[{low:.4g}, {high:.4g}]'
    )
