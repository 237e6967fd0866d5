"""The reference study, and what of it the report places beside our numbers.

Trinh, Geist, Monnet, Vilceanu, Trimpe, Brecher: "Newtonian and Lagrangian Neural Networks: A
Comparison Towards Efficient Inverse Dynamics Identification", 14th IFAC Symposium on Robotics,
2025 (arXiv:2506.17994). Data: a MABI MAX 100 with motor torques estimated from currents.

Its Table 1 (per-axis test RMSE of the seven models on the normalised scale) is not part of
this package: the table belongs to the paper. ``load_study_table`` reads it from a JSON file the
user points at (``train --study-table PATH``); the report then places it beside our numbers, and
says that it is absent otherwise. The file holds ``rmse_normalised`` (model kind -> six values,
axes 1..6), ``joints``, and optionally ``source``, ``metric``, ``split_note`` and ``findings``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

from id_learning.config_io import read_capped
from id_learning.errors import ConfigError
from id_learning.models.metadata_checks import loads_unique

__all__ = [
    'MAX_STUDY_TABLE_BYTES',
    'MODEL_LABELS',
    'STUDY_CITATION',
    'STUDY_FINDINGS',
    'StudyTable',
    'load_study_table',
]

STUDY_CITATION = (
    'Trinh, Geist, Monnet, Vilceanu, Trimpe, Brecher: Newtonian and Lagrangian Neural Networks: '
    'A Comparison Towards Efficient Inverse Dynamics Identification. 14th IFAC Symposium on '
    'Robotics, 2025. arXiv:2506.17994'
)

#: The largest study table read [bytes]: seven rows of six numbers and a few sentences are
#: about 2 KiB; a file of a MiB is another file (a log, a device), read whole it could fill
#: the memory.
MAX_STUDY_TABLE_BYTES = 2**20


@dataclass(frozen=True)
class StudyTable:
    """The study's Table 1 as read from a file.

    Attributes:
        path: the file it came from.
        rmse_normalised: model kind -> per-axis test RMSE on the study's normalised scale.
        joints: the study's axis names, in order.
        source: where the numbers are from (citation, table).
        metric: what the numbers are, in the study's words.
        split_note: what the study says of its train/test split.
        findings: the study's findings, in its words.
    """

    path: Path
    rmse_normalised: dict[str, tuple[float, ...]]
    joints: tuple[str, ...]
    source: str = ''
    metric: str = ''
    split_note: str = ''
    findings: tuple[str, ...] = field(default_factory=tuple)


def load_study_table(path: Path | str, n_joints: int | None = None) -> StudyTable:
    """Read the study's Table 1 from JSON (module docstring).

    Raises:
        ConfigError: the file is missing or unreadable, a device, past
            ``MAX_STUDY_TABLE_BYTES`` (``config_io.read_capped``) or not JSON, a key is
            given twice or missing, a model row has the wrong number of values or a non-finite
            one, or the axes do not match ``n_joints``.
    """
    path = Path(path)
    text = read_capped(path, 'study table', MAX_STUDY_TABLE_BYTES)
    try:
        data = loads_unique(text.decode('utf-8'))
    except ValueError as err:  # not UTF-8, not JSON, a key given twice
        raise ConfigError(f'{path}: cannot read study table: {err}') from err
    if not isinstance(data, dict):
        raise ConfigError(f'{path}: the study table must be a JSON object')
    for key in ('rmse_normalised', 'joints'):
        if key not in data:
            raise ConfigError(f'{path}: the study table lacks {key!r}')
    joints = tuple(str(j) for j in data['joints'])
    if n_joints is not None and len(joints) != n_joints:
        raise ConfigError(
            f'{path}: the study table has {len(joints)} axes, the robot {n_joints} joints'
        )
    rows: dict[str, tuple[float, ...]] = {}
    for kind, values in dict(data['rmse_normalised']).items():
        try:
            row = tuple(float(x) for x in values)
        except (TypeError, ValueError) as err:
            raise ConfigError(f'{path}: rmse_normalised.{kind}: {err}') from err
        if len(row) != len(joints) or not all(math.isfinite(x) for x in row):
            raise ConfigError(
                f'{path}: rmse_normalised.{kind} needs {len(joints)} finite values, got {values}'
            )
        rows[str(kind)] = row
    return StudyTable(
        path=path,
        rmse_normalised=rows,
        joints=joints,
        source=str(data.get('source', '')),
        metric=str(data.get('metric', '')),
        split_note=str(data.get('split_note', '')),
        findings=tuple(str(f) for f in data.get('findings', ())),
    )


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
