"""The column mapping of a log import: which column holds what, in which unit, and its checks.

``ImportMapping`` validates itself on construction, and ``load_import_mapping`` builds one from
a mapping YAML (see ``config/import_example.yaml``). The unit table is here too, since the
mapping checks units against it and the import converts with it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal, TypeGuard

import numpy as np

from id_learning.config_io import check_keys, load_yaml_mapping
from id_learning.errors import ConfigError

__all__ = [
    'QUANTITIES',
    'UNITS',
    'ColumnSpec',
    'ImportMapping',
    'JointColumns',
    'MotorSide',
    'ResamplePolicy',
    'load_import_mapping',
]

# Factor from each allowed unit to SI (s, rad, rad/s, A, N*m); rpm is joint-side turns per minute.
UNITS: dict[str, dict[str, float]] = {
    'time': {'s': 1.0, 'ms': 1e-3, 'us': 1e-6, 'ns': 1e-9},
    'position': {'rad': 1.0, 'deg': math.pi / 180.0, 'mrad': 1e-3},
    'velocity': {'rad/s': 1.0, 'deg/s': math.pi / 180.0, 'rpm': 2.0 * math.pi / 60.0},
    'current': {'A': 1.0, 'mA': 1e-3},
    'torque': {'Nm': 1.0, 'kNm': 1e3},
}
QUANTITIES = ('position', 'velocity', 'current', 'torque')
_OPTIONAL_QUANTITIES = ('velocity', 'current', 'torque')
_TOP_KEYS = (
    'format',
    'header',
    'delimiter',
    'comment',
    'encoding',
    'skip_lines',
    'time',
    'period_s',
    'joints',
    'nan_policy',
    'implausible_policy',
    'beyond_limits_policy',
    'jitter_tolerance',
    'resample',
    'motors',
)
_RESAMPLE_KEYS = ('method', 'period_s', 'max_gap_s', 'min_segment_s')
_MOTOR_KEYS = ('gear_ratio', 'torque_constant', 'coupling', 'signals')
_MOTOR_SIGNALS = ('position', 'velocity', 'current')
_SPEC_KEYS = ('column', 'unit', 'index', 'scale', 'offset')
_JOINT_KEYS = ('name', *QUANTITIES)


@dataclass(frozen=True)
class ColumnSpec:
    """Where one quantity is in the log, and how to convert it: SI = raw * unit * scale + offset.

    Attributes:
        column: column name (CSV with header, NPZ key) or 0-based index (CSV without header).
        unit: unit of the raw values, one of those allowed for the quantity.
        index: column of a 2-D NPZ array; None for a 1-D array.
        scale: factor applied after the unit conversion (e.g. -1 for an inverted axis).
        offset: added last, in SI units (e.g. an encoder zero [rad]). For time it only tells
            an absolute time column (seconds since the epoch) from a relative one
            (``import_stamps.absolute_start_ns``): steps and grid do not depend on it.
    """

    column: str | int
    unit: str
    index: int | None = None
    scale: float = 1.0
    offset: float = 0.0

    def describe(self) -> str:
        """Name the column for messages: ``'q1'`` or ``'q'[:, 2]``."""
        suffix = '' if self.index is None else f'[:, {self.index}]'
        return f'{self.column!r}{suffix}'


@dataclass(frozen=True)
class JointColumns:
    """The columns of one joint; velocity, current and torque are optional."""

    name: str
    position: ColumnSpec
    velocity: ColumnSpec | None = None
    current: ColumnSpec | None = None
    torque: ColumnSpec | None = None


@dataclass(frozen=True)
class ResamplePolicy:
    """How the log's stamps become the robot's sampling grid, and where a log splits in segments.

    Attributes:
        method: 'snap' moves stamps within ``jitter_tolerance`` periods onto the grid and refuses
            the others (a log written on the controller's own grid); 'interpolate' resamples onto
            a new grid (logs at another rate, with jitter or a drifting clock): positions and
            velocities by cubic interpolation, currents and torques through an anti-aliasing
            low-pass first when the log is faster than the grid.
        period_s: the grid's period [s]; None: the robot's IPO period (``--robot``), else the
            log's median step.
        max_gap_s: a pause in the log longer than this [s] ends a segment, never bridged; None:
            3 grid periods (what loading a bag tolerates; 'interpolate': 3 log steps when the log
            is slower). Shorter pauses are left as gaps ('snap', at most 3 periods then) or
            bridged by interpolation ('interpolate'), and reported either way.
        min_segment_s: a segment shorter than this [s] is dropped and reported (0: every segment
            of two samples or more is kept; preprocessing refuses one too short for its filter).
    """

    method: Literal['snap', 'interpolate'] = 'snap'
    period_s: float | None = None
    max_gap_s: float | None = None
    min_segment_s: float = 0.0


@dataclass(frozen=True)
class MotorSide:
    """Motor-side columns and the drive train that maps them to the joint side.

    With the reduction K = diag(gear_ratio) @ coupling, motor angles are theta = K q and joint
    torques tau = K^T (torque_constant * i), i the motor currents. Motor m belongs to the m-th
    mapped joint; rows and columns of ``coupling`` follow the mapping's joint order.

    Attributes:
        gear_ratio: (n,) motor turns per joint turn, per motor.
        torque_constant: (n,) motor torque per current [N*m/A], per motor.
        coupling: (n, n) joint-side coupling, identity for independent joints (a coupled wrist:
            coupling[m, k] is how far joint k turns motor m, per turn of motor m's own joint).
        signals: the mapped quantities logged motor side: any of position, velocity, current.
    """

    gear_ratio: tuple[float, ...]
    torque_constant: tuple[float, ...]
    coupling: tuple[tuple[float, ...], ...] | None = None
    signals: tuple[str, ...] = ('current',)


@dataclass(frozen=True, kw_only=True)
class ImportMapping:
    """How to read one kind of log: file format, time base and one column spec per quantity.

    Attributes:
        joints: the mapped joints, in the order written unless a robot config reorders them.
        time: the time stamp column, or None when ``period_s`` gives the time base.
        period_s: fixed sampling period [s] (stamp k = start + k * period), or None.
        format: 'csv' (gzip-compressed too) or 'npz'; None takes it from the file suffix
            (``.csv.gz`` is csv).
        header: whether a CSV's first non-comment row names the columns; 'auto' detects it
            (a header when a non-empty field is no number).
        delimiter: CSV field separator: one character, 'tab' or 'whitespace'; None sniffs.
        comment: prefix of CSV comment lines, or None.
        encoding: a CSV's text encoding (a Python codec name: 'cp1252', 'latin-1', ...);
            'utf-8' reads a UTF-8 file with or without a byte order mark, and a UTF-16 one that
            starts with its byte order mark.
        skip_lines: lines before the header (or the first data row) to skip: a trace's preamble.
        nan_policy: 'refuse' raises on an empty, missing (``NA``, ``null``, ...) or non-finite
            cell, 'drop' drops its row.
        implausible_policy: 'refuse' raises on a value no arm can have (far beyond the robot's
            limits, or a non-physical magnitude: see ``import_values``), 'drop' drops its row.
        beyond_limits_policy: 'refuse' raises on a value past the plausibility gate (just beyond
            the robot's limits) but not implausible, 'drop' drops its row (a drive's garbage
            samples). Rows dropped by both policies may be at most half of the rows.
        jitter_tolerance: largest stamp deviation from the sampling grid snapped onto it, as a
            fraction of the period (below 0.5 so that the nearest grid point is unambiguous).
        resample: how stamps become the sampling grid, and where the log splits in segments.
        motors: the motor-side columns and drive train, or None when every column is joint side.
        source: the mapping file, named in errors.
    """

    joints: tuple[JointColumns, ...]
    time: ColumnSpec | None = None
    period_s: float | None = None
    format: Literal['csv', 'npz'] | None = None
    header: bool | Literal['auto'] = 'auto'
    delimiter: str | None = None
    comment: str | None = '#'
    encoding: str = 'utf-8'
    skip_lines: int = 0
    nan_policy: Literal['refuse', 'drop'] = 'refuse'
    implausible_policy: Literal['refuse', 'drop'] = 'refuse'
    beyond_limits_policy: Literal['refuse', 'drop'] = 'refuse'
    jitter_tolerance: float = 0.25
    resample: ResamplePolicy = field(default_factory=ResamplePolicy)
    motors: MotorSide | None = None
    source: Path | None = field(default=None, compare=False)

    def __post_init__(self) -> None:
        """Validate every option, naming the mapping file and the key."""
        object.__setattr__(self, 'joints', tuple(self.joints))
        _check_options(self, self.where)
        _check_time_base(self, self.where)
        _check_joints(self.joints, self.where)
        _check_columns_once(self, self.where)
        _check_resample(self, self.where)
        if self.motors is not None:
            _check_motors(self.motors, self.joints, self.where)

    def mapped_columns(self) -> set[str | int]:
        """The columns the mapping reads (time and every joint's quantities), by name or index."""
        specs = [self.time] + [
            getattr(joint, quantity) for joint in self.joints for quantity in QUANTITIES
        ]
        return {spec.column for spec in specs if spec is not None}

    @property
    def where(self) -> str:
        """The mapping file for messages, or a placeholder for a mapping built in code."""
        return str(self.source) if self.source is not None else '<import mapping>'


# -- mapping validation ---------------------------------------------------------------------------
def _is_number(value: object) -> TypeGuard[float]:
    return isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)


def _check_options(mapping: ImportMapping, where: str) -> None:
    if mapping.format not in (None, 'csv', 'npz'):
        raise ConfigError(
            f"{where}: format must be 'csv', 'npz' or omitted (from the file suffix), "
            f'got {mapping.format!r}'
        )
    if not (isinstance(mapping.header, bool) or mapping.header == 'auto'):
        raise ConfigError(f"{where}: header must be true, false or 'auto', got {mapping.header!r}")
    delimiter = mapping.delimiter
    if delimiter is not None and not (
        delimiter in ('tab', 'whitespace')
        or (isinstance(delimiter, str) and len(delimiter) == 1 and delimiter not in '\r\n"')
    ):
        raise ConfigError(
            f"{where}: delimiter must be one character, 'tab', 'whitespace' or omitted (sniffed), "
            f'got {delimiter!r}'
        )
    if mapping.comment is not None and not (isinstance(mapping.comment, str) and mapping.comment):
        raise ConfigError(f'{where}: comment must be a non-empty prefix or null')
    _check_text_options(mapping, where)
    for key in ('nan_policy', 'implausible_policy', 'beyond_limits_policy'):
        if getattr(mapping, key) not in ('refuse', 'drop'):
            raise ConfigError(
                f"{where}: {key} must be 'refuse' or 'drop', got {getattr(mapping, key)!r}"
            )
    tolerance = mapping.jitter_tolerance
    if not (_is_number(tolerance) and 0.0 <= tolerance < 0.5):
        raise ConfigError(
            f'{where}: jitter_tolerance must be in [0, 0.5) periods, got {tolerance!r}'
        )


def _check_text_options(mapping: ImportMapping, where: str) -> None:
    encoding = mapping.encoding
    try:
        if not isinstance(encoding, str):
            raise LookupError(encoding)
        'x'.encode(encoding)
    except (LookupError, UnicodeError):
        raise ConfigError(
            f"{where}: encoding must name a text encoding ('utf-8', 'cp1252', 'latin-1', "
            f"'utf-16', ...), got {encoding!r}"
        ) from None
    skip = mapping.skip_lines
    if isinstance(skip, bool) or not isinstance(skip, int) or skip < 0:
        raise ConfigError(f'{where}: skip_lines must be a count of lines >= 0, got {skip!r}')


def _check_time_base(mapping: ImportMapping, where: str) -> None:
    if (mapping.time is None) == (mapping.period_s is None):
        raise ConfigError(
            f'{where}: give exactly one of time (a time stamp column) and period_s (a fixed '
            'sampling period [s])'
        )
    if mapping.time is not None:
        _check_spec(mapping.time, 'time', 'time', where)
    elif not (_is_number(mapping.period_s) and mapping.period_s > 0):
        raise ConfigError(
            f'{where}: period_s must be a positive number [s], got {mapping.period_s!r}'
        )


def _check_spec(spec: object, quantity: str, key: str, where: str) -> None:
    if not isinstance(spec, ColumnSpec):
        raise ConfigError(f'{where}: {key}: expected a column spec, got {spec!r}')
    column = spec.column
    if isinstance(column, bool) or not (
        (isinstance(column, str) and column) or (isinstance(column, int) and column >= 0)
    ):
        raise ConfigError(
            f'{where}: {key}.column must be a name or a 0-based index, got {column!r}'
        )
    if spec.index is not None and (
        isinstance(spec.index, bool) or not isinstance(spec.index, int) or spec.index < 0
    ):
        raise ConfigError(f'{where}: {key}.index must be a 0-based index, got {spec.index!r}')
    allowed = UNITS[quantity]
    if spec.unit not in allowed:
        raise ConfigError(
            f'{where}: {key}.unit: unknown {quantity} unit {spec.unit!r}; allowed: {list(allowed)}'
        )
    if not (_is_number(spec.scale) and spec.scale != 0):
        raise ConfigError(f'{where}: {key}.scale must be a non-zero number, got {spec.scale!r}')
    if not _is_number(spec.offset):
        raise ConfigError(f'{where}: {key}.offset must be a finite number, got {spec.offset!r}')


def _check_joints(joints: tuple[JointColumns, ...], where: str) -> None:
    if not joints or not all(isinstance(joint, JointColumns) for joint in joints):
        raise ConfigError(f'{where}: joints: expected a non-empty list of joint mappings')
    names = [joint.name for joint in joints]
    if not all(isinstance(name, str) and name for name in names):
        raise ConfigError(f'{where}: joints: every joint needs a non-empty name, got {names}')
    duplicates = sorted({name for name in names if names.count(name) > 1})
    if duplicates:
        raise ConfigError(f'{where}: joints: duplicate joint names {duplicates}')
    for i, joint in enumerate(joints):
        for quantity in QUANTITIES:
            spec = getattr(joint, quantity)
            if spec is not None or quantity == 'position':
                _check_spec(spec, quantity, f'joints[{i}] ({joint.name}).{quantity}', where)
    for quantity in _OPTIONAL_QUANTITIES:
        mapped = [joint.name for joint in joints if getattr(joint, quantity) is not None]
        if mapped and len(mapped) != len(joints):
            unmapped = [name for name in names if name not in mapped]
            raise ConfigError(
                f'{where}: {quantity} is mapped for joints {mapped} but not for {unmapped}; '
                'map it for all joints or for none'
            )


def _check_columns_once(mapping: ImportMapping, where: str) -> None:
    """Refuse one source column (and index) mapped to two fields: one would copy the other."""
    uses: dict[tuple[str | int, int | None], list[str]] = {}
    specs = [] if mapping.time is None else [('time', mapping.time)]
    for joint in mapping.joints:
        for quantity in QUANTITIES:
            spec = getattr(joint, quantity)
            if spec is not None:
                specs.append((f'{joint.name} {quantity}', spec))
    for use, spec in specs:
        named = uses.setdefault((spec.column, spec.index), [])
        named.append(use)
        if len(named) == 2:
            raise ConfigError(
                f'{where}: column {spec.describe()} is mapped twice ({", ".join(named)}); map '
                'each column to one field'
            )


def _check_resample(mapping: ImportMapping, where: str) -> None:
    policy = mapping.resample
    if not isinstance(policy, ResamplePolicy):
        raise ConfigError(
            f'{where}: resample: expected a mapping with keys {list(_RESAMPLE_KEYS)}'
        )
    if policy.method not in ('snap', 'interpolate'):
        raise ConfigError(
            f"{where}: resample.method must be 'snap' or 'interpolate', got {policy.method!r}"
        )
    for key in ('period_s', 'max_gap_s'):
        value = getattr(policy, key)
        if value is not None and not (_is_number(value) and value > 0):
            raise ConfigError(
                f'{where}: resample.{key} must be a positive number [s], got {value!r}'
            )
    if not (_is_number(policy.min_segment_s) and policy.min_segment_s >= 0):
        raise ConfigError(
            f'{where}: resample.min_segment_s must be a number >= 0 [s], '
            f'got {policy.min_segment_s!r}'
        )
    if policy.method == 'interpolate' and mapping.time is None:
        raise ConfigError(
            f'{where}: resample.method interpolate needs a time column (period_s logs are on '
            'their grid already)'
        )


def _check_motors(motors: MotorSide, joints: tuple[JointColumns, ...], where: str) -> None:
    n = len(joints)
    for key in ('gear_ratio', 'torque_constant'):
        values = getattr(motors, key)
        if not (
            isinstance(values, tuple)
            and len(values) == n
            and all(_is_number(x) and x != 0 for x in values)
        ):
            raise ConfigError(
                f'{where}: motors.{key} needs {n} non-zero numbers (one per mapped joint, in '
                f'mapping order), got {values!r}'
            )
    coupling = motors.coupling
    if coupling is not None:
        if not (
            isinstance(coupling, tuple)
            and len(coupling) == n
            and all(isinstance(row, tuple) and len(row) == n for row in coupling)
            and all(_is_number(x) for row in coupling for x in row)
        ):
            raise ConfigError(
                f'{where}: motors.coupling must be a {n}x{n} matrix of numbers (rows: motors, '
                f'columns: joints, in mapping order), got {coupling!r}'
            )
        if abs(float(np.linalg.det(np.array(coupling, dtype=float)))) < 1e-9:
            raise ConfigError(
                f'{where}: motors.coupling is singular: the joints cannot be recovered from the '
                'motors'
            )
    unknown = [s for s in motors.signals if s not in _MOTOR_SIGNALS]
    if unknown or not motors.signals:
        raise ConfigError(
            f'{where}: motors.signals must list some of {list(_MOTOR_SIGNALS)}, got '
            f'{list(motors.signals)}'
        )
    if 'current' in motors.signals and joints[0].current is None:
        raise ConfigError(f'{where}: motors.signals names current, but no current is mapped')
    if 'velocity' in motors.signals and joints[0].velocity is None:
        raise ConfigError(f'{where}: motors.signals names velocity, but no velocity is mapped')


# -- mapping YAML ---------------------------------------------------------------------------------
def _spec_from_yaml(value: Any, where: str) -> ColumnSpec:
    if not isinstance(value, dict):
        raise ConfigError(f'{where}: expected a mapping with keys {list(_SPEC_KEYS)}')
    check_keys(value, _SPEC_KEYS, where, required=('column', 'unit'))
    return ColumnSpec(**value)


def _joint_from_yaml(value: Any, where: str) -> JointColumns:
    if not isinstance(value, dict):
        raise ConfigError(f'{where}: expected a mapping with keys {list(_JOINT_KEYS)}')
    check_keys(value, _JOINT_KEYS, where, required=('name', 'position'))
    specs = {
        quantity: _spec_from_yaml(value[quantity], f'{where}.{quantity}')
        for quantity in QUANTITIES
        if value.get(quantity) is not None
    }
    return JointColumns(name=value['name'], **specs)


def _resample_from_yaml(value: Any, where: str) -> ResamplePolicy:
    if not isinstance(value, dict):
        raise ConfigError(f'{where}: expected a mapping with keys {list(_RESAMPLE_KEYS)}')
    check_keys(value, _RESAMPLE_KEYS, where)
    return ResamplePolicy(**value)


def _motors_from_yaml(value: Any, where: str) -> MotorSide:
    if not isinstance(value, dict):
        raise ConfigError(f'{where}: expected a mapping with keys {list(_MOTOR_KEYS)}')
    check_keys(value, _MOTOR_KEYS, where, required=('gear_ratio', 'torque_constant'))

    def as_tuple(item: Any) -> Any:
        return tuple(as_tuple(x) for x in item) if isinstance(item, list) else item

    signals = value.get('signals', ['current'])
    if not isinstance(signals, list):
        raise ConfigError(f'{where}.signals: expected a list, got {signals!r}')
    return MotorSide(
        gear_ratio=as_tuple(value['gear_ratio']),
        torque_constant=as_tuple(value['torque_constant']),
        coupling=as_tuple(value.get('coupling')),
        signals=tuple(signals),
    )


def load_import_mapping(path: Path | str) -> ImportMapping:
    """Read and validate a column-mapping YAML (see ``config/import_example.yaml``).

    Raises:
        ConfigError: the file is unreadable, a key is unknown or missing, or a value is invalid
            (names the file and the key).
    """
    path = Path(path)
    data = load_yaml_mapping(path)
    where = str(path)
    check_keys(data, _TOP_KEYS, where, required=('joints',))
    joints = data['joints']
    if not isinstance(joints, list):
        raise ConfigError(f'{where}: joints: expected a list of joint mappings, got {joints!r}')
    time = data.get('time')
    nested = ('time', 'joints', 'resample', 'motors')
    options: dict[str, Any] = {
        key: data[key] for key in _TOP_KEYS if key in data and key not in nested
    }
    if data.get('resample') is not None:
        options['resample'] = _resample_from_yaml(data['resample'], f'{where}: resample')
    if data.get('motors') is not None:
        options['motors'] = _motors_from_yaml(data['motors'], f'{where}: motors')
    return ImportMapping(
        joints=tuple(
            _joint_from_yaml(item, f'{where}: joints[{i}]') for i, item in enumerate(joints)
        ),
        time=None if time is None else _spec_from_yaml(time, f'{where}: time'),
        source=path,
        **options,
    )
