"""Settings of the feed-forward predictor's guards, validated on construction."""

from __future__ import annotations

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
        max_age_s: reject a sample whose stamp is older than this, compared with the caller's
            clock [s]; 0 turns the check off. Only meaningful when the stamps and the clock share
            a time base (PTP-synchronised controller, or use_sim_time with the replay's /clock).
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
    max_age_s: float = 0.0
    acceleration_cutoff_hz: float = 0.0
    torque_limit_scale: float = 1.0
    range_margin: float = 0.1
    out_of_range: OutOfRangeAction = 'auto'

    def __post_init__(self) -> None:
        """Check ranges, naming the key and the allowed values."""
        if not 1e-5 <= self.period_s <= 1.0:
            raise ConfigError(f'period_s must be in [1e-5, 1] s, got {self.period_s}')
        if not isinstance(self.stale_after_cycles, int) or self.stale_after_cycles < 1:
            raise ConfigError(
                f'stale_after_cycles must be an integer >= 1, got {self.stale_after_cycles!r}'
            )
        if self.max_age_s < 0:
            raise ConfigError(f'max_age_s must be >= 0 s (0 = off), got {self.max_age_s}')
        if self.acceleration_cutoff_hz < 0:
            raise ConfigError(
                f'acceleration_cutoff_hz must be >= 0 Hz (0 = off), got '
                f'{self.acceleration_cutoff_hz}'
            )
        if not 0.0 < self.torque_limit_scale <= 1.0:
            raise ConfigError(
                f'torque_limit_scale must be in (0, 1], got {self.torque_limit_scale}'
            )
        if self.range_margin < 0:
            raise ConfigError(f'range_margin must be >= 0, got {self.range_margin}')
        if self.out_of_range not in OUT_OF_RANGE_ACTIONS:
            raise ConfigError(
                f'out_of_range must be one of {OUT_OF_RANGE_ACTIONS}, got {self.out_of_range!r}'
            )

    @property
    def stale_after_ns(self) -> int:
        """The stale threshold [ns]."""
        return round(self.stale_after_cycles * self.period_s * 1e9)
