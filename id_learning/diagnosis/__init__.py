"""Diagnosis: where the nominal model and the measurements disagree, and which effect is missing.

``diagnose`` compares the nominal model (URDF rigid-body dynamics plus datasheet drives) with
recordings, selects the named effects (the twin's stable names) that explain the disagreement,
reports alias sets, untestable effects and any unexplained remainder, and refits the augmented
model (``augmented_torque``, a ``physics.AugmentedModel``).
"""

from __future__ import annotations

from id_learning.diagnosis.aliases import AliasSet
from id_learning.diagnosis.config import DiagnosisConfig
from id_learning.diagnosis.pipeline import (
    DiagnosisResult,
    FoundEffect,
    Remainder,
    augmented_torque,
    column_motion,
    evaluation_rows,
    filtered_prediction,
    run_diagnosis,
)
from id_learning.diagnosis.report import diagnose
from id_learning.diagnosis.training_part import diagnose_training_part, training_part

__all__ = [
    'AliasSet',
    'DiagnosisConfig',
    'DiagnosisResult',
    'FoundEffect',
    'Remainder',
    'augmented_torque',
    'column_motion',
    'diagnose',
    'diagnose_training_part',
    'evaluation_rows',
    'filtered_prediction',
    'run_diagnosis',
    'training_part',
]
