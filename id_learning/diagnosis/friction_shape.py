"""The shape of each joint's friction curve: its turn through zero speed, its viscous growth.

How sharply friction turns through zero speed and how its viscous part grows with speed both
differ between drives (pre-sliding, the speed controller's stiffness, the gear's grease).
A curve of the wrong shape leaves a torque at every reversal, or at speed, that other effects
(a delay, a Stribeck hump, a torque-constant error) would take up. The shape is identified per
joint before the selection, with every other candidate that acts on the joint free beside the
friction, so that what those explain is not taken for the curve's shape.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence

import numpy as np
from scipy import optimize

from id_learning.diagnosis.config import DiagnosisConfig
from id_learning.physics.terms import EffectSpec

__all__ = ['FRICTION_SHAPED', 'FrictionShape', 'identify_friction_shape']

#: Candidates whose columns depend on the friction curve's shape.
FRICTION_SHAPED = (
    'viscous_friction',
    'coulomb_friction',
    'stribeck_friction',
    'load_dependent_friction',
)
#: Grid points a hump's velocity is profiled on (``_profiled``).
_HUMP_GRID = 10
#: Twice the log-likelihood ratio a setting other than the configured one must earn.
_EVIDENCE = 10.0

#: (v_eps [rad/s], viscous exponent) of one joint.
FrictionShape = tuple[float, float]
#: A joint's training columns (M, k) of a spec.
ColumnsOf = Callable[[EffectSpec], np.ndarray]


def identify_friction_shape(
    joint: int,
    joint_name: str,
    y: np.ndarray,
    *,
    others: Sequence[np.ndarray],
    columns_of: ColumnsOf,
    effective_samples: float,
    config: DiagnosisConfig,
) -> FrictionShape:
    """The (v_eps, exponent) of one joint's friction curve.

    Each pair of the config's grids is judged by a fit of the joint's training residual ``y``
    (M,) on viscous, Coulomb and Stribeck columns of that shape (the hump at its best velocity)
    beside ``others`` (every other candidate's columns on the joint, (M, k) each). A setting
    other than the configured one (``smoothing_velocity``, a linear viscous law) must earn its
    place: a likelihood ratio of e^5 over the part's ``effective_samples``, at the best fit's
    residual level.
    """
    default: FrictionShape = (config.smoothing_velocity, 1.0)
    eps_grid = sorted({default[0], *config.smoothing_velocities})
    exponent_grid = sorted({1.0, *config.viscous_exponents})
    if len(eps_grid) == 1 and len(exponent_grid) == 1:
        return default
    # What the other candidates explain is projected off once (Frisch-Waugh): each shape's fit
    # is then one of a few columns.
    basis = _column_space(np.hstack([np.ones((len(y), 0)), *others]))

    def projected(columns: np.ndarray) -> np.ndarray:
        return columns - basis @ (basis.T @ columns)

    def spec(name: str, **settings: float) -> EffectSpec:
        return EffectSpec(name, joint, joint_name, settings)

    y_free = projected(y[:, None])[:, 0]
    coulomb = {
        eps: projected(columns_of(spec('coulomb_friction', smoothing_velocity=eps)))
        for eps in eps_grid
    }
    viscous = {
        d: projected(columns_of(spec('viscous_friction', exponent=d))) for d in exponent_grid
    }
    humps: dict[tuple[float, float], np.ndarray] = {}

    def hump(eps: float, vs: float) -> np.ndarray:
        if (eps, vs) not in humps:
            settings = {'smoothing_velocity': eps, 'velocity': vs}
            humps[eps, vs] = projected(columns_of(spec('stribeck_friction', **settings)))
        return humps[eps, vs]

    def rss(columns: list[np.ndarray]) -> float:
        x = np.hstack(columns)
        coefficients, *_ = np.linalg.lstsq(x, y_free, rcond=None)
        return float(np.sum((y_free - x @ coefficients) ** 2))

    def fit(shape: FrictionShape) -> float:
        sign = [coulomb[shape[0]], viscous[shape[1]]]
        if 'stribeck_friction' not in config.effects:
            return rss(sign)
        # A Stribeck hump at its own best velocity beside the sign: the hump's velocity trades
        # with how sharply the sign turns, and a hump at the wrong one is made up by a wrong
        # turn (the final model has one hump, at its refined velocity).
        return _profiled(lambda vs: rss([*sign, hump(shape[0], vs)]), config)

    shapes = {(eps, d): fit((eps, d)) for eps in eps_grid for d in exponent_grid}
    # The misfit's own level, not the label noise's: what no candidate explains (another
    # effect's form, a drift) would otherwise pass for evidence of a shape.
    scale = max(min(shapes.values()), 1e-300) / effective_samples

    def score(shape: FrictionShape) -> float:
        changed = (shape[0] != default[0]) + (shape[1] != default[1])
        return shapes[shape] / scale + _EVIDENCE * changed

    return min(shapes, key=score)


def _column_space(x: np.ndarray) -> np.ndarray:
    """An orthonormal basis (M, r) of the columns of x (M, k), collinear ones counted once."""
    if not x.shape[1]:
        return x
    u, singular, _ = np.linalg.svd(x, full_matrices=False)
    tolerance = singular[0] * max(x.shape) * np.finfo(float).eps
    return u[:, singular > tolerance]


def _profiled(rss_at: Callable[[float], float], config: DiagnosisConfig) -> float:
    """The least residual sum of squares over the configured Stribeck velocities' span.

    A grid, refined between the best point's neighbours. A narrower hump is a sharper turn
    through zero speed, which the sign's own grid judges; a wider one bends the viscous law,
    which the exponents judge.
    """
    low = math.log(min(config.stribeck_velocities))
    high = math.log(max(config.stribeck_velocities))
    grid = np.linspace(low, high, _HUMP_GRID)
    values = [rss_at(math.exp(x)) for x in grid]
    best = int(np.argmin(values))
    bounds = (grid[max(best - 1, 0)], grid[min(best + 1, len(grid) - 1)])
    refined = optimize.minimize_scalar(
        lambda x: rss_at(math.exp(x)), bounds=bounds, method='bounded', options={'xatol': 0.02}
    )
    return min(values[best], float(refined.fun))


def reshaped(spec: EffectSpec, shape: FrictionShape) -> EffectSpec:
    """A friction candidate with the joint's curve shape in its settings."""
    eps, exponent = shape
    if spec.name == 'viscous_friction':
        settings: Mapping[str, float] = {'exponent': exponent} if exponent != 1.0 else {}
        return EffectSpec(spec.name, spec.joint, spec.joint_name, dict(settings))
    return spec.replace_settings(smoothing_velocity=eps)
