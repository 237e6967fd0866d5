"""What one physical effect is, as the physics layer sees it: its parameters, its columns.

An effect adds X @ theta [N*m] to the joint torques, with X (N, n, k) its regressor columns built
from the nominal model's quantities and theta its k parameters in physical units. Each effect is
one object (``Effect``) that knows its own form; nothing outside ``physics.effects`` asks an
effect's name to decide what to do.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

from id_learning.physics.effects.judgement import (
    CandidateGrid,
    JointMotion,
    PlausibilityFacts,
    Trial,
    Verdict,
)
from id_learning.physics.nominal import NominalModel, NominalQuantities

__all__ = ['Effect', 'FittedTerm', 'JointEffect', 'Parameter', 'SettingAxis', 'entry']


@dataclass(frozen=True)
class Parameter:
    """One column's parameter: its name and SI unit ('1' for a ratio)."""

    name: str
    unit: str


@dataclass(frozen=True)
class SettingAxis:
    """One nonlinear setting of a selected effect, tuned on the training part.

    The search runs in its own coordinate (the log of the value when ``log``): the coarse
    ``grid``, then grids that shrink about the best point, kept within [low, high], to
    ``step`` / 729.
    """

    name: str
    grid: tuple[float, ...]
    low: float
    high: float
    step: float
    log: bool = False

    def value(self, point: float) -> float:
        """The setting at a point of the search (5 decimals: labels stay readable)."""
        x = float(np.clip(point, self.low, self.high))
        return round(math.exp(x) if self.log else x, 5)


def entry(name: str, value: float, low: float, high: float, unit: str) -> dict[str, Any]:
    """One described parameter: name, value, its interval (low, high, ordered) and unit."""
    return {
        'name': name,
        'value': float(value),
        'ci': [float(min(low, high)), float(max(low, high))],
        'unit': unit,
    }


class Effect:
    """One physical effect the nominal model lacks (subclasses set the class attributes).

    Attributes:
        name: the stable name the twin, the diagnosis and effects.json share.
        parameters: one per column, in column order (k of them; an effect whose column count
            depends on its settings lists the first and describes the rest itself).
        robot_wide: sits on no single joint (a payload, a delay, the link parameters).
        link_side: changes the torque the links put on the joints (the load of load-dependent
            friction), as against the drive's own terms.
        needs_regressor: its columns read the inertial-parameter regressor.
        whole_model_key: the setting that puts it in the whole model's form (it then acts on
            the whole delivered torque, not only the URDF's), or None.
        special_case_of: the more general effect it is a case of (the same physics with fewer
            columns: a payload or a rotor is a mass distribution the links' parameters can also
            take); where it explains the data it is named, not the general one (parsimony).
        claims_hardware: naming it claims hardware the robot may not have (a balancer): it
            must hold on held-out time and gives way to an alias that claims none.
        stands_in_for_hardware: claims no hardware and may take the place of one that does,
            when the data cannot tell them apart.
        friction_shaped: one of a joint's friction laws, which share its curve's shape (the
            smoothing velocity, a curved viscous law).
        switching: switches with the direction of motion: its filtered signature is judged
            on the smooth motion.
        exclusive_variants: two of its candidates on one joint never enter together.
        reads_link_torque: its columns read the link torque (load-dependent friction).
        needs_motion: only motion shows it (friction, cogging, inertia): its joint must move.
        needs_both_directions: its sign flips with the direction: its joint must move both ways.
        motor_side_only: exists in tau_u from currents only, not in a torque measured after the
            gear.
        scales_the_label: an error of the label's gain (the torque constant): in its whole
            model's form it scales everything the drive delivers.
        delays_the_label: a delay of the label behind the motion: in its whole model's form
            it holds back every other term.
        label_offset: a constant the current reading adds (a sensor offset): no gain scales
            it and no delay holds it back.
        hump: a low-speed hump of the friction curve, which a softer turn through zero speed
            or a curved viscous law partly makes up (its setting, 'velocity', is judged beside
            them).
        fit_sets_settings: its settings follow from its own fitted values
            (``settings_from_fit``: a payload's centre of mass from its first moments).
        law: the short name of its friction law in an identified model ('viscous', ...);
            '' for an effect that is no friction law (``law_column``).
        datasheet_value: a datasheet or CAD value the nominal model takes as exact; unnamed,
            it is estimated free within its tolerance (``prior_precision``), which widens the
            other parameters' intervals by what it leaves unknown.
    """

    name: ClassVar[str] = ''
    parameters: ClassVar[tuple[Parameter, ...]] = ()
    robot_wide: ClassVar[bool] = False
    link_side: ClassVar[bool] = False
    needs_regressor: ClassVar[bool] = False
    whole_model_key: ClassVar[str | None] = None
    special_case_of: ClassVar[str | None] = None
    claims_hardware: ClassVar[bool] = False
    stands_in_for_hardware: ClassVar[bool] = False
    friction_shaped: ClassVar[bool] = False
    switching: ClassVar[bool] = False
    exclusive_variants: ClassVar[bool] = False
    reads_link_torque: ClassVar[bool] = False
    needs_motion: ClassVar[bool] = False
    needs_both_directions: ClassVar[bool] = False
    motor_side_only: ClassVar[bool] = False
    scales_the_label: ClassVar[bool] = False
    delays_the_label: ClassVar[bool] = False
    label_offset: ClassVar[bool] = False
    hump: ClassVar[bool] = False
    fit_sets_settings: ClassVar[bool] = False
    datasheet_value: ClassVar[bool] = False
    law: ClassVar[str] = ''

    def candidates(
        self, model: NominalModel, grid: CandidateGrid
    ) -> list[tuple[int | None, dict[str, Any]]]:
        """(joint index or None, settings) of each candidate the diagnosis tries.

        By default one per joint with no settings, or one for the robot if robot-wide.
        """
        del grid
        if self.robot_wide:
            return [(None, {})]
        return [(j, {}) for j in range(model.robot.n_joints)]

    def label_parts(self, settings: Mapping[str, Any]) -> list[str]:
        """What tells this effect's candidates apart in a label, besides the joint."""
        del settings
        return []

    def columns(
        self,
        quantities: NominalQuantities,
        joint: int | None,
        settings: Mapping[str, Any],
        model: NominalModel,
    ) -> np.ndarray:
        """(N, n, k) columns along the quantities: the effect adds columns @ theta [N*m]."""
        raise NotImplementedError(self.name)

    def needs_derivatives(self, settings: Mapping[str, Any]) -> bool:
        """Whether its columns read d tau / d q, d tau / d v or M(q)."""
        del settings
        return False

    def is_whole_model(self, settings: Mapping[str, Any]) -> bool:
        """Whether these settings put it in the whole model's form (``whole_model_key``)."""
        key = self.whole_model_key
        return key is not None and settings.get(key) == 'model'

    def whole_model_settings(self) -> dict[str, str]:
        """The settings of its whole model's form.

        Raises:
            ValueError: it has no such form.
        """
        if self.whole_model_key is None:
            raise ValueError(f'{self.name} has no whole-model form')
        return {self.whole_model_key: 'model'}

    def linearised_about(self, settings: Mapping[str, Any]) -> float:
        """The value its column is taken about (a delay's last estimate [s]); 0: none."""
        del settings
        return 0.0

    def uses_model_load(self, settings: Mapping[str, Any]) -> bool:
        """Whether it grows with the whole model's link torque (not the URDF's alone)."""
        del settings
        return False

    def needs_gravity(self, settings: Mapping[str, Any]) -> bool:
        """Whether its columns read the URDF's gravity torque (``NominalQuantities``)."""
        del settings
        return False

    def model_load_settings(self, settings: Mapping[str, Any]) -> dict[str, Any] | None:
        """Its settings growing with the whole model's link torque; None: no such form."""
        del settings
        return None

    def plausibility(self, trial: Trial, model: NominalModel, facts: PlausibilityFacts) -> Verdict:
        """Whether a fitted value is physically plausible; the reason when not (``judgement``)."""
        raise NotImplementedError(self.name)

    def reshaped_settings(
        self, settings: Mapping[str, Any], smoothing_velocity: float, exponent: float
    ) -> dict[str, Any]:
        """Its settings in a joint's friction curve shape (v_eps, viscous exponent)."""
        del exponent
        return {**settings, 'smoothing_velocity': smoothing_velocity}

    def excitation_problem(self, settings: Mapping[str, Any], motion: JointMotion) -> str:
        """Why this joint's motion cannot show the effect in these settings; '' if it can."""
        del settings, motion
        return ''

    def plausible_bound(self, joint: int | None, model: NominalModel) -> float | None:
        """The largest plausible size of a one-parameter effect (to judge what is detectable)."""
        del joint, model
        return None

    def law_column(
        self, v: np.ndarray, load: np.ndarray, smoothing_velocity: float, velocity: Any
    ) -> np.ndarray:
        """Its friction law's column per unit coefficient, as an identified model fits it.

        v: joint velocities [rad/s]; load: the link torque the gear transmits [N*m]; velocity:
        the hump's velocity per joint [rad/s] (arrays broadcast over joints).
        """
        raise NotImplementedError(f'{self.name} is no friction law')

    def tuned_settings(self, settings: Mapping[str, Any]) -> tuple[SettingAxis, ...]:
        """The nonlinear settings the diagnosis tunes once the effect is selected; () if none."""
        del settings
        return ()

    def settings_from_fit(
        self, theta: np.ndarray, settings: Mapping[str, Any]
    ) -> dict[str, Any] | None:
        """The settings its fitted values imply (``fit_sets_settings``).

        The same when they have settled; None when the fit gives none (a payload of no mass).
        """
        del theta
        return dict(settings)

    def richer_form(self, settings: Mapping[str, Any]) -> tuple[dict[str, Any], int] | None:
        """Its settings with more columns the data may call for, and how many it adds."""
        del settings
        return None

    def prior_precision(
        self,
        joint: int | None,
        settings: Mapping[str, Any],
        model: NominalModel,
        *,
        as_datasheet: bool,
    ) -> np.ndarray | None:
        """(k, k) prior precision of its coefficients (physical units), or None: none.

        ``as_datasheet``: asked for an unnamed datasheet value estimated within its tolerance
        (``datasheet_value``), not for a candidate the diagnosis may name.
        """
        del joint, settings, model, as_datasheet
        return None

    def tolerance_text(self) -> str:
        """The report's words for the tolerance a datasheet value is free within."""
        return ''

    def describe(
        self,
        fit: FittedTerm,
        model: NominalModel,
    ) -> list[dict[str, Any]]:
        """Its physical parameters with intervals, in the twin's terms where one exists.

        One dict per parameter: name, value, ci (low, high), unit. By default one per column,
        as ``parameters`` names them.
        """
        del model
        lo, hi = fit.low, fit.high
        return [
            entry(p.name, fit.theta[k], lo[k], hi[k], p.unit)
            for k, p in enumerate(self.parameters[: len(fit.theta)])
        ]


@dataclass(frozen=True, eq=False)
class FittedTerm:
    """One fitted term of an effect, as ``Effect.describe`` reads it.

    Attributes:
        joint: the joint index it sits on (None: robot-wide).
        settings: the settings of its columns.
        theta: (k,) fitted column coefficients in physical units.
        half_width: (k,) half widths of their confidence intervals (same units).
        interval_covariance: (k, k) covariance of theta scaled so that the square roots of its
            diagonal are ``half_width``; for parameters that mix coefficients, or None.
        refined: settings estimated again beside the fit, name -> [value, low, high] (a
            Stribeck velocity); a setting not there is taken as exact.
    """

    joint: int | None
    settings: Mapping[str, Any]
    theta: np.ndarray
    half_width: np.ndarray
    interval_covariance: np.ndarray | None = None
    refined: Mapping[str, list[float]] | None = None

    @property
    def low(self) -> np.ndarray:
        """Lower ends of the coefficients' intervals."""
        out: np.ndarray = self.theta - self.half_width
        return out

    @property
    def high(self) -> np.ndarray:
        """Upper ends of the coefficients' intervals."""
        out: np.ndarray = self.theta + self.half_width
        return out


JointColumns = tuple[np.ndarray, ...]


class JointEffect(Effect):
    """An effect on one joint that acts on that joint alone.

    Its columns are a function of the quantities at joint index j, written with numpy
    broadcasting, so j may also be an index array with settings arrays of its length: all joints
    of an effect at once (how a saved model folds them).
    """

    def joint_columns(
        self,
        quantities: NominalQuantities,
        joint: Any,
        settings: Mapping[str, Any],
        model: NominalModel,
    ) -> JointColumns:
        """Its k columns at joint index (or index array) ``joint``, (N,) or (N, m) each."""
        raise NotImplementedError(self.name)

    def columns(
        self,
        quantities: NominalQuantities,
        joint: int | None,
        settings: Mapping[str, Any],
        model: NominalModel,
    ) -> np.ndarray:
        """(N, n, k): its joint columns on its joint's rows, zero on the others."""
        if joint is None:
            raise ValueError(f'{self.name} needs a joint')
        parts = self.joint_columns(quantities, joint, settings, model)
        out = np.zeros((*quantities.q.shape, len(parts)))
        for c, column in enumerate(parts):
            out[:, joint, c] = column
        return out
