"""What an effect's plausibility rule reads: the fit under judgement and the nominal levels.

A value is implausible when it lies outside the plausible range by more than its simultaneous
95 % confidence margin: sqrt(chi^2_k(0.95)) standard errors for a group of k parameters (1.96
for one), so a weakly determined value is not condemned for its noise.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from functools import cached_property
from typing import Any

import numpy as np
from scipy import stats

__all__ = ['PlausibilityFacts', 'Trial', 'Verdict', 'within']

#: (plausible, the reason when not).
Verdict = tuple[bool, str]


@dataclass(frozen=True, eq=False)
class PlausibilityFacts:
    """Nominal torque levels the size rules compare against; (n,) arrays [N*m].

    Attributes:
        rigid_rms: RMS of the URDF rigid-body torque per joint.
        gravity: (N, n) nominal gravity torque along the training motion (for the spring's sign).
        moving_mass_kg: total moving mass of the URDF [kg].
        body_parameters: (bodies, 10) the URDF's inertial parameters (pinocchio's order).
        positions: (2, n) the lowest and highest measured joint angle of the training motion
            [rad] (what an encoder offset may shift within the URDF's limits).
    """

    rigid_rms: np.ndarray
    gravity: np.ndarray
    moving_mass_kg: float
    body_parameters: np.ndarray
    positions: np.ndarray


@dataclass(frozen=True, eq=False)
class Trial:
    """A fitted candidate under judgement.

    Attributes:
        joint: the joint index it sits on (None: robot-wide).
        settings: the settings of its columns.
        theta: (k,) its parameters in physical units.
        covariance: (k, k) covariance of theta (zeros: exact values).
        columns: (N, n, k) its columns along the training motion (unfiltered): the torque it
            adds is columns @ theta [N*m].
    """

    joint: int | None
    settings: Mapping[str, Any]
    theta: np.ndarray
    covariance: np.ndarray
    columns: np.ndarray

    @cached_property
    def margin(self) -> float:
        """Standard errors a value may lie beyond its range: sqrt(chi^2_k(0.95))."""
        return math.sqrt(float(stats.chi2.ppf(0.95, len(self.theta))))

    @cached_property
    def sd(self) -> np.ndarray:
        """(k,) standard errors of theta."""
        out: np.ndarray = np.sqrt(np.clip(np.diag(self.covariance), 0.0, None))
        return out

    def first_within(self, low: float, high: float, unit: str) -> Verdict:
        """Whether the first parameter lies in [low, high] within its margin."""
        return within(float(self.theta[0]), self.margin * float(self.sd[0]), low, high, unit)


def within(value: float, spread: float, low: float, high: float, unit: str) -> Verdict:
    """Whether value +- spread reaches [low, high]; the reason when it does not."""
    if value + spread >= low and value - spread <= high:
        return True, ''
    return False, (
        f'value {value:.4g} +- {spread:.2g} {unit} outside the plausible range '
        f'[{low:.4g}, {high:.4g}]'
    )


@dataclass(frozen=True, eq=False)
class JointMotion:
    """One joint's motion in the excitation, as a testability rule reads it.

    Attributes:
        joint_name: the joint's name (for messages).
        v: (N,) filtered joint velocities [rad/s].
        moving: (N,) where the joint moves (beyond twice the smoothing velocity).
        gear_ratio: the joint's gear ratio.
        cutoff_hz: the label filter's cut-off on the joint [Hz].
        thresholds: the shares the rules require (``DiagnosisConfig``): 'min_slow_fraction',
            'min_below_cutoff_fraction'.
    """

    joint_name: str
    v: np.ndarray
    moving: np.ndarray
    gear_ratio: float
    cutoff_hz: float
    thresholds: Mapping[str, float]


@dataclass(frozen=True)
class CandidateGrid:
    """The settings the diagnosis tries each effect with (``DiagnosisConfig``).

    Attributes:
        smoothing_velocity: v_eps of the friction laws [rad/s].
        stribeck_velocities: Stribeck velocities v_s tried per joint [rad/s].
        cogging_periods: cogging periods per motor turn tried per joint.
        spring_joints: the joints that may carry a balancer (indices).
    """

    smoothing_velocity: float
    stribeck_velocities: tuple[float, ...]
    cogging_periods: tuple[int, ...]
    spring_joints: tuple[int, ...]
