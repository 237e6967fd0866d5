"""Digital twin: the nominal robot plus named hidden effects, recorded with realistic sensors."""

from __future__ import annotations

from id_learning.twin.effects import EFFECT_NAMES, EffectSet, effects_from_dict
from id_learning.twin.ground_truth import read_noise_free_torque, write_twin_output
from id_learning.twin.needed_torque import NeededTorque, needed_torque, needed_torque_of
from id_learning.twin.simulate import (
    GROUND_TRUTH_ARRAYS,
    GROUND_TRUTH_JSON,
    MeasurementConfig,
    TwinConfig,
    TwinResult,
    load_twin_config,
    simulate,
    true_dynamics,
)

__all__ = [
    'EFFECT_NAMES',
    'GROUND_TRUTH_ARRAYS',
    'GROUND_TRUTH_JSON',
    'EffectSet',
    'MeasurementConfig',
    'NeededTorque',
    'TwinConfig',
    'TwinResult',
    'effects_from_dict',
    'load_twin_config',
    'needed_torque',
    'needed_torque_of',
    'read_noise_free_torque',
    'simulate',
    'true_dynamics',
    'write_twin_output',
]
