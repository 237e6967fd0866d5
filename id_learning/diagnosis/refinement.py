"""Tuning a selected effect's nonlinear setting: Stribeck velocity, balancer geometry, payload.

A setting enters its columns nonlinearly; it is tuned on the training part with the other
selected effects kept free beside it, under the priors every fit over them holds.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
from scipy import optimize

from id_learning.diagnosis.candidates import PAYLOAD_COM_LIMIT_M
from id_learning.diagnosis.problem import ResidualProblem
from id_learning.diagnosis.selection import Design, Fit
from id_learning.physics.balancer import BALANCER_PHASES, BALANCER_RATIOS
from id_learning.physics.terms import EffectSpec

__all__ = ['refine_setting']


def refine_setting(
    problem: ResidualProblem,
    others: dict[str, dict[str, np.ndarray]],
    spec: EffectSpec,
    design_of: Callable[[dict[str, dict[str, np.ndarray]]], Design],
) -> EffectSpec | None:
    """Tune a selected effect's nonlinear setting on the training part, the others kept.

    ``design_of``: the regression over some columns, with the priors every fit over them holds
    (``CandidateSet.design_over``).
    """

    def rss_of(candidate: EffectSpec) -> tuple[float, Design, Fit]:
        cols, _, _ = problem.columns(candidate)
        small = design_of({**others, candidate.label: cols})
        fit = small.fit([*others, candidate.label])
        return fit.rss['train'], small, fit

    if spec.name == 'stribeck_friction':
        start = float(spec.settings['velocity'])

        def objective(log_vs: float) -> float:
            return rss_of(spec.replace_settings(velocity=float(math.exp(log_vs))))[0]

        best = optimize.minimize_scalar(
            objective,
            bounds=(math.log(start / 2.5), math.log(start * 2.5)),
            method='bounded',
            options={'xatol': 0.02},
        )
        if best.fun < rss_of(spec)[0]:
            return spec.replace_settings(velocity=round(float(math.exp(best.x)), 5))
        return None
    if spec.name == 'gravity_spring' and 'ratio' in spec.settings:
        # The balancer's geometry: the best of a grid of arm ratios and phases, then refined
        # together (an encoder zero error shifts the phase by milliradians). The ratio stays in
        # the grid's range: towards 0 the three columns merge into sin and sin 2 of the angle,
        # an ill-posed pair that fits the training part's noise, not a balancer.
        low, high = min(BALANCER_RATIOS), max(BALANCER_RATIOS)

        def spring_rss(geometry: np.ndarray) -> float:
            ratio = float(np.clip(geometry[0], low, high))
            return rss_of(spec.replace_settings(ratio=ratio, phase_rad=float(geometry[1])))[0]

        grid = [np.array([r, p]) for r in BALANCER_RATIOS for p in BALANCER_PHASES]
        geometry = min(grid, key=spring_rss)
        best = optimize.minimize(
            spring_rss,
            geometry,
            method='Nelder-Mead',
            options={
                'xatol': 1e-4,
                'fatol': 1e-9,
                'initial_simplex': geometry + np.array([[0.0, 0.0], [0.05, 0.0], [0.0, 0.05]]),
            },
        )
        if best.fun < rss_of(spec)[0]:
            ratio = round(float(np.clip(best.x[0], low, high)), 5)
            return spec.replace_settings(ratio=ratio, phase_rad=round(float(best.x[1]), 5))
        return None
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
