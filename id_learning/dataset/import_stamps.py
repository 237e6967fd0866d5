"""Time stamps of an imported log: snapped onto the controller's sampling grid, or a fixed period.

Controllers sample on a fixed grid (the IPO cycle); the jitter in logged time stamps comes from
the logging path, so a stamp within ``jitter_tolerance`` periods of a grid point is moved onto it.
Missing grid points are gaps: counted, never filled.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from id_learning.dataset.import_mapping import UNITS, ImportMapping
from id_learning.dataset.import_readers import LogTable
from id_learning.errors import DatasetError
from id_learning.robot.config import RobotConfig

__all__ = ['Stamps', 'log_stamps']

_PERIOD_RESOLUTION_NS = 100_000  # estimated periods are rounded to 0.1 ms
_ROBOT_PERIOD_MATCH = 0.1  # a median step within 10 % of the robot's IPO period is that period


@dataclass(frozen=True)
class Stamps:
    """The stamps written [ns], the sampling period [s], and what snapping did to get them."""

    stamps_ns: np.ndarray
    period_s: float
    max_jitter_s: float = 0.0
    n_snapped: int = 0
    n_gaps: int = 0


def _count_gaps(slots: np.ndarray) -> int:
    return int(np.sum(np.diff(slots) - 1))


def _stamps_on_period(row_index: np.ndarray, period_s: float, start_ns: int) -> Stamps:
    """Stamp k = start + k * period, k counting data rows from the first one kept."""
    period_ns = round(period_s * 1e9)
    slots = row_index - row_index[0]
    return Stamps(start_ns + slots * period_ns, period_ns * 1e-9, n_gaps=_count_gaps(slots))


def _snapped_stamps(
    time_raw: np.ndarray,
    positions: np.ndarray,
    table: LogTable,
    *,
    mapping: ImportMapping,
    robot: RobotConfig | None,
    start_ns: int,
) -> Stamps:
    """Snap logged stamps onto the grid t0 + k * period and shift them to ``start_ns``.

    The grid origin t0 is the median deviation from a grid through the first stamp, so that a
    jittered first stamp does not shift the grid.

    Raises:
        DatasetError: time goes backwards, a stamp is off the grid by more than the tolerance, or
            two stamps fall into one grid slot (names the rows).
    """
    spec = mapping.time
    assert spec is not None  # called only for mappings with a time column
    factor = UNITS['time'][spec.unit] * spec.scale * 1e9
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
    return Stamps(
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


def log_stamps(
    rows: np.ndarray,
    keep: np.ndarray,
    table: LogTable,
    *,
    mapping: ImportMapping,
    robot: RobotConfig | None,
    start_ns: int,
) -> Stamps:
    """Stamps of the kept rows, from the time column (``rows[:, 0]``) or the fixed period."""
    if mapping.time is not None:
        positions = table.positions(len(keep))[keep]
        return _snapped_stamps(
            rows[:, 0], positions, table, mapping=mapping, robot=robot, start_ns=start_ns
        )
    assert mapping.period_s is not None  # ImportMapping guarantees one time base
    return _stamps_on_period(np.flatnonzero(keep), mapping.period_s, start_ns)
