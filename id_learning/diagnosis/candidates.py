"""The diagnosis' library of candidate effects, and the rules it judges them by.

Every effect term of the physics layer (``physics.terms``) on every joint where it can act is a
candidate. Each candidate carries the condition under which the excitation can show it at all
(``testability``) and a sign/size rule for a physical value (``plausibility``);
``parameters.describe_parameters`` turns fitted coefficients into physical parameters.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from id_learning.diagnosis.config import DiagnosisConfig
from id_learning.errors import ConfigError
from id_learning.physics.effects import effect
from id_learning.physics.effects.judgement import (
    CandidateGrid,
    JointMotion,
    PlausibilityFacts,
    Trial,
)
from id_learning.physics.effects.links import PAYLOAD_COM_LIMIT_M
from id_learning.physics.nominal import NominalModel, NominalQuantities
from id_learning.physics.terms import EffectSpec, gravity_loaded_joints

__all__ = [
    'PAYLOAD_COM_LIMIT_M',
    'ExcitationFacts',
    'PlausibilityFacts',
    'build_library',
    'plausibility',
    'spring_joints',
    'testability',
]


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
    joints = model.robot.joints
    grid = CandidateGrid(
        config.smoothing_velocity,
        tuple(config.stribeck_velocities),
        tuple(config.cogging_periods),
        tuple(spring_joints(model, quantities, config)),
    )
    return [
        EffectSpec(name, j, joints[j] if j is not None else '', settings)
        for name in config.effects
        for j, settings in effect(name).candidates(model, grid)
    ]


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
    out: np.ndarray = np.abs(v) > 2.0 * eps
    return out


def testability(
    spec: EffectSpec, facts: ExcitationFacts, model: NominalModel, config: DiagnosisConfig
) -> tuple[bool, str]:
    """Whether this excitation can show the effect at all; the reason when it cannot."""
    item = effect(spec.name)
    j = spec.joint
    eps = config.smoothing_velocity
    norm = facts.column_norm[spec.label]
    if model.target != 'motor' and item.motor_side_only:
        return False, (
            'measured joint torques are taken after the gear: no motor torque constant is in '
            'the label'
        )
    if not np.any(norm > 0):
        return False, 'its regressor is zero on this recording'
    if j is not None and item.needs_motion:
        v = facts.v[:, j]
        moving = _moving(v, eps)
        if moving.mean() < config.min_moving_fraction:
            return False, (
                f'{spec.joint_name} moves (|v| > {2 * eps:g} rad/s) in only '
                f'{100 * moving.mean():.0f} % of the samples'
            )
        if item.needs_both_directions:
            both = min(np.mean(v > 2 * eps), np.mean(v < -2 * eps))
            if both < 0.25 * config.min_moving_fraction:
                return False, f'{spec.joint_name} hardly moves in both directions'
        motion = JointMotion(
            spec.joint_name, v, moving, float(model.robot.drives.gear_ratio[j]),
            float(facts.cutoff_hz[j]),
            {'min_slow_fraction': config.min_slow_fraction,
             'min_below_cutoff_fraction': config.min_below_cutoff_fraction},
        )  # fmt: skip
        problem = item.excitation_problem(spec.settings, motion)
        if problem:
            return False, problem
    retention = facts.retention[spec.label]
    if retention < config.min_retention:
        return False, (
            f'above the filter cut-off: the filter keeps only {100 * retention:.1f} % of its '
            'signature'
        )
    bound = item.plausible_bound(j, model)
    if bound is not None:
        smallest = 5.0 / float(norm[0])  # 5 standard errors from zero, noise only
        if smallest > bound:
            unit = item.parameters[0].unit
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

    The effect's own rule (``Effect.plausibility``): a value is implausible when it lies
    outside the plausible range by more than its simultaneous 95 % confidence margin.

    Args:
        spec: the candidate.
        theta: (k,) its parameters in physical units.
        columns: (N, n, k) its columns along the training motion (unfiltered): the torque it
            adds is columns @ theta [N*m].
        model: the nominal model (robot limits, drives).
        facts: nominal torque levels.
        covariance: (k, k) covariance of theta; exact values if None.
    """
    theta = np.asarray(theta, dtype=float)
    k = len(theta)
    covariance = np.zeros((k, k)) if covariance is None else np.asarray(covariance)
    trial = Trial(spec.joint, spec.settings, theta, covariance, columns)
    return effect(spec.name).plausibility(trial, model, facts)
