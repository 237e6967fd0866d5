"""The friction laws, written once: each law's shape per unit coefficient, in numpy.

Every part of the package that models friction (the twin's true robot, the diagnosis's
candidate columns, the identification, RNEA+LQ, the findings and the online adaptation) takes its
law from here, so a sign or a shape is the same wherever it is used. A law returns the column
that multiplies its coefficient: friction torque = coefficient * column [N*m, joint side].
Velocities v are joint velocities [rad/s]; arrays broadcast, so a law serves one joint, all
joints at once, or one sample.

Sign convention: friction opposes motion, so the torque the drive must deliver grows with
sign(v); the sign turns smoothly through zero over the smoothing velocity v_eps (the pre-sliding
regime), never with a jump a drive could not follow.
"""

from __future__ import annotations

from typing import Any

import numpy as np

__all__ = [
    'STRIBECK_SHAPES',
    'coulomb',
    'load_dependent',
    'load_slope',
    'smooth_sign',
    'stribeck',
    'viscous',
    'warm_up',
]


def smooth_sign(v: Any, smoothing_velocity: Any) -> np.ndarray:
    """tanh(v / v_eps): the sign of v without the jump at zero."""
    out: np.ndarray = np.tanh(np.asarray(v) / smoothing_velocity)
    return out


def coulomb(v: Any, smoothing_velocity: Any) -> np.ndarray:
    """Coulomb friction per unit level F_c [N*m]: tanh(v / v_eps)."""
    return smooth_sign(v, smoothing_velocity)


def viscous(v: Any, exponent: Any = 1.0, *, linear: bool = False) -> tuple[np.ndarray, ...]:
    """Viscous friction's columns: v [rad/s]; or sign(v) |v|^delta, after v where ``linear``.

    Gear grease thickens or thins with speed: a drive's viscous torque grows linearly at low
    speed and bends at high speed, which a power law alone, one shape from zero speed on, does
    not follow over a long speed range. ``exponent`` may be an array (one per joint).
    """
    v = np.asarray(v)
    if np.all(np.asarray(exponent) == 1.0):
        return (v,)
    power: np.ndarray = np.sign(v) * np.abs(v) ** np.asarray(exponent, dtype=float)
    return (v, power) if linear else (power,)


#: How a Stribeck hump fades with speed, x = |v| / v_s: 'gaussian' exp(-x^2) (the common
#: model), 'exponential' exp(-x) (Tustin's), 'lorentzian' 1 / (1 + x^2) (a slow, long tail).
STRIBECK_SHAPES = ('gaussian', 'exponential', 'lorentzian')


def stribeck(
    v: Any, stribeck_velocity: Any, smoothing_velocity: Any, shape: str = 'gaussian'
) -> np.ndarray:
    """Stribeck friction per unit level F_s [N*m]: hump(|v| / v_s) tanh(v / v_eps).

    The breakaway torque above Coulomb friction that fades as the lubricant film builds up;
    ``shape`` says how it fades (``STRIBECK_SHAPES``).

    Raises:
        ValueError: an unknown shape.
    """
    v = np.asarray(v)
    x = np.abs(v / stribeck_velocity)
    if shape == 'gaussian':
        hump: np.ndarray = np.exp(-(x**2))
    elif shape == 'exponential':
        hump = np.exp(-x)
    elif shape == 'lorentzian':
        hump = 1.0 / (1.0 + x**2)
    else:
        raise ValueError(f'unknown Stribeck shape {shape!r}; known: {list(STRIBECK_SHAPES)}')
    out: np.ndarray = hump * smooth_sign(v, smoothing_velocity)
    return out


def load_dependent(v: Any, load: Any, smoothing_velocity: Any) -> np.ndarray:
    """Load-dependent friction per unit coefficient [1]: |L| tanh(v / v_eps).

    L [N*m] is the link torque the gear transmits: tooth and bearing forces grow with it.
    """
    out: np.ndarray = np.abs(np.asarray(load)) * smooth_sign(v, smoothing_velocity)
    return out


def load_slope(v: Any, load: Any, smoothing_velocity: Any) -> np.ndarray:
    """d/dL of ``load_dependent``: sign(L) tanh(v / v_eps), per unit coefficient."""
    out: np.ndarray = np.sign(np.asarray(load)) * smooth_sign(v, smoothing_velocity)
    return out


def warm_up(
    warm_scale: float, warm_up_s: float, shift_time_s: np.ndarray | None
) -> np.ndarray | float:
    """(N, 1) scale of a friction that falls as the drive warms up over a shift, or 1.

    scale(t) = warm_scale + (1 - warm_scale) * exp(-t / warm_up_s), t (N,) the time into the
    shift [s] (lubricant viscosity falls with temperature); ``warm_up_s`` 0 keeps it constant.
    """
    if shift_time_s is None or warm_up_s <= 0:
        return 1.0
    decay = np.exp(-np.asarray(shift_time_s, dtype=float) / warm_up_s)
    return (warm_scale + (1.0 - warm_scale) * decay)[:, None]
