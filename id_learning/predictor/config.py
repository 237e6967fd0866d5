"""Settings of the feed-forward predictor's guards, validated on construction."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

from id_learning.errors import ConfigError

__all__ = ['OUT_OF_RANGE_ACTIONS', 'GuardConfig']

OUT_OF_RANGE_ACTIONS = ('auto', 'fallback', 'warn', 'reject')
OutOfRangeAction = Literal['auto', 'fallback', 'warn', 'reject']


@dataclass(frozen=True)
class GuardConfig:
    """What the predictor accepts, how it estimates accelerations and how it limits its output.

    Attributes:
        period_s: nominal reference period [s] (the IPO cycle); stale thresholds count in it.
        stale_after_cycles: the reference is stale when no valid sample has arrived for more than
            this many periods (receive time), or when consecutive stamps are further apart. A
            stale reference ends the feed-forward (nothing is published); a jump in the stamps
            resets the history (acceleration estimate, LSTM window) for when it resumes.
        max_age_s: reject a sample that arrives later than this against the stream's time base
            [s], and one whose stamp leads it by more than one IPO period (or this, where
            shorter) (``predictor.stamps``: no shared clock needed); 0 turns both checks off
            (the stamps' order is still checked).
        resync_after: rejections for time in a row (order, age, future) after which the next
            sample starts a new time base, with one warning: a sender's clock step never locks
            the stream out.
        rearm_samples: after a sample that fails the kinematic consistency gate
            (``dataset.consistency``), this many consistent samples
            pass before the model's torque is served again (the hold output meanwhile).
        consistency_scale: a multiple of the consistency gate's tolerances (1: as derived).
        torque_rise_s: the published torque changes by at most the torque limit per this time
            [s] (``predictor.output``).
        acceleration_cutoff_hz: first-order low-pass of the causal acceleration estimate [Hz];
            0 for the raw backward difference. Used only when the reference carries no
            accelerations.
        torque_limit_scale: the output is clamped to this share of the robot's torque limits.
        range_margin: a value counts as outside the training range once it leaves
            [low - m * half, high + m * half], m = range_margin, half = half of the range.
        out_of_range: what a sample outside the training range gets: 'fallback' (the physics
            prior's torque, blended in across the margin: ``predictor.fallback``), 'warn' (count,
            log, still predict), 'reject' (publish nothing), or 'auto' (fallback for a model
            with a network, warn for a physics model, whose range is the joint limits).
    """

    period_s: float = 0.008
    stale_after_cycles: int = 5
    max_age_s: float = 0.1
    resync_after: int = 5
    rearm_samples: int = 2
    consistency_scale: float = 1.0
    torque_rise_s: float = 0.05
    acceleration_cutoff_hz: float = 0.0
    torque_limit_scale: float = 1.0
    range_margin: float = 0.1
    out_of_range: OutOfRangeAction = 'auto'

    def __post_init__(self) -> None:
        """Check ranges, naming the key, the value and the allowed values."""
        period = self.period_s
        nyquist = 0.5 / period if _finite(period) and period > 0 else math.inf
        bounds: tuple[tuple[str, float, float, float], ...] = (
            ('period_s', period, 1e-5, 1.0),
            ('max_age_s', self.max_age_s, 0.0, 3600.0),
            ('consistency_scale', self.consistency_scale, 1e-3, 1e3),
            ('torque_rise_s', self.torque_rise_s, 1e-4, 60.0),
            ('torque_limit_scale', self.torque_limit_scale, 1e-6, 1.0),
            ('range_margin', self.range_margin, 0.0, 1e3),
            ('acceleration_cutoff_hz', self.acceleration_cutoff_hz, 0.0, nyquist),
        )
        for name, value, low, high in bounds:
            if not (_finite(value) and low <= value <= high):
                raise ConfigError(
                    f'{name} must be a finite value in [{low:g}, {high:g}], got {value!r}'
                )
        if self.acceleration_cutoff_hz >= nyquist:
            raise ConfigError(
                f'acceleration_cutoff_hz {self.acceleration_cutoff_hz:g} Hz must be below the '
                f'Nyquist frequency {nyquist:g} Hz of period_s {period:g} s (0 = off)'
            )
        counts = (
            ('stale_after_cycles', self.stale_after_cycles, 1),
            ('resync_after', self.resync_after, 1),
            ('rearm_samples', self.rearm_samples, 0),
        )
        for name, count, low in counts:
            if isinstance(count, bool) or not isinstance(count, int) or not low <= count <= 10**6:
                raise ConfigError(f'{name} must be an integer in [{low}, 1000000], got {count!r}')
        if self.out_of_range not in OUT_OF_RANGE_ACTIONS:
            raise ConfigError(
                f'out_of_range must be one of {OUT_OF_RANGE_ACTIONS}, got {self.out_of_range!r}'
            )

    @property
    def stale_after_ns(self) -> int:
        """The stale threshold [ns]."""
        return round(self.stale_after_cycles * self.period_s * 1e9)


def _finite(value: object) -> bool:
    """A real number (not a bool) that is finite."""
    return isinstance(value, int | float) and not isinstance(value, bool) and math.isfinite(value)
