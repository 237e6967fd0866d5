"""The shape of each joint's friction curve: its turn through zero speed, its viscous growth.

How sharply friction turns through zero speed and how its viscous part grows with speed both
differ between drives (pre-sliding, the speed controller's stiffness, the gear's grease).
A curve of the wrong shape leaves a torque at every reversal, or at speed, that other effects
(a delay, a Stribeck hump, a torque-constant error) would take up. The shape is identified per
joint before the selection, with every other candidate that acts on the joint free beside the
friction, so that what those explain is not taken for the curve's shape.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np

from id_learning.diagnosis.config import DiagnosisConfig
from id_learning.physics.effects import REGISTRY, effect
from id_learning.physics.terms import EffectSpec

__all__ = ['SHAPE_EVIDENCE', 'FrictionShape', 'identify_friction_shape', 'reshaped']

#: Stribeck velocities [rad/s] beside the sign while judging the shape: a hump is no sharp sign.
_HUMPS = (0.015, 0.05)
#: Twice the log-likelihood ratio a setting other than the configured one must earn.
SHAPE_EVIDENCE = 10.0

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
    (M,) on viscous, Coulomb and two Stribeck columns of that shape beside ``others`` (every other
    candidate's columns on the joint, (M, k) each). A setting other than the configured one
    (``smoothing_velocity``, a linear viscous law) must earn its place: a likelihood ratio of
    e^5 over the part's ``effective_samples``, at the best fit's residual level.
    """
    default: FrictionShape = (config.smoothing_velocity, 1.0)
    eps_grid = sorted({default[0], *config.smoothing_velocities})
    exponent_grid = sorted({1.0, *config.viscous_exponents})
    if len(eps_grid) == 1 and len(exponent_grid) == 1:
        return default
    fixed = np.hstack([np.ones((len(y), 0)), *others])

    def spec(name: str, **settings: float) -> EffectSpec:
        return EffectSpec(name, joint, joint_name, settings)

    # The joint's friction curve: its turn through zero speed (Coulomb), the humps at fixed
    # velocities where the library has one, and its speed law (viscous).
    laws = [item for item in REGISTRY.values() if item.friction_shaped]
    turns = [i.name for i in laws if i.switching and not (i.hump or i.reads_link_torque)]
    humps = [i.name for i in laws if i.hump and i.name in config.effects]
    curves = [i.name for i in laws if not i.switching]
    sign = {
        eps: np.hstack(
            [columns_of(spec(name, smoothing_velocity=eps)) for name in turns]
            + [
                columns_of(spec(name, smoothing_velocity=eps, velocity=vs))
                for name in humps
                for vs in _HUMPS
            ]
        )
        for eps in eps_grid
    }
    viscous = {
        d: np.hstack([columns_of(reshaped(spec(name), (default[0], d))) for name in curves])
        for d in exponent_grid
    }

    def rss(shape: FrictionShape) -> float:
        x = np.hstack([fixed, sign[shape[0]], viscous[shape[1]]])
        coefficients, *_ = np.linalg.lstsq(x, y, rcond=None)
        return float(np.sum((y - x @ coefficients) ** 2))

    shapes = [(e, d) for e in eps_grid for d in exponent_grid]
    fits = {shape: rss(shape) for shape in shapes}
    # The misfit's own level, not the label noise's: what no candidate explains (another
    # effect's form, a drift) would otherwise pass for evidence of a shape.
    scale = max(min(fits.values()), 1e-300) / effective_samples

    def score(shape: FrictionShape) -> float:
        changed = (shape[0] != default[0]) + (shape[1] != default[1])
        return fits[shape] / scale + SHAPE_EVIDENCE * changed

    return min(shapes, key=score)


def reshaped(spec: EffectSpec, shape: FrictionShape) -> EffectSpec:
    """A friction candidate with the joint's curve shape in its settings."""
    settings = effect(spec.name).reshaped_settings(spec.settings, *shape)
    return EffectSpec(spec.name, spec.joint, spec.joint_name, settings)
