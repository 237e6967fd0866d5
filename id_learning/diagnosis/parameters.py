"""A fitted effect's physical parameters with intervals, in the twin's terms where one exists."""

from __future__ import annotations

from typing import Any

import numpy as np

from id_learning.physics.effects import FittedTerm, effect
from id_learning.physics.nominal import NominalModel
from id_learning.physics.terms import EffectSpec

__all__ = ['describe_parameters']


def describe_parameters(
    spec: EffectSpec,
    theta: np.ndarray,
    half_width: np.ndarray,
    model: NominalModel,
    interval_covariance: np.ndarray | None = None,
    *,
    settings: dict[str, list[float]] | None = None,
) -> list[dict[str, Any]]:
    """Physical parameters with confidence intervals, as the effect describes itself.

    Args:
        spec: the candidate.
        theta: (k,) fitted column coefficients in physical units.
        half_width: (k,) half widths of their confidence intervals (same units).
        model: the nominal model (datasheet values for scales).
        interval_covariance: (k, k) covariance of theta scaled so that the square roots of its
            diagonal are ``half_width``; needed for parameters that mix coefficients (the
            base parameters of ``inertial_parameter_error``).
        settings: refined settings estimated again beside the fit, name -> [value, low, high]
            (a Stribeck velocity); otherwise the spec's value, as exact.

    Returns:
        One dict per parameter: name, value, ci (low, high), unit.
    """
    fit = FittedTerm(spec.joint, spec.settings, theta, half_width, interval_covariance, settings)
    return effect(spec.name).describe(fit, model)
