"""The reference study, and what of it the report places beside our numbers.

Trinh, Geist, Monnet, Vilceanu, Trimpe, Brecher: "Newtonian and Lagrangian Neural Networks: A
Comparison Towards Efficient Inverse Dynamics Identification", 14th IFAC Symposium on Robotics,
2025 (arXiv:2506.17994). Data: a MABI MAX 100 with motor torques estimated from currents.

NOT BUNDLED: the study's Table 1 (per-axis test RMSE of its seven models). Only the paper's
abstract and summaries could be consulted when this module was written, never the table itself,
and numbers are never made up: ``STUDY_TABLE_1`` stays None until someone copies the values from
the paper (one list of six normalised RMSEs per model kind, axes 1..6, in ``STUDY_MODELS`` order),
with the table's exact caption in ``STUDY_TABLE_1_CAPTION``. The report then shows them beside
ours; while it is None, the report says that they are not bundled.
"""

from __future__ import annotations

__all__ = [
    'MODEL_LABELS',
    'STUDY_CITATION',
    'STUDY_FINDINGS',
    'STUDY_TABLE_1',
    'STUDY_TABLE_1_CAPTION',
]

STUDY_CITATION = (
    'Trinh, Geist, Monnet, Vilceanu, Trimpe, Brecher: Newtonian and Lagrangian Neural Networks: '
    'A Comparison Towards Efficient Inverse Dynamics Identification. 14th IFAC Symposium on '
    'Robotics, 2025. arXiv:2506.17994'
)

#: Per model kind, the study's six per-axis test RMSEs on its normalised scale; None: not bundled.
STUDY_TABLE_1: dict[str, tuple[float, ...]] | None = None
STUDY_TABLE_1_CAPTION: str | None = None

#: The model names as the study writes them.
MODEL_LABELS = {
    'rnea_lq': 'RNEA+LQ',
    'rnea_mlp': 'RNEA+MLP',
    'delan': 'DeLaN',
    'lnn': 'LNN',
    'lnn_mlp': 'LNN+MLP',
    'mlp': 'MLP',
    'lstm': 'LSTM',
    'rnea_effects': 'RNEA+effects',
    'rnea_effects_mlp': 'RNEA+effects+MLP',
}

#: The study's findings the report checks, by finding (from its abstract and issue 3).
STUDY_FINDINGS = {
    'rnea_mlp_beats_lagrangian': (
        'with motor-torque labels (tau_u from currents), RNEA+MLP beats DeLaN and LNN on the '
        'high-friction axes'
    ),
    'lnn_mlp_recovers_gap': (
        'with motor-torque labels, LNN+MLP (LNN plus a network for dissipative torques) recovers '
        'most of the gap between LNN and RNEA+MLP'
    ),
    'lagrangian_competitive': (
        'with joint-torque labels (no dissipation in the label), the Lagrangian networks are '
        'competitive'
    ),
}
