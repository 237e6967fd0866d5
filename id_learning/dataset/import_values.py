"""Values of an imported log: SI conversion, motor side to joint side, and the row checks.

Two checks name the file, the line (CSV) or row (NPZ), the column and the value:

- implausible values, which no arm can have: with a robot config, beyond its limits by a wide
  margin (positions a whole joint range or a turn, whichever is larger, outside them; velocities,
  currents and torques ``IMPLAUSIBLE_FACTOR`` times what the limits allow); without one,
  non-physical magnitudes (``MAGNITUDE_BOUNDS``). Corrupt rows of a logger look like this (values
  of 1e306 in a log's first lines), so the mapping's ``implausible_policy`` may drop them;
- the plausibility gate's bounds (``dataset.plausibility``), with a robot config only: a value
  past them but not implausible is a wrong unit, offset or config, never dropped.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from id_learning.dataset.import_mapping import UNITS, ColumnSpec, MotorSide
from id_learning.dataset.plausibility import (
    LIMITS_HINT,
    POSITION_MARGIN_RAD,
    TORQUE_FACTOR,
    VELOCITY_FACTOR,
)
from id_learning.errors import ConfigError, DatasetError
from id_learning.robot.config import RobotConfig

__all__ = [
    'IMPLAUSIBLE_FACTOR',
    'MAGNITUDE_BOUNDS',
    'Field',
    'RowChecks',
    'joint_side',
    'si_values',
]

#: Velocities, currents and torques this many times what the robot's limits allow are implausible.
IMPLAUSIBLE_FACTOR = 10.0
#: More than this share of the rows implausible is a unit or mapping error, never dropped.
MAX_IMPLAUSIBLE_SHARE = 0.5
#: Without a robot config: magnitudes no joint of an arm reaches (rad, rad/s, A, N*m).
MAGNITUDE_BOUNDS = {'position': 1e3, 'velocity': 1e3, 'current': 1e4, 'torque': 1e6}
_UNIT_OF = {'position': 'rad', 'velocity': 'rad/s', 'current': 'A', 'torque': 'N*m'}


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
    coupling = np.eye(len(order)) if motors.coupling is None else np.asarray(motors.coupling)
    reduction = gear[:, None] * coupling[np.ix_(order, order)]
    inverse = np.linalg.inv(reduction)
    out = dict(values)
    for quantity in ('position', 'velocity'):
        if quantity in motors.signals:
            out[quantity] = values[quantity] @ inverse.T
    if 'current' in motors.signals:
        if robot is None:
            raise ConfigError(
                f'{where}: motors maps currents motor side; pass --robot so that they can be '
                "written as the currents of the robot config's drives"
            )
        kt = np.asarray(motors.torque_constant, dtype=float)[order]
        torque = (values['current'] * kt) @ reduction
        out['current'] = torque / (robot.drives.gear_ratio * robot.drives.torque_constant)
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

    def _bounds(self, quantity: str, wide: bool) -> tuple[np.ndarray, np.ndarray] | None:
        """(low, high) per joint, or None when the quantity has no bound at this level."""
        robot = self.robot
        if robot is None:
            if not wide:
                return None
            magnitude = MAGNITUDE_BOUNDS[quantity]
            return np.array([-magnitude]), np.array([magnitude])
        limits, factor = robot.limits, IMPLAUSIBLE_FACTOR if wide else None
        if quantity == 'position':
            span = limits.position_upper - limits.position_lower
            margin = np.maximum(span, 2.0 * math.pi) if wide else POSITION_MARGIN_RAD
            return limits.position_lower - margin, limits.position_upper + margin
        bound: np.ndarray
        if quantity == 'velocity':
            bound = limits.velocity * (factor or VELOCITY_FACTOR)
        else:
            bound = limits.torque * (factor or TORQUE_FACTOR)
            if quantity == 'current':
                bound = bound / (robot.drives.gear_ratio * robot.drives.torque_constant)
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

    def describe(self, values: dict[str, np.ndarray], row: int, wide: bool) -> tuple[str, int]:
        """The first column of ``row`` outside the bounds, described, and its joint's index."""
        for quantity, array in values.items():
            if wide and not np.isfinite(array[row]).all():
                j = int(np.argmax(~np.isfinite(array[row])))
                item = self._fields_of(quantity)[j]
                return f'{item.describe()}: no finite value after the motors conversion', j
            bounds = self._bounds(quantity, wide)
            if bounds is None:
                continue
            low, high = np.broadcast_to(bounds[0], array.shape[1]), bounds[1]
            high = np.broadcast_to(high, array.shape[1])
            outside = (array[row] < low) | (array[row] > high)
            if outside.any():
                j = int(np.argmax(outside))
                item = self._fields_of(quantity)[j]
                unit = _UNIT_OF[quantity]
                text = (
                    f'{item.describe()}: {array[row, j]:.6g} {unit} is outside '
                    f'[{low[j]:.4g}, {high[j]:.4g}] {unit}'
                )
                as_radians = np.radians(array[:, j])
                finite = np.isfinite(as_radians)
                if quantity == 'position' and self.robot is not None and finite.any():
                    gate = self._bounds('position', wide=False)
                    assert gate is not None
                    fits = as_radians[finite]
                    if np.all((fits >= gate[0][j]) & (fits <= gate[1][j])):
                        text += (
                            '; read as degrees every value of this column fits the limits: '
                            'set its unit: deg'
                        )
                return text, j
        raise AssertionError('describe() called for a row within the bounds')


def refuse_implausible(
    checks: RowChecks,
    values: dict[str, np.ndarray],
    keep: np.ndarray,
    positions: np.ndarray,
    *,
    policy: str,
    where: str,
    label: str,
) -> tuple[np.ndarray, list[tuple[int, str]]]:
    """Apply the implausible-value policy: the rows kept, and (position, reason) of those dropped.

    Then refuse, whatever the policy, the first kept row past the gate's bounds.

    Raises:
        DatasetError: under 'refuse', the first implausible value; a value past the gate.
    """
    implausible = keep & checks.violations(values, wide=True)
    dropped: list[tuple[int, str]] = []
    if implausible.any():
        rows = np.flatnonzero(implausible)
        share = rows.size / max(int(np.count_nonzero(keep)), 1)
        if share > MAX_IMPLAUSIBLE_SHARE:
            text, _ = checks.describe(values, int(rows[0]), wide=True)
            raise DatasetError(
                f'{where}: {label} {positions[rows[0]]}, {text}; {rows.size} of '
                f'{int(np.count_nonzero(keep))} rows hold implausible values: a wrong unit, '
                'scale, offset or column in the mapping, not corrupt rows'
            )
        if policy == 'refuse':
            text, _ = checks.describe(values, int(rows[0]), wide=True)
            raise DatasetError(
                f'{where}: {label} {positions[rows[0]]}, {text}: no arm has such a value (a '
                f'corrupt row?); {rows.size} rows hold implausible values. Fix the log or set '
                'implausible_policy: drop'
            )
        dropped = [
            (int(positions[row]), 'implausible ' + checks.describe(values, int(row), True)[0])
            for row in rows
        ]
        keep = keep & ~implausible
    past_gate = keep & checks.violations(values, wide=False)
    if past_gate.any():
        row = int(np.argmax(past_gate))
        text, _ = checks.describe(values, row, wide=False)
        raise DatasetError(
            f'{where}: {label} {positions[row]}, {text}: beyond what the plausibility gate '
            f"allows ({int(past_gate.sum())} rows); check the column's unit, scale and offset; "
            f'{LIMITS_HINT}'
        )
    return keep, dropped
