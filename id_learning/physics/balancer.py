"""The torque of a balancer (spring or gas) that holds a link against gravity.

A balancer between a point at distance a on the link and one at distance b on its predecessor
(both from the joint axis) has the length l = sqrt(a^2 + b^2 - 2 a b cos(theta)), theta = q +
phase; a force F(l) along it puts the torque -F(l) a b sin(theta) / l on the joint. In units of
a, l / a = s(theta) = sqrt(1 + r^2 - 2 r cos(theta)) with r = b / a. For a force polynomial in
the length, F = f0 + f1 l + f2 l^2 (a steel spring's preload and rate, a gas spring's rising
force), the torque is linear in three coefficients:

    tau = c0 sin(theta) / s + c1 sin(theta) + c2 s sin(theta),

while the geometry (r, phase) enters nonlinearly: it is chosen on a coarse grid and refined by
Gauss-Newton on the basis's analytic derivatives (``balancer_basis_derivatives``). r and 1 / r
give the same shape, so r < 1; r near 1 makes the balancer short near upright and its torque
sharp there.
"""

from __future__ import annotations

import numpy as np

__all__ = [
    'BALANCER_PHASES',
    'BALANCER_RATIOS',
    'BALANCER_TERMS',
    'balancer_basis',
    'balancer_basis_derivatives',
]

#: Columns of the balancer basis (force polynomial of degree 2 in the length).
BALANCER_TERMS = 3
#: Geometries a search starts from: ratios of the arms, phases [rad] (0: shortest upright).
BALANCER_RATIOS = (0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 0.9)
BALANCER_PHASES = (-0.2, -0.1, 0.0, 0.1, 0.2)


def balancer_basis(q: np.ndarray, ratio: float, phase: float) -> np.ndarray:
    """The three torque columns (..., 3) of a balancer with geometry (ratio r, phase) at q [rad].

    Args:
        q: (...) joint positions [rad].
        ratio: r = b / a in (0, 1).
        phase: where the balancer is shortest, theta = q + phase = 0 [rad].
    """
    theta = np.asarray(q, dtype=float) + phase
    length = np.sqrt(1.0 + ratio**2 - 2.0 * ratio * np.cos(theta))
    sine = np.sin(theta)
    return np.stack([sine / length, sine, length * sine], axis=-1)


def balancer_basis_derivatives(q: np.ndarray, ratio: float, phase: float) -> np.ndarray:
    """The basis's derivatives (..., 3, 2) with respect to the ratio r and the phase [1/rad].

    ``[..., k, 0]`` is d column_k / d r, ``[..., k, 1]`` is d column_k / d phase; the refinement
    of a geometry steps along them (Gauss-Newton), so none of it is derivative-free search.
    """
    theta = np.asarray(q, dtype=float) + phase
    sine, cosine = np.sin(theta), np.cos(theta)
    length = np.sqrt(1.0 + ratio**2 - 2.0 * ratio * cosine)
    d_ratio = (ratio - cosine) / length  # d length / d r
    d_theta = ratio * sine / length  # d length / d theta
    out = np.empty((*theta.shape, BALANCER_TERMS, 2))
    out[..., 0, 0] = -sine * d_ratio / length**2
    out[..., 0, 1] = cosine / length - sine * d_theta / length**2
    out[..., 1, 0] = 0.0
    out[..., 1, 1] = cosine
    out[..., 2, 0] = sine * d_ratio
    out[..., 2, 1] = cosine * length + sine * d_theta
    return out
