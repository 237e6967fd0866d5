"""What a diagnosis found: the effects, alias sets, remainder and held-out figures, as JSON."""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from functools import cached_property
from typing import Any

import numpy as np

from id_learning.dataset.statistics import (
    NoiseEstimate,
)
from id_learning.diagnosis.aliases import AliasSet
from id_learning.diagnosis.config import DiagnosisConfig
from id_learning.diagnosis.locate import JointLocation
from id_learning.physics.augmented import AugmentedModel
from id_learning.physics.nominal import NominalModel
from id_learning.physics.terms import (
    EffectSpec,
)
from id_learning.robot.config import RobotConfig

__all__ = ['SCHEMA', 'DiagnosisResult', 'FoundEffect', 'Remainder', 'json_default']

SCHEMA = 'id_learning.diagnosis/1'


@dataclass(frozen=True)
class FoundEffect:
    """One effect the refit model contains.

    Attributes:
        spec: the candidate (name, joint, column settings).
        status: 'found' (named) or 'alias' (kept in the model, but one of an alias set).
        confidence: 'high', or 'low' when its held-out gain over blocks of time is not
            significant (or cannot be judged), when its joint falls back to the nominal model,
            or when a structured remainder on its joints is larger than what it explains there.
        coefficients: (k,) column coefficients in physical units (the model's parameters, with
            what the diagnosis does not name at its datasheet value).
        coefficients_ci: (k, 2) 95 % confidence intervals of the coefficients.
        parameters: physical parameters with intervals (``describe_parameters``), estimated
            on both parts (the held-out part too, once it chose the effects) with the datasheet
            values no effect names free within their tolerances
            (``DiagnosisResult.marginalised``): a torque constant taken as exact would set the
            scale of every parameter in torque units. Where one of them stands in for a missing
            effect (``DiagnosisResult.stand_ins``), the values are the refit model's and only
            the intervals carry the tolerances.
        contribution_rms_nm: (n,) RMS of the filtered torque it adds per joint [N*m].
        variance_explained: (n,) share of the nominal residual's held-out variance it removed.
        variance_explained_total: the same over all joints, noise-weighted.
        selection: the tests when it entered (F, p-value, delta BIC, held-out gain),
            'held_out_blocks': its gain judged over blocks of held-out time (``heldout``), and
            'interval_inflation': the factor its interval covariance was widened by for a
            remainder correlated longer than filtered noise (1: none).
    """

    spec: EffectSpec
    status: str
    confidence: str
    coefficients: np.ndarray
    coefficients_ci: np.ndarray
    parameters: list[dict[str, Any]]
    contribution_rms_nm: np.ndarray
    variance_explained: np.ndarray
    variance_explained_total: float
    selection: dict[str, Any]

    @property
    def name(self) -> str:
        """The effect's stable name."""
        return self.spec.name

    @property
    def label(self) -> str:
        """name[joint, ...]."""
        return self.spec.label


@dataclass(frozen=True)
class Remainder:
    """What is left on one joint after the refit (both parts).

    Attributes:
        joint: joint name.
        rms_nm: residual RMS [N*m].
        noise_nm: estimated noise level of the filtered label [N*m].
        ratio: rms_nm / noise_nm.
        p_value: chi^2 variance test against the noise level, effective samples.
        correlation_ratio: residual correlation time / the filtered noise's (1 for noise).
        structured: a remainder no candidate explains: larger than the noise level (variance
            test and ``noise_tolerance``), or above it and correlated for much longer than
            filtered noise (``structure_correlation_ratio``).
    """

    joint: str
    rms_nm: float
    noise_nm: float
    ratio: float
    p_value: float
    correlation_ratio: float
    structured: bool


@dataclass(frozen=True, eq=False)
class DiagnosisResult:
    """Everything a diagnosis found; ``to_json`` gives effects.json.

    Attributes:
        robot: the robot config (not serialised; needed to evaluate the augmented model).
        target: 'motor' or 'joint'.
        sources: recordings diagnosed.
        duration_s: total recorded time [s].
        noise: the label's noise estimate.
        effective_samples: {'train', 'test'} -> (n,) independent samples per joint.
        effects: effects in the refit model, in the order they entered.
        alias_sets: effects this excitation cannot tell apart.
        untestable: candidates the excitation cannot show, with reasons.
        remainder: per joint, what is left.
        rmse_before_nm, rmse_after_nm: (n,) held-out RMSE of the nominal and the refit model
            (the nominal model's on the joints in ``nominal_joints``).
        waterfall: per added effect, (label, (n,) held-out RMSE after adding it [N*m]).
        location: per joint, where the nominal residual lives.
        stop_reason: why the selection stopped.
        cut_short: the steps the time budget left out (``DiagnosisConfig.max_seconds``).
        rejected: the best candidate that did not enter, and why.
        refused: per joint it closed, a candidate that explains the joint's residual best but
            fails its plausibility rule (its fitted values and the rule): that joint's
            remainder is reported as unexplained rather than filled with other effects.
        nominal_joints: joints whose held-out part the effects do not improve: the refit model
            gives the nominal torque there.
        marginalised: candidates for datasheet values no effect names (torque constants, rotor
            inertias, link parameters) that the parameters were estimated with, free within
            their tolerances (``CandidateSet.datasheet_unknowns``).
        stand_ins: those of them that fitted far outside their tolerances: they stand in for an
            effect the model lacks, and the parameters' values are the coefficients' instead.
        config: the settings used (JSON-ready).
        settings: the diagnosis config (not serialised; ``config`` is its JSON form).
        series: on the kept rows of both parts (not serialised): 'time_s' (M,), 'is_test' (M,),
            'label' (filtered label), 'residual_before' (label minus nominal) and
            'residual_after' (label minus refit model), each (M, n) [N*m].
    """

    robot: RobotConfig
    target: str
    sources: list[str]
    duration_s: float
    noise: NoiseEstimate
    effective_samples: dict[str, np.ndarray]
    effects: list[FoundEffect]
    alias_sets: list[AliasSet]
    untestable: list[dict[str, Any]]
    remainder: list[Remainder]
    rmse_before_nm: np.ndarray
    rmse_after_nm: np.ndarray
    waterfall: list[tuple[str, np.ndarray]]
    location: list[JointLocation]
    stop_reason: str
    rejected: dict[str, Any] | None
    refused: list[dict[str, Any]] = field(default_factory=list)
    nominal_joints: list[str] = field(default_factory=list)
    cut_short: list[str] = field(default_factory=list)
    marginalised: list[str] = field(default_factory=list)
    stand_ins: list[str] = field(default_factory=list)
    config: dict[str, Any] = field(default_factory=dict)
    series: dict[str, np.ndarray] = field(default_factory=dict)
    settings: DiagnosisConfig | None = None

    @property
    def joints(self) -> tuple[str, ...]:
        """Joint names, the column order of every array."""
        return self.robot.joints

    def named_effects(self) -> list[FoundEffect]:
        """Effects named without ambiguity (not part of an alias set)."""
        return [effect for effect in self.effects if effect.status == 'found']

    def untestable_effects(self) -> list[tuple[str, str | None]]:
        """(name, joint) pairs none of whose candidates this excitation can show."""
        return [(e['name'], e['joint']) for e in self.untestable if e['all_variants']]

    def structured_joints(self) -> list[str]:
        """Joints with an unexplained, structured remainder (or closed by a refused candidate)."""
        closed = {record['joint'] for record in self.refused}
        return [r.joint for r in self.remainder if r.structured or r.joint in closed]

    @cached_property
    def augmented_model(self) -> AugmentedModel:
        """The refit model: nominal plus every effect; nominal alone on the fallback joints."""
        return AugmentedModel(
            self.robot,
            self.target,
            [(e.spec, e.coefficients) for e in self.effects],
            nominal_joints=self.nominal_joints,
        )

    @property
    def nominal_model(self) -> NominalModel:
        """The nominal model the effects are added to (built on first use)."""
        return self.augmented_model.nominal

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form (effects.json)."""
        joints = list(self.joints)

        def member(label: str) -> dict[str, Any]:
            for effect in self.effects:
                if effect.label == label:
                    return {'name': effect.name, 'joint': effect.spec.joint_name or None,
                            'label': label}  # fmt: skip
            name, _, rest = label.partition('[')
            joint = rest.rstrip(']').split(',')[0].strip() if rest else ''
            return {'name': name, 'joint': joint if joint in joints else None, 'label': label}

        return {
            'schema': SCHEMA,
            'robot': self.robot.name,
            'joints': joints,
            'target': self.target,
            'sources': self.sources,
            'model': self.augmented_model.to_dict(),
            'duration_s': self.duration_s,
            'noise': {
                'raw_std_nm': self.noise.raw_std_nm.tolist(),
                'filtered_std_nm': self.noise.filtered_std_nm.tolist(),
                'correlation_time_samples': self.noise.correlation_samples.tolist(),
                'band_hz': list(self.noise.band_hz),
            },
            'effective_samples': {k: v.tolist() for k, v in self.effective_samples.items()},
            'effects': [
                {
                    'name': e.name,
                    'joint': e.spec.joint_name or None,
                    'label': e.label,
                    'status': e.status,
                    'confidence': e.confidence,
                    'parameters': e.parameters,
                    'variance_explained': e.variance_explained.tolist(),
                    'variance_explained_total': e.variance_explained_total,
                    'contribution_rms_nm': e.contribution_rms_nm.tolist(),
                    'selection': e.selection,
                    'model': {
                        'spec': e.spec.to_dict(),
                        'coefficients': e.coefficients.tolist(),
                        'coefficients_ci': e.coefficients_ci.tolist(),
                    },
                }
                for e in self.effects
            ],
            'alias_sets': [
                {
                    'representative': alias.representative,
                    'members': [member(label) for label in alias.members],
                    'canonical_correlation': alias.canonical_correlation,
                    'unexplained_effective': alias.unexplained,
                    'alternatives_ranked': alias.alternatives(),
                    'further_alternatives': alias.further,
                    'separating_motion': alias.separation,
                }
                for alias in self.alias_sets
            ],
            'untestable': self.untestable,
            'unexplained_remainder': [r.__dict__ for r in self.remainder],
            'held_out_rmse_nm': {
                'before': self.rmse_before_nm.tolist(),
                'after': self.rmse_after_nm.tolist(),
                'nominal_joints': list(self.nominal_joints),
                'waterfall': [
                    {'added': label, 'rmse_nm': rmse.tolist()} for label, rmse in self.waterfall
                ],
            },
            'location': [
                {
                    'joint': loc.joint,
                    'rms_nm': loc.rms_nm,
                    'explained_share': loc.explained_share,
                    'dominant': loc.dominant(),
                }
                for loc in self.location
            ],
            'stop_reason': self.stop_reason,
            'cut_short': list(self.cut_short),
            'rejected': self.rejected,
            'refused': self.refused,
            'marginalised': list(self.marginalised),
            'stand_ins': list(self.stand_ins),
            'config': self.config,
        }

    def to_json(self) -> str:
        """effects.json text."""
        return json.dumps(self.to_dict(), indent=1, default=json_default) + '\n'


def json_default(value: Any) -> Any:
    """JSON form of numpy values (``json.dumps(default=...)``)."""
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, (np.floating, np.integer, np.bool_)):
        return value.item()
    raise TypeError(f'{type(value).__name__} is not JSON serialisable')
