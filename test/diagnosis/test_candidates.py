"""The diagnosis' candidate library."""

from __future__ import annotations

import numpy as np

from id_learning.diagnosis import DiagnosisConfig
from id_learning.diagnosis.candidates import build_library
from id_learning.physics import EFFECT_NAMES, NominalModel
from id_learning.twin.effects import EFFECT_NAMES as TWIN_EFFECT_NAMES


def test_library_names_every_effect_once_per_joint_or_robot_wide(mabi):
    model = NominalModel(mabi)
    rng = np.random.default_rng(0)
    limits = mabi.limits
    q = rng.uniform(limits.position_lower, limits.position_upper, (200, mabi.n_joints))
    v = rng.uniform(-1, 1, q.shape) * limits.velocity
    quantities = model.evaluate(q, v, np.zeros_like(q))

    library = build_library(model, quantities, DiagnosisConfig())
    names = {s.name for s in library}
    assert names == set(EFFECT_NAMES)
    # The physics layer names exactly the effects the twin can hide, in the same order.
    assert EFFECT_NAMES == TWIN_EFFECT_NAMES
    labels = [s.label for s in library]
    assert len(labels) == len(set(labels))
    config = DiagnosisConfig(effects=('viscous_friction', 'torque_offset'))
    assert len(build_library(model, quantities, config)) == 2 * model.robot.n_joints
