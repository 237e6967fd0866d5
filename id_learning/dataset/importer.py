"""Import CSV or NPZ logs from other sources (controller traces, real-time data logs) into a bag.

A small column-mapping YAML (see ``config/import_example.yaml``) says which column holds the time
stamp and each joint's position, velocity, motor current and joint torque, and in which unit.
Values are converted to SI (rad, rad/s, A, N*m), time stamps are snapped onto the controller's
sampling grid, and the result is written as a bag in the bag contract (see ``recording.py``).

Controllers sample on a fixed grid (the IPO cycle); the jitter in logged time stamps comes from
the logging path, so a stamp within ``jitter_tolerance`` periods of a grid point is moved onto it.
Missing grid points are gaps: counted, never filled (the dataset loader decides about gaps).
"""

from __future__ import annotations

import csv
import logging
import math
import zipfile
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal, TypeGuard

import numpy as np

from id_learning.config_io import check_keys, load_yaml_mapping
from id_learning.dataset.recording import Recording, write_recording
from id_learning.errors import ConfigError, DatasetError
from id_learning.robot.config import RobotConfig

__all__ = [
    'DEFAULT_START_NS',
    'ColumnSpec',
    'ImportMapping',
    'ImportReport',
    'JointColumns',
    'import_log',
    'load_import_mapping',
]

logger = logging.getLogger(__name__)

# A fixed epoch (2023-11-14 22:13:20 UTC) for the first sample, so an import is deterministic.
DEFAULT_START_NS = 1_700_000_000 * 10**9

# Factor from each allowed unit to SI (s, rad, rad/s, A, N*m); rpm is joint-side turns per minute.
_UNITS: dict[str, dict[str, float]] = {
    'time': {'s': 1.0, 'ms': 1e-3, 'us': 1e-6, 'ns': 1e-9},
    'position': {'rad': 1.0, 'deg': math.pi / 180.0, 'mrad': 1e-3},
    'velocity': {'rad/s': 1.0, 'deg/s': math.pi / 180.0, 'rpm': 2.0 * math.pi / 60.0},
    'current': {'A': 1.0, 'mA': 1e-3},
    'torque': {'Nm': 1.0, 'kNm': 1e3},
}
_QUANTITIES = ('position', 'velocity', 'current', 'torque')
_OPTIONAL_QUANTITIES = ('velocity', 'current', 'torque')
_TOP_KEYS = (
    'format',
    'header',
    'delimiter',
    'comment',
    'time',
    'period_s',
    'joints',
    'nan_policy',
    'jitter_tolerance',
)
_SPEC_KEYS = ('column', 'unit', 'index', 'scale', 'offset')
_JOINT_KEYS = ('name', *_QUANTITIES)
# Sniffing order: tab and semicolon first, since a comma may be a decimal separator there.
_SNIFF_DELIMITERS = ('tab', ';', ',', 'whitespace')
_SNIFF_LINES = 20
_CSV_SUFFIXES = ('.csv', '.tsv', '.txt', '.dat', '.log')
_PERIOD_RESOLUTION_NS = 100_000  # estimated periods are rounded to 0.1 ms
_ROBOT_PERIOD_MATCH = 0.1  # a median step within 10 % of the robot's IPO period is that period


@dataclass(frozen=True)
class ColumnSpec:
    """Where one quantity is in the log, and how to convert it: SI = raw * unit * scale + offset.

    Attributes:
        column: column name (CSV with header, NPZ key) or 0-based index (CSV without header).
        unit: unit of the raw values, one of those allowed for the quantity.
        index: column of a 2-D NPZ array; None for a 1-D array.
        scale: factor applied after the unit conversion (e.g. -1 for an inverted axis).
        offset: added last, in SI units (e.g. an encoder zero [rad]); ignored for time, which is
            made relative to its first value.
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


@dataclass(frozen=True, kw_only=True)
class ImportMapping:
    """How to read one kind of log: file format, time base and one column spec per quantity.

    Attributes:
        joints: the mapped joints, in the order written unless a robot config reorders them.
        time: the time stamp column, or None when ``period_s`` gives the time base.
        period_s: fixed sampling period [s] (stamp k = start + k * period), or None.
        format: 'csv' or 'npz'; None takes it from the file suffix.
        header: whether a CSV's first non-comment row names the columns; 'auto' detects it
            (a header when a non-empty field is no number).
        delimiter: CSV field separator: one character, 'tab' or 'whitespace'; None sniffs.
        comment: prefix of CSV comment lines, or None.
        nan_policy: 'refuse' raises on an empty or non-finite cell, 'drop' drops its row.
        jitter_tolerance: largest stamp deviation from the sampling grid snapped onto it, as a
            fraction of the period (below 0.5 so that the nearest grid point is unambiguous).
        source: the mapping file, named in errors.
    """

    joints: tuple[JointColumns, ...]
    time: ColumnSpec | None = None
    period_s: float | None = None
    format: Literal['csv', 'npz'] | None = None
    header: bool | Literal['auto'] = 'auto'
    delimiter: str | None = None
    comment: str | None = '#'
    nan_policy: Literal['refuse', 'drop'] = 'refuse'
    jitter_tolerance: float = 0.25
    source: Path | None = field(default=None, compare=False)

    def __post_init__(self) -> None:
        """Validate every option, naming the mapping file and the key."""
        object.__setattr__(self, 'joints', tuple(self.joints))
        _check_options(self, self.where)
        _check_time_base(self, self.where)
        _check_joints(self.joints, self.where)

    @property
    def where(self) -> str:
        """The mapping file for messages, or a placeholder for a mapping built in code."""
        return str(self.source) if self.source is not None else '<import mapping>'


@dataclass
class ImportReport:
    """What an import did; ``summary()`` gives it in one line.

    Attributes:
        source: the imported log file.
        out: the bag written.
        n_rows_read: data rows in the log (without header, comment and blank lines).
        n_rows_written: samples written to the bag.
        period_s: sampling period of the written stamps [s].
        velocity_source: 'column' (mapped) or 'differentiated' (from position).
        row_label: what row positions count: 'line' (1-based CSV line, header and comments
            included) or 'row' (0-based NPZ array index).
        dropped_rows: (position, reason) of each row dropped under nan_policy 'drop'.
        max_jitter_s: largest |stamp - grid point| seen [s].
        n_snapped: stamps moved onto the grid.
        n_gaps: grid slots with no sample (not filled).
    """

    source: Path
    out: Path
    n_rows_read: int
    n_rows_written: int
    period_s: float
    velocity_source: Literal['column', 'differentiated']
    row_label: Literal['line', 'row'] = 'line'
    dropped_rows: list[tuple[int, str]] = field(default_factory=list)
    max_jitter_s: float = 0.0
    n_snapped: int = 0
    n_gaps: int = 0

    def summary(self, max_positions: int = 5) -> str:
        """Counts and the first ``max_positions`` dropped positions, in one line."""
        dropped = ''
        if self.dropped_rows:
            shown = ', '.join(str(position) for position, _ in self.dropped_rows[:max_positions])
            more = ', ...' if len(self.dropped_rows) > max_positions else ''
            dropped = f' ({self.row_label}s {shown}{more})'
        return (
            f'{self.source} -> {self.out}: {self.n_rows_written} of {self.n_rows_read} rows '
            f'written, {len(self.dropped_rows)} dropped{dropped}; period '
            f'{self.period_s * 1e3:g} ms, {self.n_snapped} stamps snapped (max jitter '
            f'{self.max_jitter_s * 1e3:.3g} ms), {self.n_gaps} missing grid slots; velocity '
            f'{self.velocity_source}'
        )


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
    if mapping.nan_policy not in ('refuse', 'drop'):
        raise ConfigError(
            f"{where}: nan_policy must be 'refuse' or 'drop', got {mapping.nan_policy!r}"
        )
    tolerance = mapping.jitter_tolerance
    if not (_is_number(tolerance) and 0.0 <= tolerance < 0.5):
        raise ConfigError(
            f'{where}: jitter_tolerance must be in [0, 0.5) periods, got {tolerance!r}'
        )


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
    allowed = _UNITS[quantity]
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
        for quantity in _QUANTITIES:
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
        for quantity in _QUANTITIES
        if value.get(quantity) is not None
    }
    return JointColumns(name=value['name'], **specs)


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
    options = {
        key: data[key] for key in _TOP_KEYS if key in data and key not in ('time', 'joints')
    }
    return ImportMapping(
        joints=tuple(
            _joint_from_yaml(item, f'{where}: joints[{i}]') for i, item in enumerate(joints)
        ),
        time=None if time is None else _spec_from_yaml(time, f'{where}: time'),
        source=path,
        **options,
    )


# -- reading the log ------------------------------------------------------------------------------
@dataclass(frozen=True)
class _Table:
    """A log's columns as read, before any conversion.

    CSV columns are (N,) arrays of cell strings keyed by header name or 0-based index; NPZ
    columns are the stored arrays keyed by name. ``line_numbers`` holds the 1-based CSV line of
    each data row, or None for NPZ, whose rows are named by their 0-based index.
    """

    source: Path
    columns: dict[str | int, np.ndarray]
    line_numbers: np.ndarray | None

    @property
    def row_label(self) -> Literal['line', 'row']:
        """'line' for CSV line numbers, 'row' for NPZ array indices."""
        return 'row' if self.line_numbers is None else 'line'

    def positions(self, n_rows: int) -> np.ndarray:
        """(N,) position of each data row in the file, as ``row_label`` counts it."""
        return np.arange(n_rows) if self.line_numbers is None else self.line_numbers


def _read_table(source: Path, mapping: ImportMapping) -> _Table:
    file_format = mapping.format or _format_from_suffix(source, mapping)
    return _read_npz(source) if file_format == 'npz' else _read_csv(source, mapping)


def _format_from_suffix(source: Path, mapping: ImportMapping) -> Literal['csv', 'npz']:
    suffix = source.suffix.lower()
    if suffix == '.npz':
        return 'npz'
    if suffix in _CSV_SUFFIXES:
        return 'csv'
    raise ConfigError(
        f'{mapping.where}: cannot tell the format of {source} from its suffix {suffix!r}; set '
        "format: 'csv' or 'npz'"
    )


def _read_npz(source: Path) -> _Table:
    try:
        loaded = np.load(source, allow_pickle=False)
        if not isinstance(loaded, np.lib.npyio.NpzFile):
            raise DatasetError(f'{source}: not an NPZ archive of named arrays')
        with loaded:
            columns: dict[str | int, np.ndarray] = {key: loaded[key] for key in loaded.files}
    except (OSError, ValueError, zipfile.BadZipFile) as err:
        raise DatasetError(f'{source}: cannot read NPZ file: {err}') from err
    return _Table(source, columns, None)


def _read_csv(source: Path, mapping: ImportMapping) -> _Table:
    try:
        text = source.read_text(encoding='utf-8-sig')
    except (OSError, UnicodeDecodeError) as err:
        raise DatasetError(f'{source}: cannot read CSV file: {err}') from err
    comment = mapping.comment
    numbered = [
        (number, line)
        for number, line in enumerate(text.splitlines(), start=1)
        if line.strip() and not (comment and line.lstrip().startswith(comment))
    ]
    if not numbered:
        raise DatasetError(f'{source}: no data rows')
    lines = [line for _, line in numbered]
    delimiter = mapping.delimiter or _sniff_delimiter(lines[:_SNIFF_LINES])
    rows = _split(lines, delimiter)
    has_header = _looks_like_header(rows[0]) if mapping.header == 'auto' else mapping.header
    first_data = 1 if has_header else 0
    names, data_rows = rows[:first_data], rows[first_data:]
    if not data_rows:
        raise DatasetError(f'{source}: no data rows')
    header = names[0] if names else []
    _check_unique_names(header, source)
    width = max(len(header), *(len(row) for row in data_rows))
    cells = np.array([row + [''] * (width - len(row)) for row in data_rows], dtype=object)
    keys: Sequence[str | int] = header or range(width)
    columns: dict[str | int, np.ndarray] = {
        key: cells[:, j] for j, key in enumerate(keys) if key != ''
    }
    line_numbers = np.array([number for number, _ in numbered[first_data:]])
    return _Table(source, columns, line_numbers)


def _split(lines: Sequence[str], delimiter: str) -> list[list[str]]:
    """Split lines into stripped fields; one CSV reader per line keeps line numbers exact."""
    if delimiter == 'whitespace':
        return [line.split() for line in lines]
    char = '\t' if delimiter == 'tab' else delimiter
    return [
        [cell.strip() for cell in next(csv.reader([line], delimiter=char, skipinitialspace=True))]
        for line in lines
    ]


def _sniff_delimiter(lines: Sequence[str]) -> str:
    """The first candidate that splits the first line in several fields, as most lines split."""
    for candidate in _SNIFF_DELIMITERS:
        counts = [len(row) for row in _split(lines, candidate)]
        if counts and counts[0] > 1 and 2 * counts.count(counts[0]) > len(counts):
            return candidate
    return ','


def _is_float(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


def _looks_like_header(row: Sequence[str]) -> bool:
    return any(cell and not _is_float(cell) for cell in row)


def _check_unique_names(names: list[str], source: Path) -> None:
    duplicates = sorted({name for name in names if name and names.count(name) > 1})
    if duplicates:
        raise DatasetError(f'{source}: the header names columns {duplicates} more than once')


# -- columns -> raw float matrix ------------------------------------------------------------------
@dataclass(frozen=True)
class _Field:
    """One mapped column: the quantity it holds, for which joint (None for time)."""

    quantity: str
    joint: str | None
    spec: ColumnSpec

    def describe(self) -> str:
        """Column and meaning, for messages."""
        meaning = 'time' if self.joint is None else f'joint {self.joint} {self.quantity}'
        return f'column {self.spec.describe()} ({meaning})'


def _fields(mapping: ImportMapping, joints: tuple[JointColumns, ...]) -> list[_Field]:
    """Time first, then each quantity's columns in joint order."""
    fields = [] if mapping.time is None else [_Field('time', None, mapping.time)]
    for quantity in _QUANTITIES:
        for joint in joints:
            spec = getattr(joint, quantity)
            if spec is not None:
                fields.append(_Field(quantity, joint.name, spec))
    return fields


def _raw_matrix(table: _Table, fields: Sequence[_Field], mapping: ImportMapping) -> np.ndarray:
    """(N, F) raw values, one column per field; empty cells are NaN.

    Raises:
        ConfigError: a column is missing, or its shape does not fit the spec's index.
        DatasetError: a cell is no number, or columns differ in length.
    """
    columns = [_column(table, item, mapping) for item in fields]
    lengths = {len(column) for column in columns}
    if len(lengths) > 1:
        pairs = zip(fields, columns, strict=True)
        found = ', '.join(f'{item.spec.describe()}: {len(column)}' for item, column in pairs)
        raise DatasetError(f'{table.source}: mapped columns differ in length ({found})')
    return np.column_stack(columns)


def _column(table: _Table, item: _Field, mapping: ImportMapping) -> np.ndarray:
    spec = item.spec
    if spec.column not in table.columns:
        raise ConfigError(
            f'{mapping.where}: {item.describe()} not found in {table.source}; its columns: '
            f'{list(table.columns)}'
        )
    values = table.columns[spec.column]
    if spec.index is not None:
        if values.ndim != 2 or not spec.index < values.shape[1]:
            raise ConfigError(
                f'{mapping.where}: {item.describe()}: index {spec.index} needs a 2-D array with '
                f'more than {spec.index} columns; {table.source} has shape {values.shape}'
            )
        values = values[:, spec.index]
    elif values.ndim != 1:
        raise ConfigError(
            f'{mapping.where}: {item.describe()} is an array of shape {values.shape} in '
            f'{table.source}; give index to pick one of its columns'
        )
    return _as_float(values, table, item)


def _as_float(values: np.ndarray, table: _Table, item: _Field) -> np.ndarray:
    try:
        return np.asarray(values, dtype=np.float64)
    except (TypeError, ValueError):
        pass  # empty cells or text: parse cell by cell to name the culprit
    positions = table.positions(len(values))
    parsed = np.empty(len(values))
    for i, cell in enumerate(values.tolist()):
        text = str(cell).strip()
        if not text:
            parsed[i] = np.nan
        elif _is_float(text):
            parsed[i] = float(text)
        else:
            raise DatasetError(
                f'{table.source}: {table.row_label} {positions[i]}, {item.describe()}: '
                f'{text!r} is not a number'
            )
    return parsed


def _finite_rows(
    raw: np.ndarray,
    fields: Sequence[_Field],
    table: _Table,
    mapping: ImportMapping,
) -> tuple[np.ndarray, list[tuple[int, str]]]:
    """Apply the NaN policy: (N,) mask of rows kept, and (position, reason) of rows dropped.

    Raises:
        DatasetError: under 'refuse', the first empty or non-finite cell (names row and column).
    """
    bad = ~np.isfinite(raw)
    bad_rows = np.flatnonzero(bad.any(axis=1))
    positions = table.positions(len(raw))
    if bad_rows.size and mapping.nan_policy == 'refuse':
        row, col = (int(i) for i in np.argwhere(bad)[0])
        raise DatasetError(
            f'{table.source}: {table.row_label} {positions[row]}, {fields[col].describe()}: '
            f'empty or non-finite value ({raw[row, col]}); {bad_rows.size} rows are affected. '
            'Fix the log or set nan_policy: drop'
        )
    dropped = [(int(positions[row]), _drop_reason(bad[row], fields)) for row in bad_rows]
    return ~bad.any(axis=1), dropped


def _drop_reason(bad_cells: np.ndarray, fields: Sequence[_Field]) -> str:
    columns = ', '.join(fields[i].describe() for i in np.flatnonzero(bad_cells))
    return f'empty or non-finite {columns}'


def _si_matrix(raw: np.ndarray, fields: Sequence[_Field], quantity: str) -> np.ndarray | None:
    """(N, n) values of one quantity in SI, in joint order, or None when not mapped."""
    columns = [
        raw[:, i] * (_UNITS[quantity][item.spec.unit] * item.spec.scale) + item.spec.offset
        for i, item in enumerate(fields)
        if item.quantity == quantity
    ]
    return np.column_stack(columns) if columns else None


# -- time stamps ----------------------------------------------------------------------------------
@dataclass(frozen=True)
class _Stamps:
    stamps_ns: np.ndarray
    period_s: float
    max_jitter_s: float = 0.0
    n_snapped: int = 0
    n_gaps: int = 0


def _count_gaps(slots: np.ndarray) -> int:
    return int(np.sum(np.diff(slots) - 1))


def _stamps_on_period(row_index: np.ndarray, period_s: float, start_ns: int) -> _Stamps:
    """Stamp k = start + k * period, k counting data rows from the first one kept."""
    period_ns = round(period_s * 1e9)
    slots = row_index - row_index[0]
    return _Stamps(start_ns + slots * period_ns, period_ns * 1e-9, n_gaps=_count_gaps(slots))


def _snapped_stamps(
    time_raw: np.ndarray,
    positions: np.ndarray,
    table: _Table,
    *,
    mapping: ImportMapping,
    robot: RobotConfig | None,
    start_ns: int,
) -> _Stamps:
    """Snap logged stamps onto the grid t0 + k * period and shift them to ``start_ns``.

    The grid origin t0 is the median deviation from a grid through the first stamp, so that a
    jittered first stamp does not shift the grid.

    Raises:
        DatasetError: time goes backwards, a stamp is off the grid by more than the tolerance, or
            two stamps fall into one grid slot (names the rows).
    """
    spec = mapping.time
    assert spec is not None  # called only for mappings with a time column
    factor = _UNITS['time'][spec.unit] * spec.scale * 1e9
    relative_ns = np.rint((time_raw - time_raw[0]) * factor).astype(np.int64)
    where, label = table.source, table.row_label
    steps = np.diff(relative_ns)
    if (steps < 0).any():
        i = int(np.argmax(steps < 0))
        raise DatasetError(
            f'{where}: {label} {positions[i + 1]}: time goes backwards by '
            f'{-steps[i] * 1e-6:g} ms from {label} {positions[i]}'
        )
    period_ns = _period_ns(steps, robot, where)
    phase = int(np.rint(np.median(relative_ns - np.rint(relative_ns / period_ns) * period_ns)))
    slots = np.rint((relative_ns - phase) / period_ns).astype(np.int64)
    deviation = relative_ns - phase - slots * period_ns
    tolerance_ns = mapping.jitter_tolerance * period_ns
    off_grid = np.abs(deviation) > tolerance_ns
    if off_grid.any():
        i = int(np.argmax(off_grid))
        raise DatasetError(
            f'{where}: {label} {positions[i]}: time stamp is {deviation[i] * 1e-6:+g} ms off the '
            f'{period_ns * 1e-6:g} ms sampling grid, beyond jitter_tolerance '
            f'{mapping.jitter_tolerance:g} periods ({tolerance_ns * 1e-6:g} ms)'
        )
    repeated = np.diff(slots) == 0
    if repeated.any():
        i = int(np.argmax(repeated))
        raise DatasetError(
            f'{where}: {label}s {positions[i]} and {positions[i + 1]} fall into the same '
            f'{period_ns * 1e-6:g} ms grid slot (a repeated sample, or not sampled on that grid)'
        )
    slots -= slots[0]
    return _Stamps(
        stamps_ns=start_ns + slots * period_ns,
        period_s=period_ns * 1e-9,
        max_jitter_s=float(np.abs(deviation).max()) * 1e-9,
        n_snapped=int(np.count_nonzero(deviation)),
        n_gaps=_count_gaps(slots),
    )


def _period_ns(steps_ns: np.ndarray, robot: RobotConfig | None, source: Path) -> int:
    """Estimate the sampling period from the median time step.

    The robot's IPO period when the median step is within 10 % of it, else the median step
    rounded to 0.1 ms.

    Raises:
        DatasetError: the median step rounds to zero.
    """
    median_s = float(np.median(steps_ns)) * 1e-9
    if robot is not None:
        ipo_s = robot.ipo_period_s
        if abs(median_s - ipo_s) <= _ROBOT_PERIOD_MATCH * ipo_s:
            return round(ipo_s * 1e9)
    period_ns = round(median_s * 1e9 / _PERIOD_RESOLUTION_NS) * _PERIOD_RESOLUTION_NS
    if period_ns <= 0:
        raise DatasetError(
            f'{source}: the median time step {median_s * 1e3:g} ms rounds to no period (periods '
            'are estimated to 0.1 ms); check the time column and its unit'
        )
    return period_ns


def _stamps(
    rows: np.ndarray,
    keep: np.ndarray,
    table: _Table,
    *,
    mapping: ImportMapping,
    robot: RobotConfig | None,
    start_ns: int,
) -> _Stamps:
    """Stamps of the kept rows, from the time column (``rows[:, 0]``) or the fixed period."""
    if mapping.time is not None:
        positions = table.positions(len(keep))[keep]
        return _snapped_stamps(
            rows[:, 0], positions, table, mapping=mapping, robot=robot, start_ns=start_ns
        )
    assert mapping.period_s is not None  # ImportMapping guarantees one time base
    return _stamps_on_period(np.flatnonzero(keep), mapping.period_s, start_ns)


# -- import ---------------------------------------------------------------------------------------
def _joint_order(mapping: ImportMapping, robot: RobotConfig | None) -> tuple[JointColumns, ...]:
    """The mapped joints, in the robot's order when a robot config is given.

    Raises:
        ConfigError: the mapped joint names are not the robot's (lists both).
    """
    if robot is None:
        return mapping.joints
    by_name = {joint.name: joint for joint in mapping.joints}
    if set(by_name) != set(robot.joints):
        raise ConfigError(
            f'{mapping.where}: mapped joints {list(by_name)} are not the joints of robot '
            f'{robot.name} {list(robot.joints)}; map exactly the robot config joints'
        )
    return tuple(by_name[name] for name in robot.joints)


def import_log(
    source: Path | str,
    mapping: ImportMapping,
    out: Path | str,
    *,
    robot: RobotConfig | None = None,
    velocity_from_position: bool = True,
    overwrite: bool = False,
    start_ns: int | None = None,
) -> ImportReport:
    """Import a CSV or NPZ log into a bag in the bag contract.

    Args:
        source: the log file.
        mapping: which columns hold what, in which unit.
        out: the bag folder to write.
        robot: when given, the joints must be the robot's (reordered to its order), its IPO
            period is preferred when estimating the sampling period, and its topics are used.
        velocity_from_position: differentiate position (central differences over the snapped
            stamps) when the mapping has no velocity columns.
        overwrite: replace an existing bag folder.
        start_ns: stamp of the first sample [ns since epoch]; default ``DEFAULT_START_NS``.

    Returns:
        What was read, dropped, snapped and written.

    Raises:
        ConfigError: the mapping does not fit the log or the robot (missing column, joint names,
            no velocity while ``velocity_from_position`` is False).
        DatasetError: unreadable log, non-numeric or (under 'refuse') non-finite cells, stamps
            backwards, off the grid or repeated, fewer than two rows left.
        BagError: ``out`` exists and ``overwrite`` is False.
    """
    source, out = Path(source), Path(out)
    start_ns = DEFAULT_START_NS if start_ns is None else start_ns
    joints = _joint_order(mapping, robot)
    if joints[0].velocity is None and not velocity_from_position:
        raise ConfigError(
            f'{mapping.where}: no velocity columns are mapped and velocity_from_position is off'
        )
    table = _read_table(source, mapping)
    fields = _fields(mapping, joints)
    raw = _raw_matrix(table, fields, mapping)
    keep, dropped = _finite_rows(raw, fields, table, mapping)
    n_usable = int(np.count_nonzero(keep))
    if n_usable < 2:
        raise DatasetError(f'{source}: {n_usable} usable rows; at least 2 are needed')
    rows = raw[keep]
    stamps = _stamps(rows, keep, table, mapping=mapping, robot=robot, start_ns=start_ns)
    position = _si_matrix(rows, fields, 'position')
    assert position is not None  # every joint maps a position
    velocity = _si_matrix(rows, fields, 'velocity')
    if velocity is None:
        velocity = np.gradient(position, (stamps.stamps_ns - stamps.stamps_ns[0]) * 1e-9, axis=0)
    recording = Recording(
        joints=tuple(joint.name for joint in joints),
        stamps_ns=stamps.stamps_ns,
        position=position,
        velocity=velocity,
        current=_si_matrix(rows, fields, 'current'),
        joint_torque=_si_matrix(rows, fields, 'torque'),
        source=str(source),
    )
    write_recording(recording, out, topics=robot.topics if robot else None, overwrite=overwrite)
    report = ImportReport(
        source=source,
        out=out,
        n_rows_read=len(raw),
        n_rows_written=recording.n_samples,
        period_s=stamps.period_s,
        velocity_source='differentiated' if joints[0].velocity is None else 'column',
        row_label=table.row_label,
        dropped_rows=dropped,
        max_jitter_s=stamps.max_jitter_s,
        n_snapped=stamps.n_snapped,
        n_gaps=stamps.n_gaps,
    )
    logger.info('imported %s', report.summary())
    return report
