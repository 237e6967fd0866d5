"""Excitation trajectories as in the reference study: per-axis third-order Fourier series.

Each segment is, per axis i (Swevers et al.),

    q_i(t)   = q0_i + sum_l [ a_il / (w l) sin(w l t) - b_il / (w l) cos(w l t) ]
    qd_i(t)  = sum_l [ a_il cos(w l t) + b_il sin(w l t) ]
    qdd_i(t) = sum_l [ -a_il w l sin(w l t) + b_il w l cos(w l t) ]

with w = 2 pi f_base. Requiring sum_l a_il = 0 and sum_l l b_il = 0 puts every axis at rest
(qd = qdd = 0) at t = 0 and, by periodicity, at the end of each period; q0 is chosen so that every
segment starts and ends at the same home pose, so segments chain into one long recording with
short rests between them. Limits are enforced by scaling and then checked on a dense grid.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from id_learning.errors import ConfigError
from id_learning.robot.config import JointLimits

__all__ = [
    'ExcitationConfig',
    'ExcitationTrajectory',
    'FourierSegment',
    'check_bandwidth',
    'check_limits',
    'design_excitation',
    'home_pose',
    'random_segment',
]

CHECK_OVERSAMPLING = 8  # dense-grid points per IPO sample for the limit check
DESIGN_MARGIN = 1e-4  # relative margin kept from each limit when scaling a segment


@dataclass(frozen=True)
class ExcitationConfig:
    """Settings of a multi-segment Fourier excitation.

    Attributes:
        duration_s: total length [s]; whole segments (period + rest) are used.
        base_frequency_hz: fundamental f_base [Hz]; harmonics reach harmonics * f_base.
        harmonics: Fourier order per axis (3 in the study).
        position_fraction: share of the usable position range from home to the nearer limit.
        velocity_fraction: share of the velocity limit the excitation may reach.
        acceleration_fraction: share of the acceleration limit the excitation may reach.
        rest_s: time at rest at the home pose before each segment and at the end [s].
        home: home pose [rad], or None for the middle of the position limits.
        file: a designed excitation (``excitation.json`` of ``id-learning excitation``) played
            whole instead of drawing one; the settings above then do not apply.
    """

    duration_s: float = 600.0
    base_frequency_hz: float = 0.04
    harmonics: int = 3
    position_fraction: float = 0.85
    velocity_fraction: float = 0.8
    acceleration_fraction: float = 0.8
    rest_s: float = 0.5
    home: tuple[float, ...] | None = None
    file: str | None = None

    def __post_init__(self) -> None:
        """Check ranges, naming the key."""
        checks = {
            'duration_s': self.duration_s > 0,
            'base_frequency_hz': self.base_frequency_hz > 0,
            'harmonics': 1 <= self.harmonics <= 10,
            'position_fraction': 0 < self.position_fraction <= 1,
            'velocity_fraction': 0 < self.velocity_fraction <= 1,
            'acceleration_fraction': 0 < self.acceleration_fraction <= 1,
            'rest_s': self.rest_s >= 0,
        }
        for key, ok in checks.items():
            if not ok:
                raise ConfigError(
                    f'excitation.{key}: value {getattr(self, key)!r} is out of range'
                )

    @property
    def period_s(self) -> float:
        """Period of one Fourier segment [s]."""
        return 1.0 / self.base_frequency_hz

    @property
    def segment_count(self) -> int:
        """Whole segments (rest + period) that fit ``duration_s`` after the final rest; >= 1."""
        return max(1, int((self.duration_s - self.rest_s) // (self.period_s + self.rest_s)))

    @property
    def actual_duration_s(self) -> float:
        """The length the trajectory has [s]: ``duration_s`` rounded to whole segments."""
        return self.segment_count * (self.period_s + self.rest_s) + self.rest_s

    def duration_note(self, period_s: float) -> str | None:
        """A line saying that ``duration_s`` was rounded, or None when it is kept (to a sample).

        A segment must end at rest at the home pose, so it cannot be cut short: the length is a
        whole number of segments, which the user asking for 5 s should be told.
        """
        actual = self.actual_duration_s
        if abs(actual - self.duration_s) <= period_s:
            return None
        return (
            f'excitation.duration_s {self.duration_s:g} s became {actual:g} s: '
            f'{self.segment_count} whole segment(s) of {self.period_s:g} s '
            f'(1 / base_frequency_hz) with {self.rest_s:g} s rests'
        )


def check_bandwidth(base_frequency_hz: float, harmonics: int, period_s: float, where: str) -> None:
    """Refuse an excitation whose highest harmonic is at or above the recording's Nyquist.

    The motion is recorded at the IPO period: content at or above 1 / (2 period) aliases into
    lower frequencies, so the recorded q, v, a (and the accelerations differentiated from them)
    no longer describe the motion the torques answer. The limit check on the dense grid cannot
    see that. Harmonics above the labels' low-pass cut-off are not refused: through the filter
    the model's torque is filtered like the labels, so they cost information but mislead nothing.

    Raises:
        ConfigError: names the highest frequency, the Nyquist frequency and the largest
            base_frequency_hz allowed.
    """
    nyquist = 0.5 / period_s
    top = base_frequency_hz * harmonics
    if not top < nyquist:
        raise ConfigError(
            f'{where}: base_frequency_hz {base_frequency_hz:g} Hz x {harmonics} harmonic(s) = '
            f'{top:g} Hz is at or above the Nyquist frequency {nyquist:g} Hz of the '
            f'{period_s * 1e3:g} ms IPO period (the recording would alias it); use '
            f'base_frequency_hz < {nyquist / harmonics:g} Hz'
        )


@dataclass(frozen=True, eq=False)
class FourierSegment:
    """One Fourier segment: coefficients a, b of shape (n, harmonics), offset q0 (n,)."""

    a: np.ndarray
    b: np.ndarray
    q0: np.ndarray
    omega: float

    def evaluate(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Return q, qd, qdd of shape (len(t), n) at segment-local times t [s]."""
        orders = np.arange(1, self.a.shape[1] + 1)
        phase = np.multiply.outer(np.asarray(t, dtype=float), self.omega * orders)  # (T, L)
        sin, cos = np.sin(phase), np.cos(phase)
        wl = self.omega * orders
        q = self.q0 + sin @ (self.a / wl).T - cos @ (self.b / wl).T
        qd = cos @ self.a.T + sin @ self.b.T
        qdd = -sin @ (self.a * wl).T + cos @ (self.b * wl).T
        return q, qd, qdd


@dataclass(frozen=True, eq=False)
class ExcitationTrajectory:
    """Segments chained with rests at the home pose; evaluable at any time in [0, duration]."""

    segments: tuple[FourierSegment, ...]
    home: np.ndarray
    period_s: float
    rest_s: float

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready coefficients, enough to re-evaluate the exact motion."""
        return {
            'home': self.home.tolist(),
            'period_s': self.period_s,
            'rest_s': self.rest_s,
            'omega_rad_s': self.segments[0].omega if self.segments else 0.0,
            'segments': [
                {'a': s.a.tolist(), 'b': s.b.tolist(), 'q0': s.q0.tolist()} for s in self.segments
            ],
        }

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> ExcitationTrajectory:
        """Rebuild a trajectory written by ``to_dict``."""
        omega = float(data['omega_rad_s'])
        segments = tuple(
            FourierSegment(np.array(s['a']), np.array(s['b']), np.array(s['q0']), omega)
            for s in data['segments']
        )
        return cls(
            segments, np.array(data['home']), float(data['period_s']), float(data['rest_s'])
        )

    @property
    def duration_s(self) -> float:
        """Total duration including the final rest [s]."""
        return len(self.segments) * (self.period_s + self.rest_s) + self.rest_s

    def evaluate(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Return q [rad], qd [rad/s], qdd [rad/s^2], each (len(t), n), at times t [s]."""
        t = np.asarray(t, dtype=float)
        n = len(self.home)
        q = np.tile(self.home, (len(t), 1))
        qd = np.zeros((len(t), n))
        qdd = np.zeros((len(t), n))
        slot = self.period_s + self.rest_s
        index = np.floor(t / slot).astype(int)
        local = t - index * slot - self.rest_s
        moving = (
            (local >= 0) & (local <= self.period_s) & (index >= 0) & (index < len(self.segments))
        )
        for k, segment in enumerate(self.segments):
            rows = moving & (index == k)
            if rows.any():
                q[rows], qd[rows], qdd[rows] = segment.evaluate(local[rows])
        return q, qd, qdd


def random_segment(
    rng: np.random.Generator,
    n: int,
    harmonics: int,
    omega: float,
    home: np.ndarray,
    *,
    reach_low: np.ndarray,
    reach_high: np.ndarray,
    vel_max: np.ndarray,
    acc_max: np.ndarray,
    grid: np.ndarray,
) -> FourierSegment:
    """One segment of random coefficients, at rest at ``home`` at both ends, scaled into reach.

    ``reach_low``/``reach_high``: how far below and above ``home`` it may go [rad];
    ``vel_max``, ``acc_max``: its limits; ``grid``: the segment-local times they are met on.
    """
    orders = np.arange(1, harmonics + 1)
    a = rng.standard_normal((n, harmonics))
    b = rng.standard_normal((n, harmonics))
    a -= a.mean(axis=1, keepdims=True)  # sum_l a_il = 0: zero velocity at t = 0
    b -= np.outer(b @ orders, orders) / (orders @ orders)  # sum_l l b_il = 0: zero acceleration
    # Offset so that q(0) = home: q(0) = q0 - sum_l b_il / (w l).
    unit = FourierSegment(a, b, home + (b / (omega * orders)).sum(axis=1), omega)
    q, qd, qdd = unit.evaluate(grid)
    deviation = q - home
    with np.errstate(divide='ignore'):
        scale_pos = np.minimum(
            reach_high / deviation.max(axis=0).clip(1e-12),
            reach_low / (-deviation.min(axis=0)).clip(1e-12),
        )
    scale = np.minimum.reduce(
        [
            scale_pos,
            vel_max / np.abs(qd).max(axis=0),
            acc_max / np.abs(qdd).max(axis=0),
        ]
    )
    # The design grid can miss the continuous extremum between its points (by ~1e-7 relative):
    # keep a small margin so the dense check never finds an overshoot.
    scale *= 1.0 - DESIGN_MARGIN
    a, b = a * scale[:, None], b * scale[:, None]
    return FourierSegment(a, b, home + (b / (omega * orders)).sum(axis=1), omega)


def home_pose(
    config: ExcitationConfig,
    limits: JointLimits,
    joints: Sequence[str] | None = None,
    where: str = 'excitation',
) -> np.ndarray:
    """The pose every segment starts and ends at: ``config.home``, or mid-range.

    ``joints`` name the limits' joints and ``where`` the config in messages.

    Raises:
        ConfigError: it is not strictly inside the position limits (names each joint outside,
            its value and its limits).
    """
    lower, upper = limits.position_lower, limits.position_upper
    home = 0.5 * (lower + upper) if config.home is None else np.asarray(config.home, dtype=float)
    if home.shape != lower.shape:
        raise ConfigError(f'{where}.home: {home.size} value(s) for {len(lower)} joints')
    outside = np.flatnonzero((home <= lower) | (home >= upper))
    if outside.size:
        names = (
            list(joints) if joints is not None else [f'joint #{j + 1}' for j in range(len(home))]
        )
        said = '; '.join(
            f'{names[j]} {home[j]:g} rad, its limits [{lower[j]:g}, {upper[j]:g}] rad'
            for j in outside
        )
        raise ConfigError(
            f'{where}.home must lie strictly inside the position limits of the robot config: '
            f'{said}'
        )
    return home


def design_excitation(
    config: ExcitationConfig,
    limits: JointLimits,
    period_s: float,
    rng: np.random.Generator,
) -> ExcitationTrajectory:
    """Draw random Fourier segments that fill the allowed range, and check them against limits.

    Args:
        config: excitation settings.
        limits: joint limits; the excitation stays inside position, velocity and acceleration.
        period_s: sample period of the recording (IPO cycle) [s].
        rng: random generator (seeded by the caller).

    Raises:
        ConfigError: the home pose is outside the limits, a harmonic at or above the Nyquist
            frequency of ``period_s`` (``check_bandwidth``), or a limit is violated on the
            check grid.
    """
    lower, upper = limits.position_lower, limits.position_upper
    n = len(lower)
    home = home_pose(config, limits)
    check_bandwidth(config.base_frequency_hz, config.harmonics, period_s, 'excitation')
    omega = 2.0 * math.pi * config.base_frequency_hz
    grid = np.linspace(
        0.0, config.period_s, int(config.period_s / period_s * CHECK_OVERSAMPLING) + 1
    )
    segments = tuple(
        random_segment(
            rng,
            n,
            config.harmonics,
            omega,
            home,
            reach_low=config.position_fraction * (home - lower),
            reach_high=config.position_fraction * (upper - home),
            vel_max=config.velocity_fraction * limits.velocity,
            acc_max=config.acceleration_fraction * limits.acceleration,
            grid=grid,
        )
        for _ in range(config.segment_count)
    )
    trajectory = ExcitationTrajectory(segments, home, config.period_s, config.rest_s)
    check_limits(trajectory, limits, period_s / CHECK_OVERSAMPLING)
    return trajectory


#: How far beyond its limit's step (rate x grid step) a value may move between grid points:
#: a smooth trajectory moves less than the limit allows, a jump by far more.
_STEP_MARGIN = 1.5


def check_limits(
    trajectory: ExcitationTrajectory,
    limits: JointLimits,
    step_s: float,
    joints: tuple[str, ...] | None = None,
) -> None:
    """Evaluate the trajectory on a dense grid and raise if any limit is exceeded.

    ``joints``: their names, for the message (else ``joint_<k>`` counted from 1).

    Raises:
        ConfigError: names the quantity, the joint, the time, the value and by how much.
    """
    t = np.arange(0.0, trajectory.duration_s + step_s, step_s)
    q, qd, qdd = trajectory.evaluate(t)
    tolerance = 1e-9
    for name, values, low, high in (
        ('position', q, limits.position_lower, limits.position_upper),
        ('velocity', qd, -limits.velocity, limits.velocity),
        ('acceleration', qdd, -limits.acceleration, limits.acceleration),
    ):
        bad = ~((values >= low - tolerance) & (values <= high + tolerance))  # NaN is bad too
        if bad.any():
            k, j = (int(x) for x in np.argwhere(bad)[0])
            joint = joints[j] if joints is not None else f'joint_{j + 1}'
            value = float(values[k, j])
            excess = max(low[j] - value, value - high[j])
            beyond = '' if not np.isfinite(value) else f' (by {excess:.3g})'
            raise ConfigError(
                f'excitation exceeds the {name} limit of {joint} at t = {t[k]:.3f} s: '
                f'{value:.6g} outside [{low[j]:.6g}, {high[j]:.6g}]{beyond}'
            )
    _check_continuous(t, q, qd, limits, joints)


def _check_continuous(
    t: np.ndarray,
    q: np.ndarray,
    qd: np.ndarray,
    limits: JointLimits,
    joints: tuple[str, ...] | None,
) -> None:
    """Refuse positions (velocities) that step further than their rate limit allows.

    Between grid points a smooth trajectory moves less than its velocity (acceleration) limit
    allows; a jump is a segment that does not start where the one before ended.

    Raises:
        ConfigError: names the quantity, the joint, the time and the step.
    """
    step = np.diff(t)[:, None]
    for name, unit, values, rate in (
        ('position', 'rad', q, limits.velocity),
        ('velocity', 'rad/s', qd, limits.acceleration),
    ):
        jumps = np.abs(np.diff(values, axis=0)) > _STEP_MARGIN * rate * step + 1e-9
        if jumps.any():
            k, j = (int(x) for x in np.argwhere(jumps)[0])
            joint = joints[j] if joints is not None else f'joint_{j + 1}'
            jump = float(values[k + 1, j] - values[k, j])
            raise ConfigError(
                f'excitation {name} of {joint} jumps by {jump:.6g} {unit} at t = '
                f'{t[k + 1]:.3f} s, more than its limits allow in {float(step[k, 0]):.3g} s: a '
                'segment that does not start where the one before ended (an edited design?)'
            )
