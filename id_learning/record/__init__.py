"""What to record: excitation trajectories for identification runs."""

from __future__ import annotations

from id_learning.record.excitation import (
    ExcitationConfig,
    ExcitationTrajectory,
    FourierSegment,
    check_limits,
    design_excitation,
)

__all__ = [
    'ExcitationConfig',
    'ExcitationTrajectory',
    'FourierSegment',
    'check_limits',
    'design_excitation',
]
