"""Time stamps of an imported log: relative times, the grid period, and snapping onto the grid.

Controllers sample on a fixed grid (the IPO cycle); the jitter in logged time stamps comes from
the logging path, so under the 'snap' policy a stamp within ``jitter_tolerance`` periods of a grid
point is moved onto it. Logs at another rate, or whose clock drifts, are resampled instead
(``import_resample``).

A time column that holds absolute times (seconds since the epoch, in any unit: its first value,
with the column's scale and offset, falls between 2000 and 2038, where a message stamp's int32
seconds end) keeps them: the bag's stamps are the log's own, to the microsecond
(``absolute_start_ns``). Any other time column counts from some start of its own (a controller's
uptime, the log's start) and the importer re-bases it.
"""

from __future__ import annotations

from dataclasses import dataclass
from fractions import Fraction
from pathlib import Path

import numpy as np

from id_learning.dataset.import_mapping import UNITS, ColumnSpec, ImportMapping
from id_learning.errors import ConfigError, DatasetError
from id_learning.robot.config import RobotConfig

__all__ = [
    'Snapped',
    'absolute_origin_ns',
    'absolute_start_ns',
    'grid_period_s',
    'relative_times',
    'snap_to_grid',
    'time_s',
]

_PERIOD_RESOLUTION_NS = 100_000  # estimated periods are rounded to 0.1 ms
_ROBOT_PERIOD_MATCH = 0.1  # a median step within 10 % of the robot's IPO period is that period
_INTERPOLATE_HINT = 'or let import resample the log: resample: {method: interpolate}'
#: Absolute times lie in this span [s since the epoch]: from 2000-01-01 (no controller counts its
#: uptime in decades) to 2038-01-19, past which a message stamp's int32 seconds cannot go.
_EPOCH_SPAN_S = (946_684_800, 2**31)
#: An absolute start is kept to the microsecond: a float64 time column of epoch seconds resolves
#: about 0.24 us, so finer digits are the float's, not the log's.
_ABSOLUTE_RESOLUTION_NS = 1000


@dataclass(frozen=True)
class Snapped:
    """Grid indices of the rows, and what snapping moved.

    ``origin_ns``: the time of slot 0 after the first row's [ns] (within the jitter tolerance).
    """

    slots: np.ndarray
    max_jitter_s: float
    n_snapped: int
    origin_ns: int = 0


def time_s(raw: float, spec: ColumnSpec) -> float:
    """A time column's value in seconds: raw * unit * scale + offset."""
    return float(raw) * UNITS['time'][spec.unit] * spec.scale + spec.offset


def absolute_start_ns(first_raw: float, mapping: ImportMapping) -> int | None:
    """The first row's time [ns since the epoch] when the time column is absolute, else None.

    Absolute means its first value in seconds (``time_s``) lies from 2000-01-01 up to
    2038-01-19 03:14:08 UTC (``_EPOCH_SPAN_S``: 2**31 s, where a message stamp's int32 seconds
    end): a wall-clock time, kept as the bag's.
    """
    spec = mapping.time
    if spec is None or not _EPOCH_SPAN_S[0] <= time_s(first_raw, spec) < _EPOCH_SPAN_S[1]:
        return None
    # In exact arithmetic: 1.7e18 ns in a float64 would be off by up to 128 ns.
    ns_per_unit = round(UNITS['time'][spec.unit] * 1e9)
    exact = Fraction(float(first_raw)) * ns_per_unit * Fraction(spec.scale)
    return round(exact + Fraction(spec.offset) * 1_000_000_000)


def absolute_origin_ns(start_ns: int, origin_ns: int = 0) -> int:
    """The stamp of grid slot 0 [ns]: ``origin_ns`` after the first row, to the microsecond."""
    half = _ABSOLUTE_RESOLUTION_NS // 2
    return (start_ns + origin_ns + half) // _ABSOLUTE_RESOLUTION_NS * _ABSOLUTE_RESOLUTION_NS


def relative_times(
    time_raw: np.ndarray, positions: np.ndarray, mapping: ImportMapping, where: Path, label: str
) -> np.ndarray:
    """(N,) seconds from the first row, checked strictly increasing.

    Raises:
        DatasetError: time goes backwards or repeats (names the rows).
    """
    spec = mapping.time
    assert spec is not None  # called only for mappings with a time column
    factor = UNITS['time'][spec.unit] * spec.scale
    times = (time_raw - time_raw[0]) * factor
    steps = np.diff(times)
    if (steps <= 0).any():
        i = int(np.argmax(steps <= 0))
        what = (
            f'repeats the time of {label} {positions[i]}'
            if steps[i] == 0
            else f'goes back in time by {-steps[i] * 1e3:g} ms from {label} {positions[i]}'
        )
        raise DatasetError(
            f'{where}: {label} {positions[i + 1]} {what}; time stamps must increase (a repeated '
            'or out-of-order row, or a time column that wraps)'
        )
    out: np.ndarray = times
    return out


def grid_period_s(
    times_s: np.ndarray, mapping: ImportMapping, robot: RobotConfig | None, where: Path
) -> float:
    """The grid's period [s].

    The policy's; else the robot's IPO period when resampling, or when the median step is within
    10 % of it; else the median step rounded to 0.1 ms.

    Raises:
        DatasetError: snapping a log whose median step is not the robot's IPO period, or a median
            step that rounds to zero.
    """
    policy = mapping.resample
    if policy.period_s is not None:
        if robot is not None and abs(policy.period_s - robot.ipo_period_s) > 1e-12:
            raise ConfigError(
                f'{mapping.where}: resample.period_s {policy.period_s:g} s is not the IPO period '
                f'{robot.ipo_period_s:g} s of robot {robot.name}: its bags must be on its grid '
                "(omit period_s to take the robot's)"
            )
        return float(policy.period_s)
    median_s = float(np.median(np.diff(times_s)))
    if robot is not None:
        ipo_s = robot.ipo_period_s
        if abs(median_s - ipo_s) <= _ROBOT_PERIOD_MATCH * ipo_s:
            return ipo_s
        _refuse_time_unit(median_s, ipo_s, mapping, robot.name, where)
        if policy.method == 'interpolate':
            return ipo_s
        raise DatasetError(
            f'{where}: the log steps {median_s * 1e3:.4g} ms (median), the IPO period of robot '
            f'{robot.name} is {ipo_s * 1e3:g} ms: a bag for this robot must be on its grid; '
            f"{_INTERPOLATE_HINT.removeprefix('or ')} (or correct the robot config's "
            'ipo_period_s)'
        )
    period_ns = round(median_s * 1e9 / _PERIOD_RESOLUTION_NS) * _PERIOD_RESOLUTION_NS
    if period_ns <= 0:
        raise DatasetError(
            f'{where}: the median time step {median_s * 1e3:g} ms rounds to no period (periods '
            'are estimated to 0.1 ms); check the time column and its unit'
        )
    return period_ns * 1e-9


def _refuse_time_unit(
    median_s: float, ipo_s: float, mapping: ImportMapping, robot: str, where: Path
) -> None:
    """Refuse a time column whose median step is the IPO period in another time unit.

    A log in ms declared as s steps 1000 x the IPO period: no resampling mends that.

    Raises:
        DatasetError: names the declared unit, the unit that fits, and the key to set.
    """
    spec = mapping.time
    if spec is None:
        return
    declared = UNITS['time'][spec.unit]
    for unit, factor in UNITS['time'].items():
        if unit == spec.unit:
            continue
        as_unit = median_s * factor / declared
        if abs(as_unit - ipo_s) <= _ROBOT_PERIOD_MATCH * ipo_s:
            raise DatasetError(
                f'{where}: the time column {spec.column!r}, declared in {spec.unit}, steps '
                f'{median_s:.4g} s (median), {median_s / ipo_s:.4g} x the {ipo_s * 1e3:g} ms '
                f'IPO period of robot {robot}; read in {unit} it steps {as_unit * 1e3:.4g} ms, '
                f'the IPO period: the column is in {unit}, not {spec.unit}: a unit problem of '
                f'the time column, which no resampling mends; set time.unit: {unit} in the '
                'mapping'
            )


def snap_to_grid(
    times_s: np.ndarray,
    positions: np.ndarray,
    period_s: float,
    mapping: ImportMapping,
    *,
    where: Path,
    label: str,
) -> Snapped:
    """Snap relative times onto the grid t0 + k * period.

    The grid origin t0 is the median deviation from a grid through the first stamp, so that a
    jittered first stamp does not shift the grid.

    Raises:
        DatasetError: a stamp is off the grid by more than the tolerance, or two stamps fall into
            one grid slot (names the rows and the remedies).
    """
    period_ns = round(period_s * 1e9)
    relative_ns = np.rint(times_s * 1e9).astype(np.int64)
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
            f'{mapping.jitter_tolerance:g} periods ({tolerance_ns * 1e-6:g} ms): the log is not '
            f'sampled on this grid; set resample.period_s to its period, {_INTERPOLATE_HINT}'
        )
    repeated = np.diff(slots) == 0
    if repeated.any():
        i = int(np.argmax(repeated))
        raise DatasetError(
            f'{where}: {label}s {positions[i]} and {positions[i + 1]} fall into the same '
            f'{period_ns * 1e-6:g} ms grid slot (the log is faster than the grid, or a sample '
            f'is repeated); {_INTERPOLATE_HINT}'
        )
    return Snapped(
        slots=slots - slots[0],
        max_jitter_s=float(np.abs(deviation).max()) * 1e-9,
        n_snapped=int(np.count_nonzero(deviation)),
        origin_ns=phase + int(slots[0]) * period_ns,
    )
