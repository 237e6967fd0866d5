"""The reference study, and what of it the report places beside our numbers.

Trinh, Geist, Monnet, Vilceanu, Trimpe, Brecher: "Newtonian and Lagrangian Neural Networks: A
Comparison Towards Efficient Inverse Dynamics Identification", 14th IFAC Symposium on Robotics,
2025 (arXiv:2506.17994). Data: a MABI MAX 100 with motor torques estimated from currents.

Its Table 1 (per-axis test RMSE of the seven models on the normalised scale) is not part of
this package: the table belongs to the paper. ``load_study_table`` reads it from a JSON file the
user points at (``train --study-table PATH``); the report then places it beside our numbers, and
says that it is absent otherwise. The file is a JSON object holding ``joints`` (a list of
distinct axis names, as many as the robot has joints), ``rmse_normalised`` (an object of model
kind, one of ``models.registry.MODEL_KINDS``, -> a list of one RMSE per axis, in the order of
``joints``, each a finite number >= 0), and optionally ``source``, ``metric`` and
``split_note`` (strings) and ``findings`` (a list of strings). Other keys are notes and are not
read. A value of another type (a string or a boolean where a number belongs, a number where a
list belongs), or a row keyed by no model kind (which the report would leave out), is refused,
naming the file, the key path (``rmse_normalised.mlp[5]``) and the value.
"""

from __future__ import annotations

import difflib
import re
from dataclasses import dataclass, field
from pathlib import Path

from id_learning.config_io import loads_unique, number_hint, range_problem, read_capped, short_json
from id_learning.errors import ConfigError

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

    Every value is checked where it enters: ``joints`` a list of distinct non-empty names,
    ``rmse_normalised`` an object of model kind -> list of one RMSE per axis, each a finite
    number >= 0 (not a boolean, not a string), ``source``, ``metric`` and ``split_note`` strings,
    ``findings`` a list of strings. Other keys (the robot, the labels) are notes and kept out.

    Raises:
        ConfigError: the file is missing or unreadable, a device, past
            ``MAX_STUDY_TABLE_BYTES`` (``config_io.read_capped``) or not JSON, a key is
            given twice or missing, a value has the wrong type, a model row is keyed by no
            model kind (the closest kind is suggested), a model row has the wrong number
            of values or one that is no finite non-negative number, or the axes do not match
            ``n_joints``; the message names the file, the key and the value.
    """
    path = Path(path)
    text = read_capped(path, 'study table', MAX_STUDY_TABLE_BYTES)
    try:
        data = loads_unique(text.decode('utf-8'))
    except ValueError as err:  # not UTF-8, not JSON, a key given twice
        raise ConfigError(f'{path}: cannot read study table: {err}') from err
    except RecursionError:
        raise ConfigError(f'{path}: cannot read study table: JSON nested too deeply') from None
    if not isinstance(data, dict):
        raise ConfigError(
            f'{path}: the study table must be a JSON object, got {_type_name(data)} {_shown(data)}'
        )
    for key in ('rmse_normalised', 'joints'):
        if key not in data:
            raise ConfigError(f'{path}: the study table lacks {key!r}')
    joints = _joints(path, data['joints'])
    if n_joints is not None and len(joints) != n_joints:
        raise ConfigError(
            f'{path}: joints: the study table has {len(joints)} axes, the robot {n_joints} joints'
        )
    return StudyTable(
        path=path,
        rmse_normalised=_rows(path, data['rmse_normalised'], len(joints)),
        joints=joints,
        source=_text(path, data, 'source'),
        metric=_text(path, data, 'metric'),
        split_note=_text(path, data, 'split_note'),
        findings=_findings(path, data.get('findings', [])),
    )


def _type_name(value: object) -> str:
    """A JSON value's kind in JSON's words (an object, a list, ...), for messages."""
    if value is None:
        return 'null'
    if isinstance(value, bool):
        return 'a boolean'
    if isinstance(value, (int, float)):
        return 'a number'
    if isinstance(value, str):
        return 'a string'
    if isinstance(value, list):
        return 'a list'
    return 'an object'


def _shown(value: object) -> str:
    """``value`` as short JSON for a message (never the whole of a large value)."""
    try:
        return short_json(value)
    except (ValueError, RecursionError):  # cannot happen for what json.loads returned
        return _type_name(value)


#: A key written as is in a key path (``rmse_normalised.rnea_mlp``); any other is quoted.
_PLAIN_KEY = re.compile(r'[A-Za-z0-9_+\-]+')


def _key(name: str) -> str:
    """A key for a dotted key path: as is when a plain word, else quoted."""
    return name if _PLAIN_KEY.fullmatch(name) else repr(name)


def _joints(path: Path, value: object) -> tuple[str, ...]:
    """``joints``: a list of distinct non-empty names, at least one."""
    if not isinstance(value, list) or not value:
        raise ConfigError(
            f'{path}: joints: must be a non-empty list of axis names, got {_type_name(value)} '
            f'{_shown(value)}'
        )
    for k, name in enumerate(value):
        if not isinstance(name, str) or not name.strip():
            raise ConfigError(
                f'{path}: joints[{k}]: must be a non-empty name (a string), got '
                f'{_type_name(name)} {_shown(name)}'
            )
    twice = sorted({name for name in value if value.count(name) > 1})
    if twice:
        raise ConfigError(f'{path}: joints: {twice} given more than once; name each axis once')
    return tuple(value)


def _rows(path: Path, value: object, n_axes: int) -> dict[str, tuple[float, ...]]:
    """``rmse_normalised``: model kind -> one finite RMSE >= 0 per axis."""
    if not isinstance(value, dict) or not value:
        raise ConfigError(
            f'{path}: rmse_normalised: must be a non-empty object of model kind -> list of '
            f'{n_axes} RMSE values (one per axis), got {_type_name(value)} {_shown(value)}'
        )
    rows: dict[str, tuple[float, ...]] = {}
    for kind, values in value.items():
        where = f'{path}: rmse_normalised.{_key(kind)}'
        if not kind.strip():
            raise ConfigError(
                f'{path}: rmse_normalised: a model kind must be a name, got {kind!r}'
            )
        problem = _kind_problem(kind)
        if problem is not None:
            raise ConfigError(f'{where}: {problem}')
        if not isinstance(values, list) or len(values) != n_axes:
            raise ConfigError(
                f'{where}: needs {n_axes} finite values >= 0 in a list (one RMSE per axis), got '
                f'{_type_name(values)} {_shown(values)}'
            )
        row = []
        for k, x in enumerate(values):
            problem = range_problem(x, low=0.0)
            if problem:
                raise ConfigError(f'{where}[{k}]: {problem}, got {_shown(x)}{number_hint(x)}')
            row.append(float(x))
        rows[kind] = tuple(row)
    return rows


def _kind_problem(kind: str) -> str | None:
    """Why a row's key is no model kind (with the closest kind and the known ones), or None.

    The report places a row beside the model of its kind: a row keyed otherwise (a typo, the
    study's label such as 'RNEA+MLP') would be left out of the comparison without a word.
    """
    from id_learning.models.registry import MODEL_KINDS

    if kind in MODEL_KINDS:
        return None
    by_label = {label.lower(): name for name, label in MODEL_LABELS.items()}
    written = re.sub(r'[^a-z0-9]+', '_', kind.lower()).strip('_')
    close = [by_label[kind.lower()]] if kind.lower() in by_label else []
    close = close or difflib.get_close_matches(written, list(MODEL_KINDS), n=1)
    guess = f' (did you mean {close[0]!r}?)' if close else ''
    return (
        f'{kind!r} is no model kind{guess}; the kinds are {", ".join(MODEL_KINDS)} (a row is '
        'keyed by the kind it is compared with)'
    )


def _text(path: Path, data: dict[str, object], key: str) -> str:
    """An optional note (``source``, ``metric``, ``split_note``): a string, '' when absent."""
    value = data.get(key, '')
    if not isinstance(value, str):
        raise ConfigError(
            f'{path}: {key}: must be a string, got {_type_name(value)} {_shown(value)}'
        )
    return value


def _findings(path: Path, value: object) -> tuple[str, ...]:
    """``findings``: a list of sentences (strings)."""
    if not isinstance(value, list):
        raise ConfigError(
            f'{path}: findings: must be a list of sentences (strings), got {_type_name(value)} '
            f'{_shown(value)}'
        )
    for k, item in enumerate(value):
        if not isinstance(item, str):
            raise ConfigError(
                f'{path}: findings[{k}]: must be a string, got {_type_name(item)} {_shown(item)}'
            )
    return tuple(value)


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
