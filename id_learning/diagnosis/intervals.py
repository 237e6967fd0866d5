"""How wide a named effect's intervals are: correlation, datasheet tolerances and aliases."""

from __future__ import annotations

import logging
import math
from collections.abc import Sequence
from dataclasses import replace
from functools import cached_property

import numpy as np

from id_learning.diagnosis.aliases import AliasSet
from id_learning.diagnosis.candidate_set import CandidateSet, log_velocity_of
from id_learning.diagnosis.design import Design, Fit
from id_learning.diagnosis.heldout import time_blocks
from id_learning.diagnosis.problem import ResidualProblem
from id_learning.diagnosis.result import Remainder
from id_learning.physics.terms import EffectSpec, whole_model_form

__all__ = ['ALIAS_ALTERNATIVES', 'HELD_TORQUE_STEPS', 'TOLERANCE_SIGMAS', 'IntervalRule']

_LOG = logging.getLogger(__name__)

#: Alternatives an alias set lists beside the kept effect, the closest mimics first.
ALIAS_ALTERNATIVES = 2
#: Times the reported fit's torque is put in the delay and torque-constant columns and the
#: fit redone (a fixed point: on the twin the second step moves a delay by 0.005 ms).
HELD_TORQUE_STEPS = 2
#: A datasheet value fitted further from its own than this many prior stds (in any direction of
#: its prior) stands in for an effect the model lacks.
TOLERANCE_SIGMAS = 4.0


class IntervalRule:
    """How much wider than the design's covariance an effect's interval must be.

    The design's covariance assumes what the filter leaves of white noise; a remainder
    correlated longer (model-form error, real drives) holds fewer independent samples: the
    long-run variance grows with the correlation time, and so do the intervals. A block
    sandwich over the training part's time holds misfit the remainder shares with an effect's
    columns; the wider of the two sets the interval. The physical parameters are refitted on
    both parts (the held-out part chose the effects; the values use every sample) with the
    datasheet values no effect names free within their tolerances
    (``CandidateSet.datasheet_unknowns``); their intervals hold what the refined Stribeck
    velocities leave unknown too (``CandidateSet.setting_sensitivities``), and what the data
    leave open between an alias set's members and between an effect's forms: the largest move of
    a value when one of the closest alternatives, or another form, stands in for a kept effect,
    weighted by how well that model fits, is added to its covariance, as one more standard
    deviation. The delay and torque-constant
    columns hold the torque of the fit the values come from (``HELD_TORQUE_STEPS``): the rule
    leaves the candidates' and the problem's whole-model columns holding it.
    """

    def __init__(
        self,
        problem: ResidualProblem,
        candidates: CandidateSet,
        design: Design,
        final: Fit,
        remainder: list[Remainder],
        *,
        aliases: Sequence[AliasSet] = (),
    ) -> None:
        self.problem, self.design, self.final = problem, design, final
        self.correlation = np.array([r.correlation_ratio for r in remainder])
        blocks, _ = time_blocks(problem, design.residual(final, 'train'), 'train')
        self.sandwich = replace(final, covariance=design.sandwich_covariance(final, blocks))
        self.unknowns, priors = candidates.datasheet_unknowns(final.groups)
        settings = candidates.setting_sensitivities(design, final)
        self.candidates = candidates
        groups = [*final.groups, *self.unknowns]

        def refit(training: Design) -> None:
            self.base = problem.pooled(training)
            self.marginal_design = self.base.with_priors(priors)
            self.marginal = self.marginal_design.fit(groups)

        refit(candidates.design(design.y, design.n_effective, settings) if settings else design)
        holds = any(whole_model_form(candidates.specs[g]) for g in groups)
        for _ in range(HELD_TORQUE_STEPS if holds else 0):
            # The delay and torque-constant columns hold the torque of the fit they are
            # reported from: with the datasheet values free, a payload's mass or a friction
            # level moves, and a delay read on the final fit's torque rate is another's
            # (twin seed 10 at 600 s: 4.61 ms on it, 4.27 on its own, for 4).
            candidates.hold_torque_of(self.marginal_design, self.marginal)
            refit(candidates.design(design.y, design.n_effective, settings or None))
        # The values and their spread with the refined settings free beside them (linearised:
        # one Gauss-Newton step from the settings refined on the training part).
        self.widened = (
            self.marginal_design.fit([*groups, *settings]) if settings else self.marginal
        )
        self.stand_ins = self._stand_ins()
        # (Where a datasheet value stands in, the parameters are the refit model's: no swaps.)
        self.swaps = [
            self._swapped(alias.representative, member)
            for alias in ([] if self.stand_ins else aliases)
            for member in alias.alternatives()[:ALIAS_ALTERNATIVES]
        ]
        # A kept effect's other forms with parameters like its own (friction growing with
        # gravity or with the link torque): what the data leave open between them.
        self.form_swaps = {
            label: [(form, *self._swapped(label, form)) for form in candidates.forms_of(label)]
            for label in ([] if self.stand_ins else final.groups)
        }
        if self.stand_ins:
            _LOG.warning(
                'datasheet values moved far outside their tolerances (%s): they stand in for '
                "an effect the model lacks; parameters are the refit model's, with intervals "
                'as wide as the tolerances leave them',
                ', '.join(self.stand_ins),
            )

    def _stand_ins(self) -> list[str]:
        """The unknowns moved more than ``TOLERANCE_SIGMAS`` prior stds in any prior direction."""
        design, fit = self.marginal_design, self.marginal
        out = []
        for label in self.unknowns:
            block = design.slices[label]
            precision = design.prior[block, block]
            if not precision.any():
                continue
            whitened = np.linalg.cholesky(precision).T @ design.coefficients(fit, label)
            if np.max(np.abs(whitened)) > TOLERANCE_SIGMAS:
                out.append(label)
        return out

    def _swapped(self, kept: str, alternative: str) -> tuple[Design, Fit]:
        """The marginal refit with an alias set's alternative in its kept effect's place.

        The datasheet values are those the swapped model leaves unnamed: a kept torque constant
        or rotor inertia swapped out is free within its tolerance again, an alternative that is
        one is free of it.
        """
        groups = [alternative if g == kept else g for g in self.final.groups]
        unknowns, priors = self.candidates.datasheet_unknowns(groups)
        design = self.base.with_priors(priors)
        return design, design.fit([*groups, *unknowns])

    def model_spread(self, label: str, covariance: np.ndarray) -> np.ndarray:
        """(k, k) w d d^T, an effect's largest weighted move (against ``covariance``).

        d: the move when one of an alias set's closest alternatives stands in for its kept
        effect, or the move to another form of it (``CandidateSet.forms_of``); w: that model's
        Akaike weight against the kept one, capped at 1. An alternative
        that fits as well moves the values as far as the data leave open; one that fits clearly
        worse is no model the data allow (a payload beside the link parameters: their CAD prior
        leaves the payload's torque to the payload, and an alternative in its place fitted 9 %
        worse, yet moved every torque-unit value by tens of %). Zero without aliases.
        """
        design = self.marginal_design
        value = design.physical(self.marginal, label)
        precision = np.linalg.pinv(covariance)
        moves = [
            math.sqrt(self.akaike_weight(fit)) * (d.physical(fit, label) - value)
            for d, fit in self.swaps
            if label in fit.groups
        ] + [
            math.sqrt(self.akaike_weight(fit)) * (d.physical(fit, form) - value)
            for form, d, fit in self.form_swaps.get(label, [])
        ]
        if not moves:
            return np.zeros_like(covariance)
        worst = max(moves, key=lambda d: float(d @ precision @ d))
        return np.outer(worst, worst)

    def akaike_weight(self, fit: Fit) -> float:
        """exp(-AIC difference / 2) of a refit against the kept marginal one, at most 1.

        The deviance in the kept model's residual variance per effective sample (over both
        parts), each effective parameter more charged 2.
        """
        kept = self.marginal
        variance = self.marginal_design.residual_variance(kept.rss['train'], kept.rank)
        variance = max(variance, 1e-300)
        aic = (fit.rss['train'] - kept.rss['train']) / variance + 2.0 * (fit.rank - kept.rank)
        return math.exp(-0.5 * max(aic, 0.0))

    def parameters(self, label: str, inflation: float) -> tuple[np.ndarray, np.ndarray]:
        """An effect's physical coefficients, datasheet values marginalised; their covariance.

        Where a datasheet value stands in for a missing effect the marginal refit explains that
        effect, not the tolerance: the refit model's values then, with the tolerances' spread.
        """
        design = self.marginal_design
        if not self.stand_ins:
            covariance = inflation * design.physical_covariance(self.widened, label)
            value = design.physical(self.widened, label)
            return value, covariance + self.model_spread(label, covariance)
        whole, final = self._refit_final
        residual_variance = whole.residual_variance(final.rss['train'], final.rank)
        spread = design.physical_covariance(self.marginal, label, noise_only=True)
        return whole.physical(final, label), inflation * spread * residual_variance

    @cached_property
    def _refit_final(self) -> tuple[Design, Fit]:
        """The final model refitted on both parts: the values where a datasheet value stands in."""
        whole = self.problem.pooled(self.design)
        return whole, whole.fit(self.final.groups)

    def settings(self, label: str, inflation: float, t_crit: float) -> dict[str, list[float]]:
        """A refined setting read again on every sample: name -> [value, low, high].

        A Stribeck velocity is refined on the training part; beside the values' fit its log
        moves once more (``widened``), within an interval that follows from that fit. Empty
        where none is free, and where a datasheet value stands in (the refined value stands).
        """
        key = log_velocity_of(label)
        if self.stand_ins or key not in self.widened.groups:
            return {}
        design = self.marginal_design
        step = float(design.physical(self.widened, key)[0])
        variance = inflation * float(design.physical_covariance(self.widened, key)[0, 0])
        half = t_crit * math.sqrt(max(variance, 0.0))
        velocity = float(self.candidates.specs[label].settings['velocity'])
        return {'velocity': [velocity * math.exp(step + d) for d in (0.0, -half, half)]}

    def inflation(self, label: str, spec: EffectSpec) -> float:
        """How much wider than the design's covariance: correlation time or block sandwich."""
        joints = slice(None) if spec.joint is None else [spec.joint]
        model = np.clip(np.diag(self.design.physical_covariance(self.final, label)), 1e-300, None)
        block = np.diag(self.design.physical_covariance(self.sandwich, label))
        return max(1.0, float(np.max(self.correlation[joints])), float(np.max(block / model)))
