"""Tuning a selected effect's nonlinear setting: Stribeck velocity, balancer geometry, payload.

A setting enters its columns nonlinearly; it is tuned on the training part with the other
selected effects kept free beside it, under the priors every fit over them holds.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from id_learning.diagnosis.candidates import PAYLOAD_COM_LIMIT_M
from id_learning.diagnosis.design import Design, Fit
from id_learning.diagnosis.problem import ResidualProblem
from id_learning.physics.balancer import BALANCER_PHASES, BALANCER_RATIOS
from id_learning.physics.terms import EffectSpec

__all__ = ['refine_setting']


#: Rounds of the shrinking grids that refine a setting, each a third as wide as the one before.
_GRID_ROUNDS = 6


def refine_setting(
    problem: ResidualProblem,
    others: dict[str, dict[str, np.ndarray]],
    spec: EffectSpec,
    design_of: Callable[[dict[str, dict[str, np.ndarray]]], Design],
) -> EffectSpec | None:
    """Tune a selected effect's nonlinear setting on the training part, the others kept.

    ``design_of``: the regression over some columns, with the priors every fit over them holds
    (``CandidateSet.design_over``). A Stribeck velocity and a balancer's geometry are chosen on
    a coarse grid, then on grids shrinking about the best point, each point a closed-form refit
    of every selected effect (``Design.rss_with``: the effect's new columns against the others'
    fixed ones), so no derivative-free search runs here.
    """

    def rss_of(candidate: EffectSpec) -> tuple[float, Design, Fit]:
        cols, _, _ = problem.columns(candidate)
        small = design_of({**others, candidate.label: cols})
        fit = small.fit([*others, candidate.label])
        return fit.rss['train'], small, fit

    if spec.name in ('stribeck_friction', 'gravity_spring') and (
        spec.name == 'stribeck_friction' or 'ratio' in spec.settings
    ):
        start_rss, base, _ = rss_of(spec)
        groups = [*others, spec.label]

        def train_rss(candidate: EffectSpec) -> float:
            return base.rss_with(groups, spec.label, problem.columns(candidate)[0])['train']

        if spec.name == 'stribeck_friction':
            start = math.log(float(spec.settings['velocity']))

            def at_velocity(point: np.ndarray) -> EffectSpec:
                return spec.replace_settings(velocity=round(float(math.exp(point[0])), 5))

            # Within a factor 2.5 of the selection's candidate velocity.
            span = math.log(2.5)
            best, value = _grid_search(
                lambda p: train_rss(at_velocity(p)),
                [np.array([start + span * k / 4]) for k in range(-4, 5)],
                low=np.array([start - span]),
                high=np.array([start + span]),
                steps=np.array([span / 8]),
            )
            return at_velocity(best) if value < start_rss else None
        # The balancer's geometry: the best of a grid of arm ratios and phases, then refined
        # together (an encoder zero error shifts the phase by milliradians). The ratio stays in
        # the grid's range: towards 0 the three columns merge into sin and sin 2 of the angle,
        # an ill-posed pair that fits the training part's noise, not a balancer.
        low, high = min(BALANCER_RATIOS), max(BALANCER_RATIOS)

        def at_geometry(point: np.ndarray) -> EffectSpec:
            ratio = round(float(np.clip(point[0], low, high)), 5)
            return spec.replace_settings(ratio=ratio, phase_rad=round(float(point[1]), 5))

        best, value = _grid_search(
            lambda p: train_rss(at_geometry(p)),
            [np.array([r, p]) for r in BALANCER_RATIOS for p in BALANCER_PHASES],
            low=np.array([low, -np.inf]),
            high=np.array([high, np.inf]),
            steps=np.array([0.05, 0.05]),
        )
        return at_geometry(best) if value < start_rss else None
    if spec.name == 'payload_mass':
        current = spec
        for _ in range(6):
            _, small, fit = rss_of(current)
            theta = small.physical(fit, current.label)
            if theta[0] <= 0:
                return None
            com = (np.asarray(theta[1:4]) / theta[0]).tolist()
            if np.allclose(com, current.settings['com_guess_m'], atol=1e-4):
                break
            if np.linalg.norm(com) > PAYLOAD_COM_LIMIT_M:
                # A weakly determined mass runs away: a centre of mass further out gives the
                # mass column more inertia, the fit a smaller mass, the next centre further out.
                break
            current = current.replace_settings(com_guess_m=com)
        # A body with its own rotational inertia (a spindle, a gripper) when the data show it:
        # six more coefficients must earn their BIC.
        if not current.settings.get('inertia'):
            point, small, _ = rss_of(current)
            full = rss_of(current.replace_settings(inertia=True))[0]
            n = small.n_eff_train
            if full > 0 and n * math.log(point / full) > 6 * math.log(n) + 10.0:
                current = current.replace_settings(inertia=True)
        return current
    return None


def _grid_search(
    objective: Callable[[np.ndarray], float],
    coarse: list[np.ndarray],
    *,
    low: np.ndarray,
    high: np.ndarray,
    steps: np.ndarray,
) -> tuple[np.ndarray, float]:
    """The best point of a coarse grid, then of grids about it that shrink, within bounds.

    Each round tries the 3^d points at -step, 0, +step about the best so far; the step is
    divided by 3 once the centre stays best (a round that moves the centre is repeated there,
    at most twice in a row). After ``_GRID_ROUNDS`` shrinks the point is known to steps / 729.
    """
    values = [objective(point) for point in coarse]
    best = np.asarray(coarse[int(np.argmin(values))], dtype=float)
    value = float(min(values))
    step = np.asarray(steps, dtype=float)
    offsets = np.array(np.meshgrid(*[[-1.0, 0.0, 1.0]] * len(best))).reshape(len(best), -1).T
    shrinks, moves = 0, 0
    while shrinks < _GRID_ROUNDS:
        centre = best
        for offset in offsets:
            if offset.any():
                point = np.clip(centre + offset * step, low, high)
                trial = objective(point)
                if trial < value:
                    best, value = point, trial
        if best is centre or moves >= 2:
            step, shrinks, moves = step / 3.0, shrinks + 1, 0
        else:
            moves += 1
    return best, value
