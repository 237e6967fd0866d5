"""Feed-forward prediction without ROS: reference sample in, guarded tau_u out.

The ROS nodes (``id_learning.nodes``) convert messages to ``ReferenceSample`` and back; every
decision (joint mapping, guards, acceleration estimate, LSTM window, clamping, counters) is made
here, so it is tested without a middleware.

The names import on first use (PEP 562): the replay needs the reference and timing helpers
without loading torch and the model families that ``FeedForwardPredictor`` brings in.
"""

from __future__ import annotations

import importlib
from typing import Any

__all__ = [
    'INFERENCE_BACKENDS',
    'CausalAccelerationEstimator',
    'FeedForwardPredictor',
    'GuardConfig',
    'PredictorCounters',
    'RangeViolation',
    'Reference',
    'ReferenceSample',
    'Reject',
    'RollingStats',
    'StatsSummary',
    'StepResult',
    'TrainingRange',
    'causal_acceleration',
    'configure_inference_threads',
    'reference_from_states',
    'set_openblas_threads',
    'training_range',
]

_MODULES = {
    'CausalAccelerationEstimator': 'acceleration',
    'causal_acceleration': 'acceleration',
    'GuardConfig': 'config',
    'FeedForwardPredictor': 'feedforward',
    'PredictorCounters': 'outcome',
    'ReferenceSample': 'sample',
    'Reject': 'outcome',
    'StepResult': 'outcome',
    'configure_inference_threads': 'threads',
    'set_openblas_threads': 'threads',
    'INFERENCE_BACKENDS': 'feedforward',
    'RangeViolation': 'ranges',
    'TrainingRange': 'ranges',
    'training_range': 'ranges',
    'Reference': 'reference',
    'reference_from_states': 'reference',
    'RollingStats': 'timing',
    'StatsSummary': 'timing',
}


def __getattr__(name: str) -> Any:
    """Import a public name's module on first use."""
    module = _MODULES.get(name)
    if module is None:
        raise AttributeError(f'module {__name__!r} has no attribute {name!r}')
    return getattr(importlib.import_module(f'{__name__}.{module}'), name)


def __dir__() -> list[str]:
    return sorted(__all__)
