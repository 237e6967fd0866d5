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
from id_learning.physics.effects.base import (
    Effect,
    FittedTerm,
    JointColumns,
    JointEffect,
    Parameter,
    SettingAxis,
    entry,
)
from id_learning.physics.effects.judgement import (
    CandidateGrid,
    JointMotion,
    PlausibilityFacts,
    Trial,
    Verdict,
    within,
)
from id_learning.physics.effects.links import (
    GRAVITY_SPRING,
    INERTIAL_PARAMETER_ERROR,
    JOINT_OFFSET,
    PAYLOAD_MASS,
)
from id_learning.physics.nominal import NominalModel, NominalQuantities
from id_learning.robot.drives import rotor_basis, rotor_inertia_joint_side

__all__ = ['LABEL_GAIN_STD', 'LIBRARY', 'ROTOR_INERTIA_STD']

#: Prior std of a label gain (torque-constant error) around 0: a datasheet's tolerance.
LABEL_GAIN_STD = 0.05
#: Relative prior std of a datasheet rotor inertia (brake and gear input stage left out).
ROTOR_INERTIA_STD = 0.3
#: A Stribeck velocity is tuned within this factor of the candidate's (``tuned_settings``).
STRIBECK_SPAN = 2.5


class ViscousFriction(JointEffect):
    """d v; or a power law sign(v) |v|^delta, after v where the settings say ``linear``."""

    name = 'viscous_friction'
    parameters = (Parameter('coefficient', 'N*m*s/rad'),)
    friction_shaped = True
    needs_motion = True
    law = 'viscous'

    def law_column(
        self, v: np.ndarray, load: np.ndarray, smoothing_velocity: float, velocity: Any
    ) -> np.ndarray:
        return laws.viscous(v)[0]

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

    def plausibility(self, trial: Trial, model: NominalModel, facts: PlausibilityFacts) -> Verdict:
        """Dissipative and within the torque limit up to the joint's top speed."""
        j = _joint(trial)
        limits = model.robot.limits
        exponent = float(trial.settings.get('exponent', 1.0))
        if len(trial.theta) == 1:
            bound = limits.torque[j] / limits.velocity[j] ** exponent
            unit = 'N*m*s/rad' if exponent == 1.0 else f'N*m*(s/rad)^{exponent:g}'
            return trial.first_within(0.0, bound, unit)
        return _viscous_curve(trial, exponent, float(limits.velocity[j]), float(limits.torque[j]))

    def reshaped_settings(
        self, settings: Mapping[str, Any], smoothing_velocity: float, exponent: float
    ) -> dict[str, Any]:
        """Stiffening: linear at low speed, bending at speed. Thinning: a power alone.

        A free linear part beside a thinning power would turn its slope at zero speed into a
        softer Coulomb turn (with one, 7 of 15 twin recordings took v + |v|^0.6 for a linear
        law, beside the turn).
        """
        if exponent == 1.0:
            return {}
        return {'exponent': exponent} | ({'linear': True} if exponent > 1.0 else {})


class _SignedFriction(JointEffect):
    """A friction law that turns with the sign of v through tanh(v / v_eps).

    Only motion in both directions shows it; at most half the joint's torque limit, never
    driving the joint; one candidate per joint at the grid's smoothing velocity.
    """

    friction_shaped = True
    switching = True
    needs_motion = True
    needs_both_directions = True

    def plausibility(self, trial: Trial, model: NominalModel, facts: PlausibilityFacts) -> Verdict:
        """Dissipative, and at most half the joint's torque limit."""
        return trial.first_within(0.0, 0.5 * model.robot.limits.torque[_joint(trial)], 'N*m')

    def candidates(
        self, model: NominalModel, grid: CandidateGrid
    ) -> list[tuple[int | None, dict[str, Any]]]:
        """One per joint, at the grid's smoothing velocity."""
        eps = grid.smoothing_velocity
        return [(j, {'smoothing_velocity': eps}) for j in range(model.robot.n_joints)]


class CoulombFriction(_SignedFriction):
    """F_c tanh(v / v_eps)."""

    name = 'coulomb_friction'
    parameters = (Parameter('level', 'N*m'),)
    law = 'coulomb'

    def law_column(
        self, v: np.ndarray, load: np.ndarray, smoothing_velocity: float, velocity: Any
    ) -> np.ndarray:
        return laws.coulomb(v, smoothing_velocity)

    def joint_columns(
        self, quantities: NominalQuantities, joint: Any, settings: Mapping[str, Any],
        model: NominalModel,
    ) -> JointColumns:  # fmt: skip
        return (laws.coulomb(quantities.v[:, joint], settings['smoothing_velocity']),)


class StribeckFriction(_SignedFriction):
    """F_s exp(-(v / v_s)^2) tanh(v / v_eps), one candidate per Stribeck velocity v_s."""

    name = 'stribeck_friction'
    parameters = (Parameter('level', 'N*m'),)
    exclusive_variants = True
    hump = True
    law = 'stribeck'

    def law_column(
        self, v: np.ndarray, load: np.ndarray, smoothing_velocity: float, velocity: Any
    ) -> np.ndarray:
        return laws.stribeck(v, velocity, smoothing_velocity)

    def tuned_settings(self, settings: Mapping[str, Any]) -> tuple[SettingAxis, ...]:
        """Its velocity, in log, within ``STRIBECK_SPAN`` of the candidate's."""
        start, span = math.log(float(settings['velocity'])), math.log(STRIBECK_SPAN)
        grid = tuple(start + span * k / 4 for k in range(-4, 5))
        return (SettingAxis('velocity', grid, start - span, start + span, span / 8, log=True),)

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

    def excitation_problem(self, settings: Mapping[str, Any], motion: JointMotion) -> str:
        """Enough slow motion: the hump lives below v_s."""
        vs = settings['velocity']
        slow = motion.moving & (np.abs(motion.v) < vs)
        share = slow.sum() / max(motion.moving.sum(), 1)
        needed = motion.thresholds['min_slow_fraction']
        if share >= needed:
            return ''
        return (
            f'too little slow motion: {100 * share:.1f} % of the moving samples of '
            f'{motion.joint_name} are slower than v_s = {vs:g} rad/s (needs {100 * needed:g} %)'
        )

    def candidates(
        self, model: NominalModel, grid: CandidateGrid
    ) -> list[tuple[int | None, dict[str, Any]]]:
        """One per joint and Stribeck velocity of the grid (the selected one is refined)."""
        eps = grid.smoothing_velocity
        return [
            (j, {'velocity': vs, 'smoothing_velocity': eps})
            for j in range(model.robot.n_joints)
            for vs in grid.stribeck_velocities
        ]


class LoadDependentFriction(_SignedFriction):
    """mu |L| tanh(v / v_eps), L the load the gear carries, in one of two forms.

    - link torque (no 'load' setting: the URDF's rigid-body torque; 'model': the whole model's,
      nominal plus the link-side effects, since with a payload or a balancer the URDF's alone
      is far off);
    - 'gravity': the URDF's gravity torque alone (a gear loaded by the weight it holds, not
      by what accelerates the arm).

    The forms are exclusive variants: held-out evidence picks one per joint.
    """

    name = 'load_dependent_friction'
    parameters = (Parameter('coefficient', '1'),)
    reads_link_torque = True
    exclusive_variants = True
    law = 'load_dependent'

    def candidates(
        self, model: NominalModel, grid: CandidateGrid
    ) -> list[tuple[int | None, dict[str, Any]]]:
        """Each form on each joint, at the grid's smoothing velocity."""
        link: dict[str, Any] = {'smoothing_velocity': grid.smoothing_velocity}
        forms = (link, {**link, 'load': 'gravity'})
        return [(j, dict(form)) for j in range(model.robot.n_joints) for form in forms]

    def law_column(
        self, v: np.ndarray, load: np.ndarray, smoothing_velocity: float, velocity: Any
    ) -> np.ndarray:
        return laws.load_dependent(v, load, smoothing_velocity)

    def label_parts(self, settings: Mapping[str, Any]) -> list[str]:
        load = settings.get('load')
        return [f'{load} load'] if load in ('model', 'gravity') else []

    def uses_model_load(self, settings: Mapping[str, Any]) -> bool:
        return settings.get('load') == 'model'

    def needs_gravity(self, settings: Mapping[str, Any]) -> bool:
        return settings.get('load') == 'gravity'

    def model_load_settings(self, settings: Mapping[str, Any]) -> dict[str, Any] | None:
        """The link torque's form grows with the whole model's; gravity's stays the URDF's."""
        if settings.get('load') == 'gravity':
            return None
        return {**settings, 'load': 'model'}

    def joint_columns(
        self, quantities: NominalQuantities, joint: Any, settings: Mapping[str, Any],
        model: NominalModel,
    ) -> JointColumns:  # fmt: skip
        if settings.get('load') == 'gravity':
            if quantities.tau_gravity is None:
                raise ValueError('load_dependent_friction (gravity) needs the gravity torque')
            load = quantities.tau_gravity[:, joint]
        else:
            load = quantities.tau_rigid[:, joint]
        v = quantities.v[:, joint]
        return (laws.load_dependent(v, load, settings['smoothing_velocity']),)

    def plausibility(self, trial: Trial, model: NominalModel, facts: PlausibilityFacts) -> Verdict:
        """Dissipative, and at most half the link torque (a gear's efficiency is above 50 %)."""
        return trial.first_within(0.0, 0.5, '')


class RotorInertia(JointEffect):
    """A change J of the rotor inertia (motor side): J N^2 a on the joint."""

    name = 'rotor_inertia'
    parameters = (Parameter('rotor_inertia_change_motor_side', 'kg*m^2'),)
    special_case_of = 'inertial_parameter_error'
    needs_motion = True
    datasheet_value = True

    def prior_precision(
        self, joint: int | None, settings: Mapping[str, Any], model: NominalModel, *,
        as_datasheet: bool,
    ) -> np.ndarray | None:  # fmt: skip
        """A datasheet's value, off by ``ROTOR_INERTIA_STD``, unless named (or none there)."""
        if not as_datasheet or joint is None or model.target != 'motor':
            return None
        nominal = float(model.robot.drives.rotor_inertia[joint])
        if nominal <= 0:
            return None  # no datasheet value to hold it near
        return np.array([[1.0 / (ROTOR_INERTIA_STD * nominal) ** 2]])

    def tolerance_text(self) -> str:
        return f'rotor inertias {ROTOR_INERTIA_STD:.0%}'

    def joint_columns(
        self, quantities: NominalQuantities, joint: Any, settings: Mapping[str, Any],
        model: NominalModel,
    ) -> JointColumns:  # fmt: skip
        return (rotor_basis(quantities.a[:, joint], model.robot.drives.gear_ratio[joint]),)

    def describe(self, fit: FittedTerm, model: NominalModel) -> list[dict[str, Any]]:
        """On joint-torque labels the axis inertia seen link side; on motor labels the rotor's."""
        j = fit.joint
        if j is None:
            return super().describe(fit, model)
        theta, lo, hi = fit.theta[0], fit.low[0], fit.high[0]
        drives = model.robot.drives
        if model.target != 'motor':
            n2 = float(rotor_inertia_joint_side(1.0, drives.gear_ratio[j]))  # N**2
            return [entry('axis_inertia_change_link_side', n2 * theta, n2 * lo, n2 * hi, 'kg*m^2')]
        nominal = drives.rotor_inertia[j]
        out = [entry('rotor_inertia_motor_side', nominal + theta, nominal + lo, nominal + hi,
                     'kg*m^2')]  # fmt: skip
        if nominal > 0:
            out.append(
                entry('scale', 1 + theta / nominal, 1 + lo / nominal, 1 + hi / nominal, '1')
            )
        return out

    def plausibility(self, trial: Trial, model: NominalModel, facts: PlausibilityFacts) -> Verdict:
        """A brake or gear stage adds inertia; a datasheet is rarely off by more than 3x."""
        nominal = model.robot.drives.rotor_inertia[_joint(trial)]
        low = -0.9 * nominal if nominal > 0 else 0.0
        high = 3.0 * nominal if nominal > 0 else 1e-3
        return trial.first_within(low, high, 'kg*m^2')


class TorqueConstantScale(JointEffect):
    """The label's gain off on a joint: the torque it reads is (1 + c) times the delivered."""

    name = 'torque_constant_scale'
    parameters = (Parameter('label_gain_change', '1'),)
    motor_side_only = True
    whole_model_key = 'of'
    scales_the_label = True
    datasheet_value = True

    def prior_precision(
        self, joint: int | None, settings: Mapping[str, Any], model: NominalModel, *,
        as_datasheet: bool,
    ) -> np.ndarray | None:  # fmt: skip
        """A datasheet torque constant's tolerance.

        It and the link masses trade a common scale that only the priors settle.
        """
        del joint, settings, model, as_datasheet
        return np.array([[1.0 / LABEL_GAIN_STD**2]])

    def tolerance_text(self) -> str:
        return f'torque constants {LABEL_GAIN_STD:.0%}'

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

    def plausibility(self, trial: Trial, model: NominalModel, facts: PlausibilityFacts) -> Verdict:
        """A torque constant off by at most 30 % (datasheet tolerance and temperature)."""
        return trial.first_within(-0.3, 0.3, '')


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

    def plausible_bound(self, joint: int | None, model: NominalModel) -> float | None:
        """At most 50 ms or ten IPO cycles [s]."""
        return max(0.05, 10.0 * model.robot.ipo_period_s)

    def plausibility(self, trial: Trial, model: NominalModel, facts: PlausibilityFacts) -> Verdict:
        """Labels lag the motion, never lead it, by at most ``plausible_bound``."""
        bound = self.plausible_bound(None, model)
        assert bound is not None
        return trial.first_within(0.0, bound, 's')


class Cogging(JointEffect):
    """Torque ripple periodic in the motor angle: sin and cos of p N q."""

    name = 'cogging'
    parameters = (Parameter('sine', 'N*m'), Parameter('cosine', 'N*m'))
    switching = True
    needs_motion = True
    needs_both_directions = True

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

    def plausibility(self, trial: Trial, model: NominalModel, facts: PlausibilityFacts) -> Verdict:
        """An amplitude of at most 5 % of the joint's torque limit."""
        limit = model.robot.limits.torque[_joint(trial)]
        amplitude = float(np.hypot(trial.theta[0], trial.theta[1]))
        spread = trial.margin * float(np.hypot(trial.sd[0], trial.sd[1]))
        return within(amplitude, spread, 0.0, 0.05 * limit, 'N*m amplitude')

    def excitation_problem(self, settings: Mapping[str, Any], motion: JointMotion) -> str:
        """Its ripple frequency p N |v| / (2 pi) below the label filter's cut-off."""
        p = settings['periods_per_motor_turn']
        frequency = p * motion.gear_ratio * np.abs(motion.v[motion.moving]) / (2 * math.pi)
        share = float(np.mean(frequency < motion.cutoff_hz))
        if share >= motion.thresholds['min_below_cutoff_fraction']:
            return ''
        return (
            f'above the filter cut-off: its frequency p N |v| / (2 pi) is below the '
            f'{motion.cutoff_hz:g} Hz cut-off in only {100 * share:.1f} % of the moving '
            f'samples of {motion.joint_name}'
        )

    def candidates(
        self, model: NominalModel, grid: CandidateGrid
    ) -> list[tuple[int | None, dict[str, Any]]]:
        """One per joint and cogging period of the grid."""
        return [
            (j, {'periods_per_motor_turn': p})
            for j in range(model.robot.n_joints)
            for p in grid.cogging_periods
        ]


class TorqueOffset(JointEffect):
    """A constant torque on the joint (a current sensor's offset)."""

    name = 'torque_offset'
    parameters = (Parameter('offset', 'N*m'),)
    stands_in_for_hardware = True
    label_offset = True

    def joint_columns(
        self, quantities: NominalQuantities, joint: Any, settings: Mapping[str, Any],
        model: NominalModel,
    ) -> JointColumns:  # fmt: skip
        return (np.ones_like(quantities.q[:, joint]),)

    def plausibility(self, trial: Trial, model: NominalModel, facts: PlausibilityFacts) -> Verdict:
        """At most 10 % of the joint's torque limit (a current sensor's offset)."""
        limit = model.robot.limits.torque[_joint(trial)]
        return trial.first_within(-0.1 * limit, 0.1 * limit, 'N*m')


#: Every effect, in the library's stable order.
LIBRARY: tuple[Effect, ...] = (
    ViscousFriction(),
    CoulombFriction(),
    StribeckFriction(),
    LoadDependentFriction(),
    RotorInertia(),
    GRAVITY_SPRING,
    PAYLOAD_MASS,
    JOINT_OFFSET,
    TorqueConstantScale(),
    SignalDelay(),
    Cogging(),
    TorqueOffset(),
    INERTIAL_PARAMETER_ERROR,
)


def _joint(trial: Trial) -> int:
    """The joint a joint effect's trial sits on."""
    if trial.joint is None:
        raise ValueError('a joint effect needs a joint')
    return trial.joint


def _viscous_curve(trial: Trial, exponent: float, max_velocity: float, limit: float) -> Verdict:
    """A linear-plus-power viscous law b v + c v^delta: dissipative and within the limit.

    Its torque at each speed up to the joint's limit is linear in (b, c): it must not be
    negative, nor exceed the torque limit, beyond its margin (from 2 % of the top speed on:
    below, the Coulomb level holds the curve up).
    """
    theta, margin = trial.theta, trial.margin
    speeds = max_velocity * np.linspace(0.02, 1.0, 50)
    basis = np.stack([speeds, speeds**exponent], axis=1)
    torque = basis @ theta
    variance = np.einsum('ik,kl,il->i', basis, trial.covariance, basis)
    spread = margin * np.sqrt(np.clip(variance, 0, None))
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
