"""Settings of the diagnosis: which effects to try, how strict to be, how to preprocess."""

from __future__ import annotations

from dataclasses import dataclass, field, fields
from typing import Any

from id_learning.dataset.preprocess import PreprocessConfig
from id_learning.errors import ConfigError
from id_learning.physics.terms import EFFECT_NAMES

__all__ = ['DiagnosisConfig']


@dataclass(frozen=True)
class DiagnosisConfig:
    """How the diagnosis searches, tests and reports.

    Attributes:
        preprocess: the study's preprocessing (target, filter order, cut-offs, 70/30 split).
        effects: candidate effects to try, by the twin's stable names; the others are skipped.
        significance: family-wise false-alarm rate of one selection step; divided among the
            candidates of the step (Bonferroni).
        alias_significance: a replacement that is worse at this level is no alias.
        noise_significance: the residual is consistent with the noise level unless its
            variance test rejects at this level.
        noise_tolerance: the residual is also consistent while its RMS stays below this multiple
            of the estimated noise level (the estimate is good to a few per cent).
        structure_correlation_ratio: a remainder above the noise whose correlation time exceeds
            the filtered noise's by this factor is structured.
        max_effects: most effects one diagnosis adds.
        smoothing_velocity: v_eps of tanh(v / v_eps) in the friction columns [rad/s], where
            ``smoothing_velocities`` is empty.
        smoothing_velocities: v_eps tried per joint; the one that fits the recording best is
            used on that joint (a drive's friction may turn through zero speed more sharply or
            more softly than any one value).
        viscous_exponents: exponents delta of a viscous law b sign(v) |v|^delta tried per joint
            beside the linear one; one is used only where it fits clearly better.
        standstill_velocity: a joint whose fitting-input speed stays below this [rad/s] for
            ``standstill_min_s`` or longer rests; the torque its friction holds there is free
            (``standstill``). 0 turns this off.
        standstill_min_s: shortest rest [s].
        stribeck_velocities: Stribeck velocities v_s tried [rad/s]; the best is refined.
        cogging_periods: cogging periods per motor turn tried.
        gravity_spring_joints: joints that may carry a balancer spring; None: every joint whose
            nominal gravity torque sweeps at least ``gravity_spring_min_share`` of its torque
            limit over the recording.
        gravity_spring_min_share: see ``gravity_spring_joints``. A balancer's torque has the
            physical form of ``physics.balancer``; its geometry is refined once selected.
        edge_trim_s: seconds dropped at each recording end and after the train/test boundary,
            where the zero-phase filter's start-up transient lives; None: 1 / lowest cut-off.
        min_moving_fraction: a friction term on a joint needs this share of moving samples.
        min_slow_fraction: Stribeck needs this share of moving samples slower than v_s.
        min_below_cutoff_fraction: cogging needs this share of moving samples whose cogging
            frequency lies below the cut-off.
        min_retention: an effect is untestable when the filter keeps less than this share of
            its regressors' energy (its signature lies above the cut-off).
        min_effective_samples: refuse recordings with fewer effective samples per part.
        max_seconds: the diagnosis's time budget [s] (None: none). Past 60 % of it no further
            selection step, resumption or special case starts, leaving the rest for what always
            runs (the springs' held-out check, the refit, the intervals); the result says what
            was cut short (``DiagnosisResult.cut_short``).
    """

    preprocess: PreprocessConfig = field(default_factory=PreprocessConfig)
    effects: tuple[str, ...] = EFFECT_NAMES
    significance: float = 0.01
    alias_significance: float = 0.01
    noise_significance: float = 0.001
    noise_tolerance: float = 1.25
    structure_correlation_ratio: float = 3.0
    max_effects: int = 60
    smoothing_velocity: float = 0.005
    smoothing_velocities: tuple[float, ...] = (0.0005, 0.001, 0.002, 0.005, 0.01, 0.02)
    viscous_exponents: tuple[float, ...] = (0.6, 0.8, 1.2, 1.4, 1.7)
    standstill_velocity: float = 0.002
    standstill_min_s: float = 0.1
    stribeck_velocities: tuple[float, ...] = (0.01, 0.02, 0.03, 0.05, 0.08)
    cogging_periods: tuple[int, ...] = (6, 12, 18, 24, 36)
    gravity_spring_joints: tuple[str, ...] | None = None
    gravity_spring_min_share: float = 0.05
    edge_trim_s: float | None = None
    min_moving_fraction: float = 0.2
    min_slow_fraction: float = 0.02
    min_below_cutoff_fraction: float = 0.2
    min_retention: float = 0.1
    min_effective_samples: float = 10.0
    max_seconds: float | None = None

    def __post_init__(self) -> None:
        """Check names and ranges, naming the key."""
        if not self.effects:  # an empty selection is no request for the default set
            raise ConfigError(
                f'diagnosis.effects: empty; name at least one of {list(EFFECT_NAMES)}, or leave '
                'it out for all'
            )
        unknown = sorted(set(self.effects) - set(EFFECT_NAMES))
        if unknown:
            raise ConfigError(
                f'diagnosis.effects: unknown effect(s) {unknown}; known: {list(EFFECT_NAMES)}'
            )
        ranges: dict[str, tuple[float, float]] = {
            'significance': (1e-9, 0.5),
            'alias_significance': (1e-9, 0.5),
            'noise_significance': (1e-12, 0.5),
            'noise_tolerance': (1.0, 10.0),
            'structure_correlation_ratio': (1.0, 1e3),
            'max_effects': (0, 100),
            'smoothing_velocity': (1e-6, 1.0),
            'standstill_velocity': (0.0, 1.0),
            'standstill_min_s': (0.0, 1e3),
            'gravity_spring_min_share': (0.0, 1.0),
            'min_moving_fraction': (0.0, 1.0),
            'min_slow_fraction': (0.0, 1.0),
            'min_below_cutoff_fraction': (0.0, 1.0),
            'min_retention': (0.0, 1.0),
            'min_effective_samples': (2.0, 1e9),
        }
        for key, (low, high) in ranges.items():
            value = getattr(self, key)
            if not low <= value <= high:
                raise ConfigError(
                    f'diagnosis.{key}: value {value!r} is out of range [{low:g}, {high:g}]'
                )
        if self.max_seconds is not None and not self.max_seconds > 0:
            raise ConfigError(f'diagnosis.max_seconds: must be > 0, got {self.max_seconds}')
        if self.edge_trim_s is not None and self.edge_trim_s < 0:
            raise ConfigError(f'diagnosis.edge_trim_s: must be >= 0, got {self.edge_trim_s}')
        if self.viscous_exponents and not all(0.2 <= d <= 3.0 for d in self.viscous_exponents):
            raise ConfigError(
                'diagnosis.viscous_exponents: need exponents in [0.2, 3], got '
                f'{self.viscous_exponents!r}'
            )
        if self.smoothing_velocities and min(self.smoothing_velocities) <= 0:
            raise ConfigError(
                'diagnosis.smoothing_velocities: need positive velocities [rad/s], got '
                f'{self.smoothing_velocities!r}'
            )
        if not self.stribeck_velocities or min(self.stribeck_velocities) <= 0:
            raise ConfigError(
                'diagnosis.stribeck_velocities: need positive velocities [rad/s], got '
                f'{self.stribeck_velocities!r}'
            )
        if not self.cogging_periods or min(self.cogging_periods) < 1:
            raise ConfigError(
                f'diagnosis.cogging_periods: need positive integers, got {self.cogging_periods!r}'
            )

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready settings."""
        out: dict[str, Any] = {}
        for item in fields(self):
            value = getattr(self, item.name)
            if isinstance(value, PreprocessConfig):
                value = {f.name: getattr(value, f.name) for f in fields(value)}
            out[item.name] = list(value) if isinstance(value, tuple) else value
        return out
