"""Import CSV or NPZ logs from other sources (controller traces, real-time data logs) into a bag.

A small column-mapping YAML (see ``config/import_example.yaml``) says which column holds the time
stamp and each joint's position, velocity, motor current and joint torque, and in which unit.
Values are converted to SI (rad, rad/s, A, N*m), time stamps are snapped onto the controller's
sampling grid, and the result is written as a bag in the bag contract (see ``recording.py``).

Controllers sample on a fixed grid (the IPO cycle); the jitter in logged time stamps comes from
the logging path, so a stamp within ``jitter_tolerance`` periods of a grid point is moved onto it.
Missing grid points are gaps: counted, never filled (the dataset loader decides about gaps).

This module turns the mapped columns into SI values and writes the bag; the mapping and its checks
are in ``import_mapping.py``, the CSV and NPZ readers in ``import_readers.py`` and the time grid
in ``import_stamps.py``.
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal

import numpy as np

from id_learning.dataset.import_mapping import (
    QUANTITIES,
    UNITS,
    ColumnSpec,
    ImportMapping,
    JointColumns,
    load_import_mapping,
)
from id_learning.dataset.import_readers import LogTable, is_float, read_table
from id_learning.dataset.import_stamps import log_stamps
from id_learning.dataset.plausibility import check_efforts, check_motion
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
    for quantity in QUANTITIES:
        for joint in joints:
            spec = getattr(joint, quantity)
            if spec is not None:
                fields.append(_Field(quantity, joint.name, spec))
    return fields


def _raw_matrix(table: LogTable, fields: Sequence[_Field], mapping: ImportMapping) -> np.ndarray:
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


def _column(table: LogTable, item: _Field, mapping: ImportMapping) -> np.ndarray:
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


def _as_float(values: np.ndarray, table: LogTable, item: _Field) -> np.ndarray:
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
        elif is_float(text):
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
    table: LogTable,
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
    columns = ', '.join(fields[int(i)].describe() for i in np.flatnonzero(bad_cells))
    return f'empty or non-finite {columns}'


def _si_matrix(raw: np.ndarray, fields: Sequence[_Field], quantity: str) -> np.ndarray | None:
    """(N, n) values of one quantity in SI, in joint order, or None when not mapped."""
    columns = [
        raw[:, i] * (UNITS[quantity][item.spec.unit] * item.spec.scale) + item.spec.offset
        for i, item in enumerate(fields)
        if item.quantity == quantity
    ]
    return np.column_stack(columns) if columns else None


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
            f'{robot.name} {list(robot.joints)}; map exactly the robot config joints '
            '(--robot names the robot config)'
        )
    return tuple(by_name[name] for name in robot.joints)


def _check_efforts(recording: Recording, robot: RobotConfig, where: str) -> None:
    """Currents and torques within what the robot's torque limits can need (the gate)."""
    drives = robot.drives
    checks = (
        (recording.current, 'current [A]', 1.0 / (drives.gear_ratio * drives.torque_constant)),
        (recording.joint_torque, 'joint torque [N*m]', None),
    )
    for values, what, unit_per_nm in checks:
        if values is not None:
            check_efforts(
                recording.joints,
                recording.stamps_ns,
                values,
                torque_limit=robot.limits.torque,
                where=where,
                what=what,
                unit_per_nm=unit_per_nm,
            )


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
            backwards, off the grid or repeated, fewer than two rows left, or motion the
            plausibility gate refuses (non-finite after unit conversion; with a robot, positions
            or velocities beyond its limits, degrees named as such).
        BagError: ``out`` exists and ``overwrite`` is False.
    """
    source, out = Path(source), Path(out)
    start_ns = DEFAULT_START_NS if start_ns is None else start_ns
    joints = _joint_order(mapping, robot)
    if joints[0].velocity is None and not velocity_from_position:
        raise ConfigError(
            f'{mapping.where}: no velocity columns are mapped and velocity_from_position is off'
        )
    table = read_table(source, mapping)
    fields = _fields(mapping, joints)
    raw = _raw_matrix(table, fields, mapping)
    keep, dropped = _finite_rows(raw, fields, table, mapping)
    n_usable = int(np.count_nonzero(keep))
    if n_usable < 2:
        raise DatasetError(f'{source}: {n_usable} usable rows; at least 2 are needed')
    rows = raw[keep]
    stamps = log_stamps(rows, keep, table, mapping=mapping, robot=robot, start_ns=start_ns)
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
    # Nothing impossible reaches a bag: the plausibility gate (the robot's limits when known).
    check_motion(
        recording.joints,
        recording.stamps_ns,
        position,
        velocity,
        limits=robot.limits if robot else None,
        where=str(source),
    )
    if robot is not None:
        _check_efforts(recording, robot, str(source))
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
