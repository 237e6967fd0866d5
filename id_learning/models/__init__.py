"""Inverse-dynamics models: one interface (base), the kinds by name (registry), artifacts.

The kinds (``MODEL_KINDS``): the study's seven (``STUDY_MODELS``), the identified physics and
the diagnosed model (``rnea_id``, ``rnea_effects``), each of these two with a network on top
(``rnea_id_mlp``, ``rnea_effects_mlp``), and the Lagrangian networks initialised from the
identified physics (``delan_id``, ``lnn_mlp_id``). Artifacts hold no pickle.

The base classes import eagerly; the registry and artifact functions import on first use, so
that ``import id_learning.models.base`` stays light and does not load every model family.
"""

from __future__ import annotations

import importlib
from typing import Any

from id_learning.models.base import InverseDynamicsModel, ModelConfig, TorqueComponents
from id_learning.models.data import PhysicsFeatures, TrainingData, nominal_rnea

__all__ = [
    'MODEL_KINDS',
    'STUDY_MODELS',
    'InverseDynamicsModel',
    'ModelConfig',
    'PhysicsFeatures',
    'TorqueComponents',
    'TrainingData',
    'load_model',
    'make_config',
    'make_model',
    'nominal_rnea',
    'read_artifact',
    'robot_fingerprint',
    'save_model',
    'write_artifact',
]

_LAZY = {
    'MODEL_KINDS': 'id_learning.models.registry',
    'STUDY_MODELS': 'id_learning.models.registry',
    'load_model': 'id_learning.models.registry',
    'make_config': 'id_learning.models.registry',
    'make_model': 'id_learning.models.registry',
    'save_model': 'id_learning.models.registry',
    'read_artifact': 'id_learning.models.artifact',
    'robot_fingerprint': 'id_learning.models.artifact',
    'write_artifact': 'id_learning.models.artifact',
}


def __getattr__(name: str) -> Any:
    """Import the registry and artifact functions on first use (PEP 562)."""
    if name in _LAZY:
        return getattr(importlib.import_module(_LAZY[name]), name)
    raise AttributeError(f'module {__name__!r} has no attribute {name!r}')


def __dir__() -> list[str]:
    return sorted(__all__)
