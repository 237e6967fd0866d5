"""Bounded timing statistics (latency, jitter) for nodes and benchmarks."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ['RollingStats', 'StatsSummary']


@dataclass(frozen=True)
class StatsSummary:
    """Summary of the values in a window; all zeros when there are none.

    Attributes:
        count: values in the window.
        median, p99, max, mean: of those values (their unit).
    """

    count: int
    median: float
    p99: float
    max: float
    mean: float


class RollingStats:
    """The last ``capacity`` values of a quantity, and how many were added in all."""

    def __init__(self, capacity: int = 4096) -> None:
        """Allocate the window; capacity must be >= 1."""
        if capacity < 1:
            raise ValueError(f'capacity must be >= 1, got {capacity}')
        self._values = np.zeros(capacity)
        self._next = 0
        self.total = 0

    def add(self, value: float) -> None:
        """Append one value, dropping the oldest once the window is full."""
        self._values[self._next] = value
        self._next = (self._next + 1) % len(self._values)
        self.total += 1

    def values(self) -> np.ndarray:
        """The values in the window, oldest first."""
        if self.total < len(self._values):
            return self._values[: self.total].copy()
        return np.roll(self._values, -self._next)

    def summary(self) -> StatsSummary:
        """Median, 99th percentile, maximum and mean of the window."""
        values = self.values()
        if not len(values):
            return StatsSummary(0, 0.0, 0.0, 0.0, 0.0)
        median, p99 = np.percentile(values, [50, 99])
        return StatsSummary(
            len(values), float(median), float(p99), float(values.max()), float(values.mean())
        )
