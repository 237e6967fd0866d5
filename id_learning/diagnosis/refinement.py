"""Tuning a selected effect's nonlinear settings (``Effect.tuned_settings`` and the like).

A setting enters its columns nonlinearly (a Stribeck velocity, a balancer's geometry, a
payload's centre of mass); it is tuned on the training part with the other selected effects
kept free beside it, under the priors every fit over them holds.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Callable

import numpy as np

from id_learning.diagnosis.design import Design, Fit
from id_learning.diagnosis.problem import ResidualProblem
from id_learning.physics.effects import effect
from id_learning.physics.terms import EffectSpec

__all__ = ['FORM_SWITCH_SHARE', 'choose_form', 'refine_setting']


#: How much less held-out error another form must leave to take the selected one's place: a
#: twin's wrist friction growing with the link torque lost to gravity's by 1.3 %, its
#: coefficient then read 5.7 times too high.
FORM_SWITCH_SHARE = 0.02
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
    (``CandidateSet.design_over``). Settings the effect tunes (``Effect.tuned_settings``) are
    chosen on a coarse grid, then on grids shrinking about the best point, each point a
    closed-form refit of every selected effect (``Design.rss_with``: the effect's new columns
    against the others' fixed ones), so no derivative-free search runs here. Settings that
    follow from its own fit (``Effect.settings_from_fit``) are refitted until they settle. None:
    nothing to tune, or nothing better.
    """

    def rss_of(candidate: EffectSpec) -> tuple[float, Design, Fit]:
        cols, _, _ = problem.columns(candidate)
        small = design_of({**others, candidate.label: cols})
        fit = small.fit([*others, candidate.label])
        return fit.rss['train'], small, fit

    item = effect(spec.name)
    axes = item.tuned_settings(spec.settings)
    if axes:
        start_rss, base, _ = rss_of(spec)
        groups = [*others, spec.label]

        def at(point: np.ndarray) -> EffectSpec:
            return spec.replace_settings(
                **{axis.name: axis.value(x) for axis, x in zip(axes, point, strict=True)}
            )

        def train_rss(point: np.ndarray) -> float:
            return base.rss_with(groups, spec.label, problem.columns(at(point))[0])['train']

        best, value = _grid_search(
            train_rss,
            [np.array(point) for point in itertools.product(*(axis.grid for axis in axes))],
            low=np.array([axis.low for axis in axes]),
            high=np.array([axis.high for axis in axes]),
            steps=np.array([axis.step for axis in axes]),
        )
        return at(best) if value < start_rss else None
    if not item.fit_sets_settings:
        return None
    current = spec
    for _ in range(6):
        _, small, fit = rss_of(current)
        settings = item.settings_from_fit(small.physical(fit, current.label), current.settings)
        if settings is None:
            return None
        if settings == dict(current.settings):
            break
        current = current.replace_settings(**settings)
    # More columns (a payload's own rotational inertia) when the data show them: they must
    # earn their BIC.
    richer = item.richer_form(current.settings)
    if richer is not None:
        point, small, _ = rss_of(current)
        full = rss_of(current.replace_settings(**richer[0]))[0]
        n = small.n_eff_train
        if full > 0 and n * math.log(point / full) > richer[1] * math.log(n) + 10.0:
            current = current.replace_settings(**richer[0])
    return current


def choose_form(
    problem: ResidualProblem,
    others: dict[str, dict[str, np.ndarray]],
    forms: list[EffectSpec],
    design_of: Callable[[dict[str, dict[str, np.ndarray]]], Design],
) -> EffectSpec:
    """Of an effect's forms, the one that, refined beside the others, fits held-out best.

    The selection takes a form greedily, the one that helps most on the training part when it
    enters; fitted beside the effects that entered after it, another may do better (a twin's
    balancer entered as a counterweight before the friction was in). Each form is refined
    (``refine_setting``) and judged on the held-out part. ``forms[0]`` is the library's first
    form (the link torque's friction, the balancer); it gives way only to a form that leaves
    ``FORM_SWITCH_SHARE`` less held-out error, whichever entered the selection.
    Once the link-side effects have a fit, a form that grows with the model's link torque is
    judged so (``Effect.model_load_settings``): beside a payload the URDF's link torque alone
    would lose to gravity's on the wrist for want of the payload, not of the form.
    """
    judged: list[tuple[float, EffectSpec]] = []
    for form in forms:
        spec = refine_setting(problem, others, form, design_of) or form
        loaded = effect(spec.name).model_load_settings(spec.settings)
        if problem.link_terms and loaded is not None:
            spec = spec.replace_settings(**loaded)
        fit = design_of({**others, spec.label: problem.columns(spec)[0]}).fit(
            [*others, spec.label]
        )
        judged.append((fit.rss['test'], spec))
    best = min(judged, key=lambda item: item[0])
    if best[0] > (1.0 - FORM_SWITCH_SHARE) * judged[0][0]:
        return judged[0][1]  # within the noise the first form stays
    return best[1]


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
