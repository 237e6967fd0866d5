"""Physics of the robot: rigid body, drives, named effects: what models and diagnosis stand on.

``RigidBodyDynamics`` (pinocchio) gives the URDF's inverse dynamics and its inertial-parameter
regressor; ``NominalModel`` adds the datasheet drives; ``EffectSpec`` and ``effect_columns`` are
the named effects as regressor columns, ``AugmentedModel`` the nominal model plus identified
effects.
"""

from __future__ import annotations

from id_learning.physics.augmented import AugmentedModel
from id_learning.physics.nominal import NominalModel, NominalQuantities
from id_learning.physics.rigid_body import (
    N_INERTIAL_PARAMETERS,
    RigidBodyDynamics,
    build_pinocchio_model,
)
from id_learning.physics.terms import EFFECT_NAMES, PARAMETERS, EffectSpec, effect_columns

__all__ = [
    'EFFECT_NAMES',
    'N_INERTIAL_PARAMETERS',
    'PARAMETERS',
    'AugmentedModel',
    'EffectSpec',
    'NominalModel',
    'NominalQuantities',
    'RigidBodyDynamics',
    'build_pinocchio_model',
    'effect_columns',
]
