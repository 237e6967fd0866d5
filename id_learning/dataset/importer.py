"""Import CSV or NPZ logs from other sources (controller traces, real-time data logs) into a bag.

A small column-mapping YAML (see ``config/import_example.yaml``) says which column holds the time
stamp and each joint's position, velocity, motor current and joint torque, in which unit, and
which are logged motor side. Values are converted to SI joint side (rad, rad/s, A, N*m), checked
(``import_values``), put on the controller's sampling grid by snapping or resampling
(``import_resample``), and written as one bag in the bag contract (see ``recording.py``).

Several files (or a folder of them) go into one bag, one after the other; each file, and each
stretch of a file between pauses longer than ``resample.max_gap_s``, is a segment, which
preprocessing and the train/test split treat as a recording of its own. Nothing is filled or
dropped silently: rows dropped by the NaN, implausible-value and beyond-limits policies (with
column, joint and value), holes bridged by resampling, pauses that end a segment and segments too
short to keep are all in the report. One log given twice is refused, also in other bytes (a
reformatted, compressed or NPZ copy: the same samples after parsing), and so are files that
overlap, holding some of the same samples (``import_overlap``).

The stamps are the log's own when its time column is absolute (since the epoch); other logs are
re-based to ``DEFAULT_START_NS``, one file after the other. Each report says which.

This module reads the mapped columns and writes the bag; the mapping and its checks are in
``import_mapping.py``, the files a source names in ``import_sources.py``, the CSV and NPZ readers
in ``import_readers.py``, the values and row checks in ``import_values.py``, the time base in
``import_stamps.py`` and ``import_resample.py``, the report in ``import_report.py``.
"""

from __future__ import annotations

import itertools
import logging
import math
from collections.abc import Sequence
from pathlib import Path
from typing import NamedTuple

import numpy as np

from id_learning.dataset.consistency import KinematicConsistency
from id_learning.dataset.import_mapping import (
    QUANTITIES,
    ColumnSpec,
    ImportMapping,
    JointColumns,
    load_import_mapping,
)
from id_learning.dataset.import_overlap import MIN_SHARED_ROWS, SourceRows, check_shared_rows
from id_learning.dataset.import_readers import LogTable, is_float, read_table
from id_learning.dataset.import_report import ImportReport, TimeBase
from id_learning.dataset.import_resample import (
    Gridded,
    check_distinct_samples,
    interpolate_segments,
    slot_segments,
)
from id_learning.dataset.import_sources import log_files
from id_learning.dataset.import_stamps import (
    absolute_origin_ns,
    absolute_start_ns,
    grid_period_s,
    relative_times,
    snap_to_grid,
    time_s,
)
from id_learning.dataset.import_values import (
    Field,
    RowChecks,
    apply_row_policies,
    check_array_types,
    joint_side,
    si_values,
)
from id_learning.dataset.inspect_checks import iso_utc
from id_learning.dataset.plausibility import check_efforts, check_motion
from id_learning.dataset.recording import Recording, write_recording
from id_learning.errors import ConfigError, DatasetError
from id_learning.robot.config import RobotConfig
from id_learning.robot.drives import amperes_per_newton_metre
from id_learning.staged_bag import staged_bag

__all__ = [
    'DEFAULT_START_NS',
    'SEGMENT_SEPARATION_S',
    'ColumnSpec',
    'ImportMapping',
    'ImportReport',
    'JointColumns',
    'import_log',
    'import_logs',
    'load_import_mapping',
    'log_files',
]

logger = logging.getLogger(__name__)

# A fixed epoch (2023-11-14 22:13:20 UTC) for the first sample, so an import is deterministic.
DEFAULT_START_NS = 1_700_000_000 * 10**9
#: The pause written between two files of one import [s] (at least; rounded up to the grid).
SEGMENT_SEPARATION_S = 1.0


# -- columns -> raw float matrix ------------------------------------------------------------------
def _fields(mapping: ImportMapping, joints: tuple[JointColumns, ...]) -> list[Field]:
    """Time first, then each quantity's columns in joint order."""
    fields = [] if mapping.time is None else [Field('time', None, mapping.time)]
    for quantity in QUANTITIES:
        for joint in joints:
            spec = getattr(joint, quantity)
            if spec is not None:
                fields.append(Field(quantity, joint.name, spec))
    return fields


def _raw_matrix(table: LogTable, fields: Sequence[Field], mapping: ImportMapping) -> np.ndarray:
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


def _column(table: LogTable, item: Field, mapping: ImportMapping) -> np.ndarray:
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
            f'{table.source}; {_shape_hint(values.shape)}'
        )
    return _as_float(values, table, item)


def _shape_hint(shape: tuple[int, ...]) -> str:
    """What a column of an array of this shape (not 1-D) needs."""
    if len(shape) == 2 and shape[0] == 1 < shape[1]:
        return 'one row of values: transposed? Store it as a 1-D array (N,)'
    if len(shape) == 2:
        return 'give index to pick one of its columns'
    return (
        'a column is a 1-D array (N,), or a 2-D one (N, k) with index picking one of its columns'
    )


#: Cells that mark a missing value in logs written by R, pandas, Excel, SQL or by hand
#: (compared in lower case): read as empty cells, so ``nan_policy`` decides.
#: Excel's #N/A is written #NV in German, #N/D in Italian and Spanish, #N/B in Dutch.
MISSING_MARKS = frozenset(
    ('na', 'n/a', '#n/a', 'nan', 'null', 'none', 'nil', '-', '--', '?', 'missing', 'n.a.')
) | frozenset(('#nv', '#n/d', '#n/b', '#n/v', '#nd'))


def _as_float(values: np.ndarray, table: LogTable, item: Field) -> np.ndarray:
    try:
        return np.asarray(values, dtype=np.float64)
    except (TypeError, ValueError):
        pass  # empty cells or text: parse cell by cell to name the culprit
    positions = table.positions(len(values))
    parsed = np.empty(len(values))
    for i, cell in enumerate(values.tolist()):
        text = str(cell).strip()
        if not text or text.lower() in MISSING_MARKS:
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
    fields: Sequence[Field],
    table: LogTable,
    mapping: ImportMapping,
) -> tuple[np.ndarray, list[tuple[int, str]]]:
    """Apply the NaN policy: (N,) mask of rows kept, and (position, reason) of rows dropped.

    Raises:
        DatasetError: under 'refuse', the first empty, missing or non-finite cell (names row and
            column).
    """
    bad = ~np.isfinite(raw)
    bad_rows = np.flatnonzero(bad.any(axis=1))
    positions = table.positions(len(raw))
    if bad_rows.size and mapping.nan_policy == 'refuse':
        row, col = (int(i) for i in np.argwhere(bad)[0])
        raise DatasetError(
            f'{table.source}: {table.row_label} {positions[row]}, {fields[col].describe()}: '
            f'empty, missing (NA, null, -, ...) or non-finite value ({raw[row, col]}); '
            f'{bad_rows.size} rows are affected. '
            'Fix the log or set nan_policy: drop'
        )
    dropped = [(int(positions[row]), _drop_reason(bad[row], fields)) for row in bad_rows]
    return ~bad.any(axis=1), dropped


def _drop_reason(bad_cells: np.ndarray, fields: Sequence[Field]) -> str:
    columns = ', '.join(fields[int(i)].describe() for i in np.flatnonzero(bad_cells))
    return f'empty, missing or non-finite {columns}'


# -- import ---------------------------------------------------------------------------------------
def _joint_order(mapping: ImportMapping, robot: RobotConfig | None) -> np.ndarray:
    """Indices of the written joints into the mapping's: the robot's order when one is given.

    Raises:
        ConfigError: the mapped joint names are not the robot's (lists both).
    """
    names = [joint.name for joint in mapping.joints]
    if robot is None:
        return np.arange(len(names))
    if set(names) != set(robot.joints):
        raise ConfigError(
            f'{mapping.where}: mapped joints {names} are not the joints of robot '
            f'{robot.name} {list(robot.joints)}; map exactly the robot config joints '
            '(--robot names the robot config)'
        )
    return np.array([names.index(name) for name in robot.joints])


def _check_efforts(recording: Recording, robot: RobotConfig, where: str) -> None:
    """Currents and torques within what the robot's torque limits can need (the gate)."""
    drives = robot.drives
    checks = (
        (recording.current, 'current [A]', amperes_per_newton_metre(drives)),
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


def _grid(
    table: LogTable,
    raw: np.ndarray,
    values: dict[str, np.ndarray],
    keep: np.ndarray,
    *,
    mapping: ImportMapping,
    robot: RobotConfig | None,
) -> Gridded:
    """The kept rows on the sampling grid, in segments (the mapping's time base and policy)."""
    positions = table.positions(len(raw))[keep]
    kept = {key: array[keep] for key, array in values.items()}
    policy = mapping.resample
    if mapping.time is None:
        assert mapping.period_s is not None  # ImportMapping guarantees one time base
        if robot is not None and not math.isclose(mapping.period_s, robot.ipo_period_s):
            raise ConfigError(
                f'{mapping.where}: period_s {mapping.period_s:g} s is not the IPO period '
                f'{robot.ipo_period_s:g} s of robot {robot.name}: a bag for this robot must be on '
                'its grid, and a log without a time column cannot be resampled; log a time '
                'column (resample: {method: interpolate}) or correct period_s or the robot '
                "config's ipo_period_s"
            )
        return slot_segments(np.flatnonzero(keep), kept, positions, mapping.period_s, policy)
    label = table.row_label
    times = relative_times(raw[keep, 0], positions, mapping, table.source, label)
    period = grid_period_s(times, mapping, robot, table.source)
    start_ns = absolute_start_ns(raw[keep, 0][0], mapping)  # None: a relative time column
    if policy.method == 'interpolate':  # grid slot 0 at the first row
        grid = interpolate_segments(times, kept, positions, period, policy)
        grid.start_ns = None if start_ns is None else absolute_origin_ns(start_ns)
        return grid
    snapped = snap_to_grid(times, positions, period, mapping, where=table.source, label=label)
    grid = slot_segments(snapped.slots, kept, positions, period, policy)
    grid.max_jitter_s, grid.n_snapped = snapped.max_jitter_s, snapped.n_snapped
    grid.start_ns = None if start_ns is None else absolute_origin_ns(start_ns, snapped.origin_ns)
    return grid


class _File(NamedTuple):
    """One log file read: on the grid, its report, and its kept rows as read."""

    grid: Gridded
    report: ImportReport
    rows: SourceRows


def _read_file(
    source: Path, mapping: ImportMapping, robot: RobotConfig | None, order: np.ndarray
) -> _File:
    """One log file on the grid, with its report (``out`` and stamps filled in by the caller)."""
    joints = tuple(mapping.joints[i] for i in order)
    table = read_table(source, mapping)
    fields = _fields(mapping, joints)
    check_array_types(table.columns, fields, source)
    raw = _raw_matrix(table, fields, mapping)
    keep, dropped = _finite_rows(raw, fields, table, mapping)
    values = si_values(raw, fields)
    if mapping.motors is not None:
        values = joint_side(values, mapping.motors, order, robot, mapping.where)
    positions = table.positions(len(raw))
    keep, beyond = apply_row_policies(
        RowChecks(fields, robot),
        values,
        keep,
        positions,
        implausible_policy=mapping.implausible_policy,
        beyond_limits_policy=mapping.beyond_limits_policy,
        where=str(source),
        label=table.row_label,
    )
    dropped = sorted(dropped + beyond)
    if np.count_nonzero(keep) < 2:
        raise DatasetError(
            f'{source}: {np.count_nonzero(keep)} usable rows; at least 2 are needed'
        )
    grid = _grid(table, raw, values, keep, mapping=mapping, robot=robot)
    if not grid.segments:
        raise DatasetError(
            f'{source}: no segment of at least resample.min_segment_s '
            f'{mapping.resample.min_segment_s:g} s without a pause longer than max_gap_s'
        )
    report = ImportReport(
        source=source,
        out=Path(),
        n_rows_read=len(raw),
        n_rows_written=sum(len(segment.slots) for segment in grid.segments),
        period_s=grid.period_s,
        velocity_source='differentiated' if joints[0].velocity is None else 'column',
        row_label=table.row_label,
        dropped_rows=dropped,
        method=mapping.resample.method if mapping.time is not None else 'snap',
        grid=grid,
        first_time_s=None if mapping.time is None else time_s(raw[keep, 0][0], mapping.time),
    )
    time = None if mapping.time is None else raw[keep, 0]
    kept = {key: array[keep] for key, array in values.items()}
    rows = SourceRows(source, table.row_label, positions[keep], time, kept)
    return _File(grid, report, rows)


def _time_base(grid: Gridded, report: ImportReport, start_ns: int | None) -> TimeBase:
    """Why a file's stamps are re-based (when they are: see ``_origins``)."""
    if start_ns is not None:
        return 'given'
    if grid.start_ns is not None:
        return 'mixed'
    return 'period' if report.first_time_s is None else 'relative'


def _origins(files: Sequence[_File], start_ns: int | None) -> list[int]:
    """The stamp [ns] of each file's grid slot 0; fills in each report's first stamp.

    Files whose time column is absolute keep the log's time (unless ``start_ns`` is given);
    otherwise the files follow one another from ``start_ns`` (default ``DEFAULT_START_NS``, so
    that an import is deterministic), ``SEGMENT_SEPARATION_S`` apart.

    Raises:
        DatasetError: two files with absolute times overlap in time (names both and spans).
    """
    period_ns = round(files[0].grid.period_s * 1e9)
    absolute = [f.grid.start_ns for f in files]
    if start_ns is None and all(origin is not None for origin in absolute):
        origins = [int(origin) for origin in absolute if origin is not None]
        for file in files:
            file.report.time_base = 'absolute'
    else:
        separation = math.ceil(SEGMENT_SEPARATION_S / files[0].grid.period_s)
        origins, offset = [], 0
        for file in files:
            origins.append(
                (DEFAULT_START_NS if start_ns is None else start_ns) + offset * period_ns
            )
            offset += int(file.grid.segments[-1].slots[-1]) + separation
            file.report.time_base = _time_base(file.grid, file.report, start_ns)
    for file, origin in zip(files, origins, strict=True):
        file.report.start_ns = origin + int(file.grid.segments[0].slots[0]) * period_ns
    _refuse_overlap_in_time(files, origins, period_ns)
    return origins


def _refuse_overlap_in_time(files: Sequence[_File], origins: list[int], period_ns: int) -> None:
    """Refuse two files whose stamps overlap (absolute time columns of one stretch of time)."""
    spans = sorted(
        (
            (f.report.start_ns, origin + int(f.grid.segments[-1].slots[-1]) * period_ns, f.report)
            for f, origin in zip(files, origins, strict=True)
        ),
        key=lambda span: span[0],
    )
    for (_, last, before), (first, end, after) in itertools.pairwise(spans):
        shared = (last - first) // period_ns + 1
        if 0 < shared < MIN_SHARED_ROWS:  # a logger repeating the rows around a file change
            logger.warning(
                'import: %s repeats the last %d sample time(s) of %s (%s): kept once, from %s',
                after.source, shared, before.source, iso_utc(last), before.source,
            )  # fmt: skip
        elif first <= last:
            raise DatasetError(
                f'import: {after.source} ({iso_utc(first)} to {iso_utc(end)}) overlaps '
                f"{before.source} (to {iso_utc(last)}) in time: the bag keeps the logs' "
                'absolute times, and one bag cannot hold two logs of one stretch of time; import '
                'them into separate bags'
            )


def _recording(
    files: Sequence[_File], origins: Sequence[int], joints: tuple[str, ...], source: str
) -> Recording:
    """The segments of every file in time order on one grid, as one recording."""
    period_ns = round(files[0].grid.period_s * 1e9)
    stamps: list[np.ndarray] = []
    starts: list[int] = []
    parts: list[dict[str, np.ndarray]] = []
    n_samples, last = 0, None
    for origin, file in sorted(zip(origins, files, strict=True), key=lambda pair: pair[0]):
        for segment in file.grid.segments:
            stamp = origin + segment.slots * period_ns
            keep = slice(None) if last is None else stamp > last  # a repeated time kept once
            if np.count_nonzero(np.ones_like(stamp, dtype=bool)[keep]) < 2:
                continue
            starts.append(n_samples)
            stamps.append(stamp[keep])
            parts.append({key: value[keep] for key, value in segment.values.items()})
            n_samples += len(stamps[-1])
            last = int(stamps[-1][-1])
    velocity = [
        part['velocity']
        if 'velocity' in part
        else np.gradient(part['position'], (stamp - stamp[0]) * 1e-9, axis=0)
        for part, stamp in zip(parts, stamps, strict=True)
    ]

    def joined(key: str) -> np.ndarray | None:
        return np.concatenate([part[key] for part in parts]) if key in parts[0] else None

    return Recording(
        joints=joints,
        stamps_ns=np.concatenate(stamps),
        position=np.concatenate([part['position'] for part in parts]),
        velocity=np.concatenate(velocity),
        current=joined('current'),
        joint_torque=joined('torque'),
        source=source,
        segment_starts=tuple(starts),
    )


def _time_column(mapping: ImportMapping) -> str:
    return 'time' if mapping.time is None else str(mapping.time.column)


def import_logs(
    sources: Sequence[Path | str],
    mapping: ImportMapping,
    out: Path | str,
    *,
    robot: RobotConfig | None = None,
    velocity_from_position: bool = True,
    overwrite: bool = False,
    start_ns: int | None = None,
) -> list[ImportReport]:
    """Import CSV or NPZ logs (files, or folders of them) into one bag in the bag contract.

    Args:
        sources: the log files, or folders whose log files are taken in name order.
        mapping: which columns hold what, in which unit, and the resample policy.
        out: the bag folder to write.
        robot: when given, the joints must be the robot's (reordered to its order), its IPO
            period is the grid's (unless the policy names one), values are checked against its
            limits, and its topics are used.
        velocity_from_position: differentiate position along each segment when the mapping has
            no velocity columns.
        overwrite: replace an existing bag folder.
        start_ns: stamp of the first sample [ns since epoch], re-basing the logs' times. By
            default a time column of absolute times (since the epoch) is kept as the stamps,
            and other logs start at ``DEFAULT_START_NS``; each report says which it was.

    Returns:
        Per file, what was read, dropped, snapped or resampled, and written.

    Raises:
        ConfigError: the mapping does not fit the log or the robot (missing column, joint names,
            no velocity while ``velocity_from_position`` is False, a format the file's first
            bytes contradict), or one log is given twice (same file, same bytes, or the same
            samples after parsing).
        DatasetError: unreadable log, non-numeric or (under 'refuse') non-finite, implausible or
            beyond-limits cells (each names line and column), more than half of the rows to drop
            for implausible or beyond-limits values, stamps
            backwards, repeated or (under 'snap') off the grid, no segment long enough, or files
            on different grids.
        OutputError: ``out`` is refused (``outputs.check_bag_output``: not a bag, or a bag
            without ``overwrite``, or an input), or writing failed; ``out`` is then as it was
            (the bag is written beside it and moved there whole: ``staged_bag``).
    """
    out = Path(out)
    order = _joint_order(mapping, robot)
    if mapping.joints[0].velocity is None and not velocity_from_position:
        raise ConfigError(
            f'{mapping.where}: no velocity columns are mapped and velocity_from_position is off'
        )
    files = log_files(sources)
    read = [_read_file(source, mapping, robot, order) for source in files]
    periods = {file.report.period_s for file in read}
    if len(periods) > 1:
        found = ', '.join(f'{f.report.source}: {f.report.period_s * 1e3:g} ms' for f in read)
        raise DatasetError(
            f'the logs are on different sampling grids ({found}); set resample.period_s and '
            'resample.method: interpolate to put them on one'
        )
    check_distinct_samples([file.grid for file in read], files)  # the same data in other bytes
    check_shared_rows([file.rows for file in read], _time_column(mapping))  # files that overlap
    where = str(files[0]) if len(files) == 1 else f'{files[0].parent} ({len(files)} files)'
    joints = tuple(mapping.joints[i].name for i in order)
    recording = _recording(read, _origins(read, start_ns), joints, where)
    # Nothing impossible reaches a bag: the plausibility gate (the robot's limits when known).
    check_motion(
        recording.joints,
        recording.stamps_ns,
        recording.position,
        recording.velocity,
        limits=robot.limits if robot else None,
        where=where,
    )
    if robot is not None:
        _check_efforts(recording, robot, where)
        # ... nor a motion that contradicts itself (the gate train and replay apply).
        KinematicConsistency.for_robot(robot, recording.joints).check(
            recording.stamps_ns, recording.position, recording.velocity, where=where,
            starts=recording.segment_starts,
        )  # fmt: skip
    # Written beside ``out`` and moved there whole: an interrupted import leaves no bag that
    # looks complete (``BagWriter`` closes a bag with its metadata however it is stopped).
    with staged_bag(out, overwrite=overwrite, inputs=files) as staged:
        write_recording(recording, staged, topics=robot.topics if robot else None)
    reports = [file.report for file in read]
    for report in reports:
        report.out = out
        report.has_current = recording.current is not None
        report.has_joint_torque = recording.joint_torque is not None
        if robot is not None:
            report.currents_topic = robot.topics.motor_currents
        logger.info('imported %s', report.summary())
    return reports


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
    """Import one CSV or NPZ log file into a bag; ``import_logs`` for one file."""
    return import_logs(
        [source],
        mapping,
        out,
        robot=robot,
        velocity_from_position=velocity_from_position,
        overwrite=overwrite,
        start_ns=start_ns,
    )[0]
