"""The torque of a balancer (spring or gas) that holds a link against gravity.

A balancer between a point at distance a on the link and one at distance b on its predecessor
(both from the joint axis) has the length l = sqrt(a^2 + b^2 - 2 a b cos(theta)), theta = q +
phase; a force F(l) along it puts the torque -F(l) a b sin(theta) / l on the joint. In units of
a, l / a = s(theta) = sqrt(1 + r^2 - 2 r cos(theta)) with r = b / a. For a force polynomial in
the length, F = f0 + f1 l + f2 l^2 (a steel spring's preload and rate, a gas spring's rising
force), the torque is linear in three coefficients:

    tau = c0 sin(theta) / s + c1 sin(theta) + c2 s sin(theta),

while the geometry (r, phase) enters nonlinearly and is chosen by search. r and 1 / r give the
same shape, so r < 1; r near 1 makes the balancer short near upright and its torque sharp there.
"""

from __future__ import annotations

import numpy as np

__all__ = ['BALANCER_PHASES', 'BALANCER_RATIOS', 'BALANCER_TERMS', 'balancer_basis']

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
