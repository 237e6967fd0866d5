"""The range of (q, v, a) a model saw in training, read from its fitted metadata.

Each model family keeps the min-max scalers it was fitted with in ``fitted_metadata()``:

- ``mlp``, ``lstm``: ``input_scaler`` over the 3n columns [q, v, a];
- ``rnea_mlp``: ``state_scaler`` over [q, v] (the inputs of its network h);
- ``delan``, ``lnn``, ``lnn_mlp``: ``scaling.position`` and ``scaling.velocity``;
- ``rnea_lq``: none (a physical model with identified parameters). The robot's joint limits stand
  in, so that a reference far outside the workspace is still flagged.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from functools import cached_property
from typing import Any

import numpy as np

from id_learning.robot.config import RobotConfig

__all__ = ['QUANTITIES', 'RangeViolation', 'TrainingRange', 'training_range']

#: The checked quantities and their units.
QUANTITIES = {'q': 'rad', 'v': 'rad/s', 'a': 'rad/s^2'}


@dataclass(frozen=True)
class RangeViolation:
    """The first value found outside the range."""

    quantity: str
    joint: str
    value: float
    low: float
    high: float

    def describe(self) -> str:
        """One line naming joint, value, bounds and unit."""
        unit = QUANTITIES[self.quantity]
        return (
            f'{self.quantity} of {self.joint} = {self.value:.4g} {unit} is outside '
            f'[{self.low:.4g}, {self.high:.4g}] {unit}'
        )


@dataclass(frozen=True, eq=False)
class TrainingRange:
    """Per-joint bounds of q, v and a; a quantity without bounds is not checked.

    Attributes:
        joints: joint names, the column order of the bounds.
        bounds: quantity ('q', 'v', 'a') -> (low (n,), high (n,)) in SI units.
        source: where the bounds came from, for log messages.
    """

    joints: tuple[str, ...]
    bounds: Mapping[str, tuple[np.ndarray, np.ndarray]]
    source: str

    def widened(self, margin: float) -> TrainingRange:
        """The bounds widened by ``margin`` times half the range on each side."""
        out = {}
        for name, (low, high) in self.bounds.items():
            pad = margin * 0.5 * (high - low)
            out[name] = (low - pad, high + pad)
        return TrainingRange(self.joints, out, self.source)

    @cached_property
    def _stacked(self) -> tuple[tuple[str, ...], np.ndarray, np.ndarray]:
        names = tuple(name for name in QUANTITIES if name in self.bounds)
        low = np.concatenate([self.bounds[name][0] for name in names]) if names else np.empty(0)
        high = np.concatenate([self.bounds[name][1] for name in names]) if names else low
        return names, low, high

    def _outside(self, q: np.ndarray, v: np.ndarray, a: np.ndarray) -> np.ndarray | None:
        """The bounded values stacked, or None when all lie inside.

        One comparison of all of them: the common case (inside), per sample.
        """
        names, low, high = self._stacked
        given = {'q': q, 'v': v, 'a': a}
        values = np.concatenate([given[name] for name in names]) if names else low
        return values if ((values < low) | (values > high)).any() else None

    def excess(self, q: np.ndarray, v: np.ndarray, a: np.ndarray) -> float:
        """How far (n,) q, v, a reach beyond the bounds, in half ranges; 0 inside.

        The largest overshoot of any bounded value, each in units of its own half range.
        """
        values = self._outside(q, v, a)
        if values is None:
            return 0.0
        _, low, high = self._stacked
        half = np.maximum(0.5 * (high - low), 1e-12)
        return float(np.max(np.maximum(low - values, values - high) / half))

    def first_violation(
        self, q: np.ndarray, v: np.ndarray, a: np.ndarray
    ) -> RangeViolation | None:
        """The first value of (n,) q, v, a outside its bounds, or None."""
        if self._outside(q, v, a) is None:
            return None
        for name, values in (('q', q), ('v', v), ('a', a)):
            limits = self.bounds.get(name)
            if limits is None:
                continue
            low, high = limits
            outside = (values < low) | (values > high)
            if outside.any():
                j = int(np.argmax(outside))
                return RangeViolation(name, self.joints[j], float(values[j]), low[j], high[j])
        return None


def _scaler(data: Any) -> tuple[np.ndarray, np.ndarray] | None:
    if not isinstance(data, Mapping) or 'low' not in data or 'high' not in data:
        return None
    return np.asarray(data['low'], dtype=float), np.asarray(data['high'], dtype=float)


def training_range(fitted: Mapping[str, Any], robot: RobotConfig) -> TrainingRange:
    """The training range a model's fitted metadata records, else the robot's joint limits.

    Args:
        fitted: ``model.fitted_metadata()``.
        robot: the robot (joint names, and the limits used when the metadata has no ranges).
    """
    n = robot.n_joints
    bounds: dict[str, tuple[np.ndarray, np.ndarray]] = {}
    inputs = _scaler(fitted.get('input_scaler'))
    state = _scaler(fitted.get('state_scaler'))
    scaling = fitted.get('scaling')
    if inputs is not None and inputs[0].shape == (3 * n,):
        for k, name in enumerate(('q', 'v', 'a')):
            bounds[name] = (inputs[0][k * n : (k + 1) * n], inputs[1][k * n : (k + 1) * n])
        source = 'training range (input_scaler)'
    elif state is not None and state[0].shape == (2 * n,):
        bounds = {'q': (state[0][:n], state[1][:n]), 'v': (state[0][n:], state[1][n:])}
        source = 'training range (state_scaler)'
    elif isinstance(scaling, Mapping) and _scaler(scaling.get('position')) is not None:
        position = _scaler(scaling.get('position'))
        velocity = _scaler(scaling.get('velocity'))
        assert position is not None
        bounds['q'] = position
        if velocity is not None:
            bounds['v'] = velocity
        source = 'training range (scaling)'
    else:
        limits = robot.limits
        bounds = {
            'q': (limits.position_lower, limits.position_upper),
            'v': (-limits.velocity, limits.velocity),
            'a': (-limits.acceleration, limits.acceleration),
        }
        return TrainingRange(robot.joints, bounds, 'robot joint limits (no training range saved)')
    return TrainingRange(robot.joints, bounds, source)
