"""Values of an imported log: SI conversion, motor side to joint side, and the row checks.

Two checks name the file, the line (CSV) or row (NPZ), the column and the value:

- implausible values, which no arm can have: with a robot config, beyond its limits by a wide
  margin (positions a whole joint range or a turn, whichever is larger, outside them; velocities,
  currents and torques ``IMPLAUSIBLE_FACTOR`` times what the limits allow); without one,
  non-physical magnitudes (``MAGNITUDE_BOUNDS``). Corrupt rows of a logger look like this (values
  of 1e306 in a log's first lines), so the mapping's ``implausible_policy`` may drop them;
- the plausibility gate's bounds (``dataset.plausibility``), with a robot config only: a value
  past them but not implausible is a limit question when just beyond the limit (the config's
  limit, an encoder offset, an arm past a soft limit), else a wrong unit, scale or offset; the
  message says which (``plausibility.beyond_hint``). ``beyond_limits_policy`` may drop such rows
  (a drive's garbage samples).

Rows dropped by both policies together may be at most ``MAX_DROPPED_SHARE`` of the rows: more is
a wrong mapping or robot config, refused whatever the policies.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from id_learning.dataset.import_mapping import UNITS, ColumnSpec, MotorSide
from id_learning.dataset.plausibility import (
    POSITION_MARGIN_RAD,
    TORQUE_FACTOR,
    VELOCITY_FACTOR,
    beyond_hint,
    beyond_position,
    beyond_rate,
    farthest_position,
    reads_as_degrees,
)
from id_learning.errors import ConfigError, DatasetError
from id_learning.robot.config import RobotConfig
from id_learning.robot.drives import (
    current_from_motor_torque,
    joint_from_motor_motion,
    joint_torque_from_motor_side,
    reduction_matrix,
)

__all__ = [
    'IMPLAUSIBLE_FACTOR',
    'MAGNITUDE_BOUNDS',
    'MAX_DROPPED_SHARE',
    'Field',
    'RowChecks',
    'apply_row_policies',
    'joint_side',
    'si_values',
]

logger = logging.getLogger(__name__)

#: Velocities, currents and torques this many times what the robot's limits allow are implausible.
IMPLAUSIBLE_FACTOR = 10.0
#: More than this share of the rows implausible or past the gate is a unit, mapping or robot
#: config error, never dropped.
MAX_DROPPED_SHARE = 0.5
#: Without a robot config: magnitudes no joint of an arm reaches (rad, rad/s, A, N*m).
MAGNITUDE_BOUNDS = {'position': 1e3, 'velocity': 1e3, 'current': 1e4, 'torque': 1e6}
_UNIT_OF = {'position': 'rad', 'velocity': 'rad/s', 'current': 'A', 'torque': 'N*m'}
_GATE_FACTOR = {'velocity': VELOCITY_FACTOR, 'current': TORQUE_FACTOR, 'torque': TORQUE_FACTOR}
_DEGREES_REMEDY = 'set its unit: deg'
#: NPZ dtype kinds that hold no real numbers, and what they hold.
_NOT_NUMBERS = {
    'b': 'true/false values',
    'c': 'complex numbers',
    'M': 'dates',
    'm': 'time differences',
    'V': 'records (a structured array)',
}
#: The coarsest step a time array's float may have at its largest value, as a share of the
#: array's median step: far below the jitter a grid tolerates.
_TIME_RESOLUTION = 0.1


@dataclass(frozen=True)
class Field:
    """One mapped column: the quantity it holds, for which joint (None for time)."""

    quantity: str
    joint: str | None
    spec: ColumnSpec

    def describe(self) -> str:
        """Column and meaning, for messages."""
        meaning = 'time' if self.joint is None else f'joint {self.joint} {self.quantity}'
        return f'column {self.spec.describe()} ({meaning})'


def check_array_types(
    columns: Mapping[str | int, np.ndarray], fields: Sequence[Field], source: Path
) -> None:
    """Refuse mapped NPZ arrays that hold no real numbers; warn of floats too narrow for them.

    A bool array (``i > 0``) would import as 0 and 1, a complex one without its imaginary part, a
    date or a structured array as no number at all: each is refused. A time array whose float
    resolves less than ``_TIME_RESOLUTION`` of its median step at its largest value (float32
    epoch seconds step by 128 s) cannot tell the samples apart: refused. float16 keeps 11
    significant bits (positions near 37 deg step by 0.03 deg, a quantisation the identification
    would take for the motion): a warning names the step at the largest magnitude, in its unit.

    Raises:
        DatasetError: names the file, the array, its dtype and what to store instead.
    """
    seen: set[str | int] = set()
    for item in fields:
        values = columns.get(item.spec.column)
        if values is None or item.spec.column in seen:
            continue
        seen.add(item.spec.column)
        kind = values.dtype.kind
        if kind in _NOT_NUMBERS:
            raise DatasetError(
                f'{source}: array {item.spec.column!r} ({item.describe()}) is '
                f'{_NOT_NUMBERS[kind]} (dtype {values.dtype}), not real numbers; store it as '
                'float64 (time too: seconds as float64, or nanoseconds as int64)'
            )
        if kind != 'f':
            continue
        finite = np.abs(values[np.isfinite(values)].astype(np.float64))
        largest = float(finite.max()) if finite.size else 1.0
        step = float(np.spacing(values.dtype.type(largest)))
        unit = item.spec.unit
        if item.quantity == 'time':
            steps = np.diff(values[np.isfinite(values)].astype(np.float64))
            sampling = float(np.median(np.abs(steps))) if steps.size else math.inf
            if step > _TIME_RESOLUTION * sampling:
                raise DatasetError(
                    f'{source}: array {item.spec.column!r} (time) is {values.dtype}: at its '
                    f'largest value {largest:.6g} {unit} it resolves only {step:.3g} {unit}, '
                    f'coarser than a tenth of its median step ({sampling:.3g} {unit}); store '
                    'time as float64 (or int64 nanoseconds)'
                )
        elif values.dtype.itemsize < 4:
            logger.warning(
                '%s: array %r is %s: at its largest magnitude %.4g %s it resolves only %.3g %s; '
                'store it as float32 or float64',
                source, item.spec.column, values.dtype, largest, unit, step, unit,
            )  # fmt: skip


def si_values(raw: np.ndarray, fields: Sequence[Field]) -> dict[str, np.ndarray]:
    """(N, n) values of each mapped joint quantity in SI, in joint order."""
    out: dict[str, np.ndarray] = {}
    for quantity in _UNIT_OF:
        columns = [
            raw[:, i] * (UNITS[quantity][item.spec.unit] * item.spec.scale) + item.spec.offset
            for i, item in enumerate(fields)
            if item.quantity == quantity
        ]
        if columns:
            out[quantity] = np.column_stack(columns)
    return out


def joint_side(
    values: dict[str, np.ndarray],
    motors: MotorSide,
    order: np.ndarray,
    robot: RobotConfig | None,
    where: str,
) -> dict[str, np.ndarray]:
    """Map the motor-side quantities to the joint side (see ``MotorSide``).

    Currents stay currents in the bag contract: the joint torque K^T (k_t * i) is written as the
    current the robot config's drive of each joint would need for it, so that the package's
    tau_u = gear_ratio * torque_constant * current gives that torque back.

    Args:
        values: (N, n) SI values per quantity, in ``order`` (robot order).
        motors: the mapping's motor side, in mapping order.
        order: indices of the written joints into the mapping's joints.
        robot: the robot config; needed for currents.
        where: the mapping file, for messages.

    Raises:
        ConfigError: currents are mapped motor side without a robot config.
    """
    gear = np.asarray(motors.gear_ratio, dtype=float)[order]
    coupling = (
        None if motors.coupling is None else np.asarray(motors.coupling)[np.ix_(order, order)]
    )
    reduction = reduction_matrix(gear, coupling)
    out = dict(values)
    for quantity in ('position', 'velocity'):
        if quantity in motors.signals:
            out[quantity] = joint_from_motor_motion(values[quantity], reduction)
    if 'current' in motors.signals:
        if robot is None:
            raise ConfigError(
                f'{where}: motors maps currents motor side; pass --robot so that they can be '
                "written as the currents of the robot config's drives"
            )
        kt = np.asarray(motors.torque_constant, dtype=float)[order]
        torque = joint_torque_from_motor_side(values['current'] * kt, reduction)
        out['current'] = current_from_motor_torque(torque, robot.drives)
    return out


class RowChecks:
    """The implausible-value and gate bounds of each written column, in SI joint side.

    Args:
        fields: the mapped columns (time first when there is one).
        robot: the robot config, or None (magnitude bounds only, no gate).
    """

    def __init__(self, fields: Sequence[Field], robot: RobotConfig | None) -> None:
        self.fields = [item for item in fields if item.joint is not None]
        self.robot = robot

    def _fields_of(self, quantity: str) -> list[Field]:
        return [item for item in self.fields if item.quantity == quantity]

    def _limit(self, robot: RobotConfig, quantity: str) -> np.ndarray:
        """(n,) the limit of a velocity [rad/s], current [A] or torque [N*m] per joint."""
        limits = robot.limits
        if quantity == 'velocity':
            return limits.velocity
        if quantity == 'current':
            return current_from_motor_torque(limits.torque, robot.drives)
        return limits.torque

    def _bounds(self, quantity: str, wide: bool) -> tuple[np.ndarray, np.ndarray] | None:
        """(low, high) per joint, or None when the quantity has no bound at this level."""
        robot = self.robot
        if robot is None:
            if not wide:
                return None
            magnitude = MAGNITUDE_BOUNDS[quantity]
            return np.array([-magnitude]), np.array([magnitude])
        limits = robot.limits
        if quantity == 'position':
            span = limits.position_upper - limits.position_lower
            margin = np.maximum(span, 2.0 * math.pi) if wide else POSITION_MARGIN_RAD
            return limits.position_lower - margin, limits.position_upper + margin
        bound = self._limit(robot, quantity) * (
            IMPLAUSIBLE_FACTOR if wide else _GATE_FACTOR[quantity]
        )
        return -bound, bound

    def violations(self, values: dict[str, np.ndarray], wide: bool) -> np.ndarray:
        """(N,) True for rows with a value outside the bounds of this level."""
        bad = np.zeros(len(next(iter(values.values()))), dtype=bool)
        for quantity, array in values.items():
            if wide:  # finite cells that overflow in the motor-side conversion (rows with
                # empty cells are not kept, so their NaN never counts here)
                bad |= ~np.isfinite(array).all(axis=1)
            bounds = self._bounds(quantity, wide)
            if bounds is not None:
                bad |= ((array < bounds[0]) | (array > bounds[1])).any(axis=1)
        return bad

    def describe(
        self,
        values: dict[str, np.ndarray],
        row: int,
        *,
        wide: bool,
        keep: np.ndarray | None = None,
        hint: bool = True,
    ) -> tuple[str, int]:
        """The first column of ``row`` outside the bounds of this level, described, and its joint.

        Args:
            values: (N, n) SI joint-side values per quantity.
            row: the row to describe.
            wide: the implausible level (True) or the gate (False).
            keep: (N,) the rows whose values the degrees rule reads; None: all.
            hint: add what the value most likely is and its remedy (``beyond_hint``).
        """
        for quantity, array in values.items():
            if wide and not np.isfinite(array[row]).all():
                j = int(np.argmax(~np.isfinite(array[row])))
                item = self._fields_of(quantity)[j]
                return f'{item.describe()}: no finite value after the motors conversion', j
            bounds = self._bounds(quantity, wide)
            if bounds is None:
                continue
            low = np.broadcast_to(bounds[0], array.shape[1])
            high = np.broadcast_to(bounds[1], array.shape[1])
            outside = (array[row] < low) | (array[row] > high)
            if outside.any():
                j = int(np.argmax(outside))
                value, unit = float(array[row, j]), _UNIT_OF[quantity]
                column = array[:, j] if keep is None else array[keep, j]
                if wide:
                    text = f'is outside [{low[j]:.4g}, {high[j]:.4g}] {unit}'
                    if hint and self._reads_as_degrees(quantity, column, j):
                        text += '; ' + beyond_hint(math.inf, True, _DEGREES_REMEDY)
                else:
                    text = self._beyond(quantity, value, column, j, hint)
                return f'{self._fields_of(quantity)[j].describe()}: {value:.6g} {unit} {text}', j
        raise AssertionError('describe() called for a row within the bounds')

    def _reads_as_degrees(self, quantity: str, column: np.ndarray, j: int) -> bool:
        if quantity != 'position' or self.robot is None:
            return False
        limits = self.robot.limits
        return reads_as_degrees(column, limits.position_lower[j], limits.position_upper[j])

    def _beyond(self, quantity: str, value: float, column: np.ndarray, j: int, hint: bool) -> str:
        """How far a value past the gate lies beyond its limit, and (``hint``) what it is."""
        robot = self.robot
        assert robot is not None  # the gate has bounds only with a robot config
        lower, upper = robot.limits.position_lower[j], robot.limits.position_upper[j]

        def excess(x: float) -> tuple[float, str]:
            if quantity == 'position':
                return beyond_position(x, lower, upper)
            limit = float(self._limit(robot, quantity)[j])
            return beyond_rate(x, limit, _GATE_FACTOR[quantity], _UNIT_OF[quantity])

        share, text = excess(value)
        if quantity == 'position':
            text += f' (the gate allows {POSITION_MARGIN_RAD:g} rad)'
        if not hint:  # a dropped row's reason: no pass over the column per row
            return f'is {text}'
        if quantity == 'position':
            farthest = farthest_position(column, lower, upper)
        else:
            farthest = float(column[np.argmax(np.abs(column))])
        far_share, _ = excess(farthest)
        if far_share > share:
            text += f'; the farthest value of this column lies {100 * far_share:.3g} % beyond'
        degrees = self._reads_as_degrees(quantity, column, j)
        return f'is {text}; {beyond_hint(max(share, far_share), degrees, _DEGREES_REMEDY)}'


def apply_row_policies(
    checks: RowChecks,
    values: dict[str, np.ndarray],
    keep: np.ndarray,
    positions: np.ndarray,
    *,
    implausible_policy: str,
    beyond_limits_policy: str,
    where: str,
    label: str,
) -> tuple[np.ndarray, list[tuple[int, str]]]:
    """Apply the implausible-value and beyond-limits policies to the rows kept so far.

    Args:
        checks: the bounds of the written columns.
        values: (N, n) SI joint-side values per quantity.
        keep: (N,) rows kept by the NaN policy.
        positions: (N,) each row's line (CSV) or row (NPZ), for messages.
        implausible_policy: 'refuse' or 'drop' rows with an implausible value.
        beyond_limits_policy: 'refuse' or 'drop' rows past the gate but not implausible.
        where: the log file, for messages.
        label: what ``positions`` count: 'line' or 'row'.

    Returns:
        The rows kept, and (position, reason) of each row dropped.

    Raises:
        DatasetError: under 'refuse', the first row the policy covers; whatever the policies,
            more than ``MAX_DROPPED_SHARE`` of the rows to drop.
    """
    n_rows = max(int(np.count_nonzero(keep)), 1)
    implausible = keep & checks.violations(values, wide=True)
    if implausible.any():
        row = int(np.argmax(implausible))
        text, _ = checks.describe(values, row, wide=True, keep=keep)
        n_bad = int(implausible.sum())
        if n_bad > MAX_DROPPED_SHARE * n_rows:
            raise DatasetError(
                f'{where}: {label} {positions[row]}, {text}; {n_bad} of {n_rows} rows hold '
                'implausible values: a wrong unit, scale, offset or column in the mapping, not '
                'corrupt rows'
            )
        if implausible_policy == 'refuse':
            raise DatasetError(
                f'{where}: {label} {positions[row]}, {text}: no arm has such a value (a corrupt '
                f'row?); {n_bad} rows hold implausible values. Fix the log or set '
                'implausible_policy: drop'
            )
    past_gate = keep & ~implausible & checks.violations(values, wide=False)
    if past_gate.any():
        row = int(np.argmax(past_gate))
        text, _ = checks.describe(values, row, wide=False, keep=keep & ~implausible)
        n_past, n_drop = int(past_gate.sum()), int(past_gate.sum() + implausible.sum())
        if n_drop > MAX_DROPPED_SHARE * n_rows:
            raise DatasetError(
                f'{where}: {label} {positions[row]}, {text}; {n_drop} of {n_rows} rows are '
                'past the plausibility gate or implausible: too many to drop, the mapping (unit, '
                'scale, offset, column) or the robot config is wrong'
            )
        if beyond_limits_policy == 'refuse':
            raise DatasetError(
                f'{where}: {label} {positions[row]}, {text} ({n_past} rows past the '
                'plausibility gate); if they are corrupt rows, set beyond_limits_policy: drop '
                'to drop them (reported)'
            )
    dropped = [
        (
            int(positions[row]),
            f'{kind} {checks.describe(values, int(row), wide=wide, hint=False)[0]}',
        )
        for kind, wide, rows in (
            ('implausible', True, implausible),
            ('beyond the limits,', False, past_gate),
        )
        for row in np.flatnonzero(rows)
    ]
    return keep & ~implausible & ~past_gate, dropped
