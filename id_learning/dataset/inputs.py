"""What a model takes as input: (q, v, a) made from a recording, and how they are made.

A controller sends its feed-forward a smooth reference: positions, velocities and accelerations
of the motion as it is meant to happen, not low-passed at the label filter's 0.3-1.2 Hz. Models
are fitted and scored on inputs made the same way from the recording (``controller``): recorded
positions, recorded velocities smoothed at the robot's ``input_smoothing_hz`` (far above the
motion's band; it only removes sensor noise), accelerations differentiated from them. The
reference study instead low-passes positions and velocities like the labels (``study``).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from id_learning.dataset.signals import differentiate, lowpass
from id_learning.errors import CheckpointError

__all__ = ['InputDefinition', 'Motion']


@dataclass(frozen=True, eq=False)
class Motion:
    """Model inputs along a recording, each (N, n): q [rad], v [rad/s], a [rad/s^2]."""

    q: np.ndarray
    v: np.ndarray
    a: np.ndarray

    def take(self, rows: slice | np.ndarray) -> Motion:
        """The motion on some rows."""
        return Motion(self.q[rows], self.v[rows], self.a[rows])

    @classmethod
    def concatenate(cls, parts: Sequence[Motion]) -> Motion:
        """Motions one after the other."""
        return cls(*(np.concatenate([getattr(m, k) for m in parts]) for k in ('q', 'v', 'a')))


@dataclass(frozen=True)
class InputDefinition:
    """How (q, v, a) are made from recorded positions and velocities.

    Attributes:
        name: 'controller' (a controller's smooth reference) or 'study' (the study's inputs).
        velocity_cutoff_hz: (n,) cut-off of the zero-phase Butterworth low-pass applied to the
            recorded velocities [Hz].
        position_cutoff_hz: (n,) the same for positions; None keeps the recorded positions.
        filter_order: Butterworth order of each pass.

    Accelerations are central differences of the smoothed velocities.
    """

    name: str
    velocity_cutoff_hz: tuple[float, ...]
    position_cutoff_hz: tuple[float, ...] | None = None
    filter_order: int = 4

    @classmethod
    def controller(cls, smoothing_hz: np.ndarray, filter_order: int = 4) -> InputDefinition:
        """Recorded positions; velocities smoothed at ``smoothing_hz`` (the robot config's)."""
        return cls('controller', _floats(smoothing_hz), None, filter_order)

    @classmethod
    def study(cls, cutoff_hz: np.ndarray, filter_order: int = 4) -> InputDefinition:
        """Positions and velocities low-passed like the labels, as the reference study does."""
        return cls('study', _floats(cutoff_hz), _floats(cutoff_hz), filter_order)

    def motion(self, position: np.ndarray, velocity: np.ndarray, period_s: float) -> Motion:
        """The inputs along one contiguous recording, position and velocity (N, n) on its grid.

        Raises:
            DatasetError: too few samples for the filter.
        """
        q = np.asarray(position, dtype=float)
        if self.position_cutoff_hz is not None:
            q = lowpass(q, np.asarray(self.position_cutoff_hz), period_s, self.filter_order)
        v = lowpass(velocity, np.asarray(self.velocity_cutoff_hz), period_s, self.filter_order)
        return Motion(q, v, differentiate(v, period_s))

    def describe(self) -> str:
        """One line for reports."""
        positions = (
            'recorded positions'
            if self.position_cutoff_hz is None
            else f'positions low-passed at {_hz(self.position_cutoff_hz)} Hz'
        )
        return (
            f'{self.name} inputs: {positions}, velocities low-passed at '
            f'{_hz(self.velocity_cutoff_hz)} Hz (zero-phase Butterworth, order '
            f'{self.filter_order}), accelerations by central differences of those velocities'
        )

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form; ``from_dict`` rebuilds it."""
        return {
            'name': self.name,
            'position_cutoff_hz': None
            if self.position_cutoff_hz is None
            else list(self.position_cutoff_hz),
            'velocity_cutoff_hz': list(self.velocity_cutoff_hz),
            'filter_order': self.filter_order,
            'acceleration': 'central differences of the smoothed velocities',
            'description': self.describe(),
        }

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> InputDefinition:
        """Rebuild from ``to_dict`` output.

        Raises:
            CheckpointError: a field is missing or malformed.
        """
        try:
            position = data.get('position_cutoff_hz')
            return cls(
                name=str(data['name']),
                velocity_cutoff_hz=_floats(data['velocity_cutoff_hz']),
                position_cutoff_hz=None if position is None else _floats(position),
                filter_order=int(data['filter_order']),
            )
        except (KeyError, TypeError, ValueError) as err:
            raise CheckpointError(f'input definition is incomplete or invalid: {err}') from err


def _floats(values: Any) -> tuple[float, ...]:
    return tuple(float(x) for x in np.asarray(values, dtype=float).ravel())


def _hz(values: Sequence[float]) -> str:
    unique = sorted(set(values))
    return f'{unique[0]:g}' if len(unique) == 1 else '/'.join(f'{x:g}' for x in values)
