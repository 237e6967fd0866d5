"""The motion that would tell an alias set's members apart.

Two effects form an alias set when, on this excitation, one reproduces the other's torque within
the noise. Where their torques still differ most says what to record next: the joint, and the
range of its speed, acceleration or position in which the difference is largest.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from id_learning.diagnosis.design import Design, Fit
from id_learning.diagnosis.problem import ResidualProblem

__all__ = ['describe', 'separating_motion']

#: Motion features a difference is organised by: name, unit, per-joint value on a row.
_FEATURES = (('speed', 'rad/s'), ('acceleration', 'rad/s^2'), ('position', 'rad'))
_BINS = 4


def separating_motion(
    problem: ResidualProblem,
    design: Design,
    fit: Fit,
    kept: str,
    alternative: str,
) -> dict[str, Any]:
    """Where ``alternative``'s best mimic of ``kept``'s torque differs from it most.

    The mimic is the least-squares fit of ``kept``'s contribution (training part, filtered) by
    the alternative with the other effects of ``fit`` free. Returns the joint, the motion
    feature and its range (one of four quantile bins) where the difference's RMS is largest,
    that RMS [N*m] and its ratio to the difference's RMS over the whole part.
    """
    groups = list(fit.groups)
    others = [g for g in groups if g != kept]
    idx_kept = design.indices([kept])
    idx_mimic = np.concatenate([design.indices(others), design.indices([alternative])])
    theta = design.coefficients(fit, kept)
    gram = design.gram['train']
    beta = np.linalg.lstsq(
        gram[np.ix_(idx_mimic, idx_mimic)], gram[np.ix_(idx_mimic, idx_kept)] @ theta, rcond=None
    )[0]
    x = design.matrix['train']
    shape = design.y['train'].shape
    difference = (x[:, idx_kept] @ theta - x[:, idx_mimic] @ beta).reshape(shape)
    difference = difference / np.sqrt(design.weights)
    joint = int(np.argmax(np.sqrt(np.mean(difference**2, axis=0))))
    values = _features(problem, joint)
    overall = float(np.sqrt(np.mean(difference[:, joint] ** 2)))
    best: dict[str, Any] = {}
    for (name, unit), value in zip(_FEATURES, values, strict=True):
        edges = np.quantile(value, np.linspace(0.0, 1.0, _BINS + 1))
        bins = np.clip(np.searchsorted(edges, value, side='right') - 1, 0, _BINS - 1)
        for b in range(_BINS):
            rows = bins == b
            if not rows.any():
                continue
            rms = float(np.sqrt(np.mean(difference[rows, joint] ** 2)))
            if rms > best.get('difference_rms_nm', -1.0):
                best = {
                    'joint': problem.robot.joints[joint],
                    'feature': name,
                    'range': [float(edges[b]), float(edges[b + 1])],
                    'unit': unit,
                    'difference_rms_nm': rms,
                    'ratio_to_overall': rms / overall if overall > 0 else 1.0,
                }
    return best


def describe(separation: dict[str, Any]) -> str:
    """One line: what motion would tell the two apart."""
    if not separation:
        return ''
    low, high = separation['range']
    return (
        f'more motion of {separation["joint"]} with {separation["feature"]} in '
        f'[{low:.3g}, {high:.3g}] {separation["unit"]} (they differ most there: '
        f'{separation["difference_rms_nm"]:.2g} N*m RMS)'
    )


def _features(problem: ResidualProblem, joint: int) -> Sequence[np.ndarray]:
    v, a, q = (problem.part(key, 'train')[:, joint] for key in ('v', 'a', 'q'))
    return np.abs(v), np.abs(a), q
