"""Kinematic consistency: consecutive samples whose positions, velocities and accelerations agree.

The plausibility gate (``plausibility``) judges each sample alone; this gate judges each sample
against the ones before it, so a stream whose every sample is possible but whose succession is
not (a 1 rad jump in one cycle, two poses alternating, a still position with a velocity,
velocities flipping sign every cycle) is refused too. One rule for every door: the predictor
(``ConsistencyStream``, sample by sample), the replay, ``inspect`` and the dataset loader (whole
recordings, ``KinematicConsistency``).

Sample k is compared with sample k - w for w = 1 (the pair) and for the longest window of at most
``WINDOW_S`` (W samples), D = t_k - t_(k-w), h = D / w, I the trapezoid integral of the
velocities over the window; per joint:

    |q_k - q_(k-w) - I|  <=  A D (h / 2 + L)  +  r |I|  +  S max(|v_k|, |v_(k-w)|)  +  f V T
    |v_k - v_(k-1) - (a_k + a_(k-1)) dt / 2|  <=  A (dt + S)  +  r |a_k + a_(k-1)| dt / 2  +  f V

The accelerations are the samples' own or, when they carry none, zero: the second line then
bounds the acceleration the velocities imply. V is the joint's velocity limit, A
``ACCELERATION_FACTOR`` times its acceleration limit, T the IPO period. Why each term:

- ``A D h / 2``: the trapezoid rule's largest error for a velocity whose rate stays within A;
- ``A D L``: a velocity signal may lag its position by L = ``LAG_PERIODS`` periods (a filter);
- ``r |I|``: a scale error of r = ``RELATIVE`` between the signals (a rounded gear ratio);
- ``S |v|``, ``A S``: a signal may hold its value for up to S = ``STALE_S`` and then catch up (a
  bus's or a log's hiccup: a real Panda log holds positions for 5 ms);
- ``f V T``, ``f V``: noise and quantisation, f = ``FLOOR_SHARE`` of the velocity limit.

The pair catches jumps and alternations at once; the window catches what grows slowly, such as a
still position with a velocity (on the MABI's first joint refused from about 0.3 rad/s). Measured:
the twins' recordings (MABI, UR5, Panda) use at most 8 % of a tolerance, the real Panda log
(../shared/data/panda_gaz2019, imported at 1 kHz) 44 %. Nothing is compared across the starts
of segments the caller names (``starts``: seams, gaps).
"""

from __future__ import annotations

import itertools
import math
from collections import deque
from dataclasses import dataclass
from typing import Any

import numpy as np

from id_learning.dataset.plausibility import ACCELERATION_FACTOR
from id_learning.errors import DatasetError
from id_learning.robot.config import JointLimits, RobotConfig

__all__ = [
    'FLOOR_SHARE',
    'LAG_PERIODS',
    'RELATIVE',
    'SCALE_LIMIT',
    'SCALE_MIN_TRAVEL',
    'SCALE_WINDOW_S',
    'STALE_S',
    'WINDOW_S',
    'ConsistencyStream',
    'Inconsistency',
    'KinematicConsistency',
    'gap_starts',
]

#: Lag allowed between a velocity signal and its position [IPO periods].
LAG_PERIODS = 2.0
#: Scale error allowed between two signals (share of the change).
RELATIVE = 0.25
#: How long a signal may hold its value before it catches up [s].
STALE_S = 0.01
#: The longest window a sample is compared over [s].
WINDOW_S = 0.05
#: Noise and quantisation allowed (share of the velocity limit; per period for positions).
FLOOR_SHARE = 0.05
#: The windows the whole-recording scale check compares over [s].
SCALE_WINDOW_S = 0.2
#: The largest factor allowed between the integrated velocities and the position change of a
#: whole recording (at consistency_scale 1; a rounded gear ratio is a few per cent).
SCALE_LIMIT = 1.5
#: Travel a joint must make (sum of |position change| over the windows) before its scale is
#: judged [rad or m]: below it noise and quantisation could dominate.
SCALE_MIN_TRAVEL = 0.05
#: How far back the stream's scale check looks (``ConsistencyStream``) [s]: a scaled stream
#: fails once its joints travel ``SCALE_MIN_TRAVEL`` within it, a valid one is served again at
#: the latest once the scaled windows have left it.
SCALE_HORIZON_S = 2.0
#: The stream judges a joint's scale once it travels this many times the integral a velocity
#: bias at the local floor (``FLOOR_SHARE`` of the velocity limit) makes over the horizon.
BIAS_MARGIN = 4.0


def gap_starts(stamps_ns: np.ndarray, period_s: float, gap_periods: float) -> tuple[int, ...]:
    """0 and every sample after a silence longer than ``gap_periods`` periods.

    The segment starts the gate compares nothing across (``starts`` of its methods).
    """
    after = np.flatnonzero(np.diff(stamps_ns) > gap_periods * period_s * 1e9) + 1
    return (0, *(int(k) for k in after))


@dataclass(frozen=True)
class Inconsistency:
    """The worst joint of a sample that fails the gate.

    Attributes:
        joint: the joint's name.
        quantity: 'position' (against the velocities), 'velocity' (against the accelerations),
            or 'scale' (the velocities' integral a multiple of the position change over the
            stream's last ``SCALE_HORIZON_S``: ``change`` is the factor, ``tolerance`` the
            largest allowed either way, ``expected`` 1).
        change: how far the quantity moved over the window [rad or rad/s].
        expected: how far the other signal says it moved [rad or rad/s].
        tolerance: the allowed mismatch [rad or rad/s].
        window_s: the time compared over [s].
    """

    joint: str
    quantity: str
    change: float
    expected: float
    tolerance: float
    window_s: float
    recorded: bool = True

    def describe(self) -> str:
        """One line: what moved, what the other signal says, and the tolerance."""
        if self.quantity == 'scale':
            return (
                f'the velocities of {self.joint} integrate to {self.change:.3g} x its position '
                f'change over the last {self.window_s:.3g} s (at most {self.tolerance:.3g} x '
                'either way: a unit, a gear ratio or a sign between the two signals)'
            )
        unit = 'rad' if self.quantity == 'position' else 'rad/s'
        other = 'velocities' if self.quantity == 'position' else 'accelerations'
        if not self.recorded:
            return (
                f'{self.quantity} of {self.joint} changed by {self.change:.6g} {unit} in '
                f'{self.window_s * 1e3:.3g} ms, more than the acceleration limits allow (the '
                f'samples carry no {other}; tolerance {self.tolerance:.3g} {unit})'
            )
        return (
            f'{self.quantity} of {self.joint} changed by {self.change:.6g} {unit} in '
            f'{self.window_s * 1e3:.3g} ms where its {other} say {self.expected:.6g} {unit} '
            f'(tolerance {self.tolerance:.3g} {unit})'
        )


class KinematicConsistency:
    """The gate of the module docstring for one robot's joints, on whole recordings.

    Args:
        joints: the joint names, in the order of ``limits`` and of the samples.
        limits: the robot's joint limits.
        period_s: the IPO period [s].
        scale: a multiple of every tolerance (> 0; 1 as derived above), for a sender whose
            signals are known to be rougher.
    """

    def __init__(
        self, joints: tuple[str, ...], limits: JointLimits, period_s: float, scale: float = 1.0
    ) -> None:
        if not (math.isfinite(scale) and scale > 0):
            raise ValueError(f'scale must be a finite value > 0, got {scale}')
        self.joints = joints
        self.limits = limits
        self.scale = scale
        self.period_s = period_s
        #: The long window [samples].
        self.window = max(2, math.ceil(WINDOW_S / period_s - 1e-9))
        self.accel = scale * ACCELERATION_FACTOR * np.asarray(limits.acceleration, float)
        velocity = np.asarray(limits.velocity, float)
        self.lag_s = LAG_PERIODS * period_s
        self.relative = scale * RELATIVE
        self.stale_s = scale * STALE_S
        self.floor_q = scale * FLOOR_SHARE * velocity * period_s
        self.floor_v = scale * FLOOR_SHARE * velocity

    @classmethod
    def for_robot(
        cls, robot: RobotConfig, joints: tuple[str, ...] | None = None
    ) -> KinematicConsistency:
        """The gate of a robot (its ``consistency_scale``), for ``joints`` in any order."""
        names = robot.joints if joints is None else joints
        limits = robot.limits.take([robot.joints.index(name) for name in names])
        return cls(tuple(names), limits, robot.ipo_period_s, robot.consistency_scale)

    def position_terms(
        self, span_s: Any, steps: Any, dq: np.ndarray, integral: np.ndarray, v_ends: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """(mismatch, tolerance) of positions over windows of ``steps`` pairs lasting span_s.

        ``v_ends`` is the larger |v| at either end of each window.
        """
        tolerance = (
            self.accel * span_s * (0.5 * span_s / steps + self.lag_s)
            + self.relative * np.abs(integral)
            + self.stale_s * v_ends
            + self.floor_q
        )
        return np.abs(dq - integral), tolerance

    def velocity_terms(
        self, dt_s: Any, dv: np.ndarray, half_a: np.ndarray | float
    ) -> tuple[np.ndarray, np.ndarray]:
        """(mismatch, tolerance) of consecutive velocities; half_a = (a0 + a1) dt / 2 or 0."""
        tolerance = (
            self.accel * (dt_s + self.stale_s) + self.relative * np.abs(half_a) + self.floor_v
        )
        return np.abs(dv - half_a), tolerance

    def ratios(
        self, stamps_ns: np.ndarray, q: np.ndarray, v: np.ndarray, a: np.ndarray | None = None
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Mismatch over tolerance per sample and joint, (N, n) each: pair, window, velocity.

        Sample 0 has no predecessor (ratio 0); the window of the first samples is shorter.
        """
        t = (np.asarray(stamps_ns, dtype=np.int64) - int(stamps_ns[0])) * 1e-9
        dt = np.diff(t)[:, None]
        steps = 0.5 * (v[1:] + v[:-1]) * dt
        integral = np.concatenate([np.zeros((1, q.shape[1])), np.cumsum(steps, axis=0)])
        out = []
        for w in (1, self.window):
            ratio = np.zeros_like(q, dtype=float)
            first = np.arange(1, min(w, len(t)))  # the first samples: windows from sample 0
            if len(first):
                span = (t[first] - t[0])[:, None]
                ends = np.maximum(np.abs(v[first]), np.abs(v[0]))
                mismatch, tolerance = self.position_terms(
                    span, first[:, None], q[first] - q[0], integral[first], ends
                )
                ratio[first] = mismatch / tolerance
            if len(t) > w:
                span = (t[w:] - t[:-w])[:, None]
                dq, di = q[w:] - q[:-w], integral[w:] - integral[:-w]
                ends = np.maximum(np.abs(v[w:]), np.abs(v[:-w]))
                mismatch, tolerance = self.position_terms(span, w, dq, di, ends)
                ratio[w:] = mismatch / tolerance
            out.append(ratio)
        half_a = 0.0 if a is None else 0.5 * (a[1:] + a[:-1]) * dt
        mismatch, tolerance = self.velocity_terms(dt, v[1:] - v[:-1], half_a)
        out.append(np.concatenate([np.zeros((1, q.shape[1])), mismatch / tolerance]))
        return out[0], out[1], out[2]

    def scale_errors(
        self,
        stamps_ns: np.ndarray,
        q: np.ndarray,
        v: np.ndarray,
        *,
        starts: tuple[int, ...] = (0,),
    ) -> list[tuple[str, float, float]]:
        """(joint, factor, travel) of each joint whose velocities are a multiple of its rate.

        A scale error (deg/s for rad/s, a factor 2, a reversed sign) stays inside the local
        tolerances while the motion is slow, so it is judged over the whole recording: in
        windows of ``SCALE_WINDOW_S`` within each segment, the velocity integral I against the
        position change dq, factor = sum(I dq) / sum(dq^2) (a least-squares slope; 1 when they
        agree). A joint is judged once it travels ``SCALE_MIN_TRAVEL``; it fails outside
        [1 / limit, limit], limit = max(``SCALE_LIMIT``, 1 + 2 relative).
        """
        t = (np.asarray(stamps_ns, dtype=np.int64) - int(stamps_ns[0])) * 1e-9
        bounds = [*sorted(set(starts) | {0}), len(t)]
        dqs, integrals = [], []
        for begin, end in itertools.pairwise(bounds):
            if end - begin < 2:
                continue
            ts, qs, vs = t[begin:end], q[begin:end], v[begin:end]
            steps = 0.5 * (vs[1:] + vs[:-1]) * np.diff(ts)[:, None]
            cum = np.concatenate([np.zeros((1, q.shape[1])), np.cumsum(steps, axis=0)])
            stride = max(1, round(SCALE_WINDOW_S / self.period_s))
            marks = np.arange(0, end - begin, stride)
            if marks[-1] != end - begin - 1:
                marks = np.append(marks, end - begin - 1)
            dqs.append(np.diff(qs[marks], axis=0))
            integrals.append(np.diff(cum[marks], axis=0))
        if not dqs:
            return []
        return self.judge_scale(np.concatenate(dqs), np.concatenate(integrals))

    @property
    def scale_limit(self) -> float:
        """The largest factor allowed either way between velocity integral and position change."""
        return max(SCALE_LIMIT, 1.0 + 2.0 * self.relative)

    def judge_scale(
        self, dq: np.ndarray, integral: np.ndarray, min_travel: np.ndarray | float = 0.0
    ) -> list[tuple[str, float, float]]:
        """``scale_errors`` of windows' position changes and velocity integrals (W, n).

        ``min_travel``: per joint, the travel below which it is not judged (besides
        ``SCALE_MIN_TRAVEL``).
        """
        travel = np.abs(dq).sum(axis=0)
        needed = np.maximum(SCALE_MIN_TRAVEL, np.broadcast_to(min_travel, travel.shape))
        limit = self.scale_limit
        out = []
        for j, name in enumerate(self.joints):
            if not travel[j] >= needed[j]:
                continue
            factor = float(np.dot(integral[:, j], dq[:, j]) / np.dot(dq[:, j], dq[:, j]))
            if not (1.0 / limit <= factor <= limit):
                out.append((name, factor, float(travel[j])))
        return out

    def describe_scale(self, errors: list[tuple[str, float, float]]) -> str:
        """One phrase naming each joint whose velocities are a multiple of its positions' rate."""
        parts = [
            f'{name}: its velocities integrate to {factor:.3g} x its position change '
            f'(over {travel:.3g} rad of travel)'
            for name, factor, travel in errors
        ]
        return '; '.join(parts)

    def failing(
        self,
        stamps_ns: np.ndarray,
        q: np.ndarray,
        v: np.ndarray,
        a: np.ndarray | None = None,
        *,
        starts: tuple[int, ...] = (0,),
    ) -> np.ndarray:
        """(N,) True where a sample disagrees with those before it in its segment.

        Args:
            starts: first sample of each segment (a seam or a gap): nothing is compared across.
        """
        failing = np.zeros(len(stamps_ns), dtype=bool)
        bounds = [*sorted(set(starts) | {0}), len(stamps_ns)]
        for begin, end in itertools.pairwise(bounds):
            if end - begin < 2:
                continue
            part = slice(begin, end)
            ratios = self.ratios(stamps_ns[part], q[part], v[part], None if a is None else a[part])
            failing[part] = np.logical_or.reduce([(r > 1.0).any(axis=1) for r in ratios])
        return failing

    def explain(
        self, k: int, stamps_ns: np.ndarray, q: np.ndarray, v: np.ndarray, a: np.ndarray | None
    ) -> Inconsistency:
        """The worst joint and check of sample k (k >= 1) against the samples before it."""
        begin = max(0, k - self.window)
        part = slice(begin, k + 1)
        pair, window, velocity = (r[-1] for r in self.ratios(
            stamps_ns[part], q[part], v[part], None if a is None else a[part]))  # fmt: skip
        kind = int(np.argmax([pair.max(), window.max(), velocity.max()]))
        j = int(np.argmax((pair, window, velocity)[kind]))
        k0 = k - 1 if kind != 1 else begin
        span = (int(stamps_ns[k]) - int(stamps_ns[k0])) * 1e-9
        if kind == 2:
            dv = float(v[k, j] - v[k0, j])
            expected = 0.0 if a is None else 0.5 * float(a[k, j] + a[k0, j]) * span
            _, tolerance = self.velocity_terms(span, np.full(len(self.joints), dv), expected)
            return Inconsistency(
                self.joints[j], 'velocity', dv, expected, float(tolerance[j]), span, a is not None
            )
        t = (np.asarray(stamps_ns[k0 : k + 1], dtype=np.int64) - int(stamps_ns[k0])) * 1e-9
        expected = float(np.sum(0.5 * (v[k0 + 1 : k + 1, j] + v[k0:k, j]) * np.diff(t)))
        dq = float(q[k, j] - q[k0, j])
        ends = np.maximum(np.abs(v[k]), np.abs(v[k0]))
        _, tolerance = self.position_terms(
            span, k - k0, q[k] - q[k0], np.full(len(q[k]), expected), ends
        )
        return Inconsistency(self.joints[j], 'position', dq, expected, float(tolerance[j]), span)

    def first_failure(
        self,
        stamps_ns: np.ndarray,
        q: np.ndarray,
        v: np.ndarray,
        a: np.ndarray | None = None,
        *,
        starts: tuple[int, ...] = (0,),
    ) -> tuple[int, int, Inconsistency] | None:
        """(first failing sample, failing samples in all, its worst joint), or None."""
        failing = self.failing(stamps_ns, q, v, a, starts=starts)
        if not failing.any():
            return None
        k = int(np.argmax(failing))
        return k, int(failing.sum()), self.explain(k, stamps_ns, q, v, a)

    def check(
        self,
        stamps_ns: np.ndarray,
        q: np.ndarray,
        v: np.ndarray,
        a: np.ndarray | None = None,
        *,
        where: str,
        starts: tuple[int, ...] = (0,),
    ) -> None:
        """Refuse a recording or reference with a sample that fails the gate.

        Raises:
            DatasetError: names the sample, its stamp, the joint, both signals' changes, the
                tolerance and how many samples fail in all.
        """
        found = self.first_failure(stamps_ns, q, v, a, starts=starts)
        if found is None:
            scale = self.scale_errors(stamps_ns, q, v, starts=starts)
            if scale:
                raise DatasetError(
                    f'{where}: the velocities contradict the positions over the whole '
                    f'recording by a factor: {self.describe_scale(scale)}; the limit is '
                    f'{self.scale_limit:.3g} x either way. A '
                    'velocity in another unit (deg/s for rad/s), of the motor rather than the '
                    'joint side, or of a wrongly scaled column does not describe the motion '
                    'the positions record'
                )
            return
        sample, count, worst = found
        if self.scale < 1.0:
            derived = KinematicConsistency(self.joints, self.limits, self.period_s)
            if derived.first_failure(stamps_ns, q, v, a, starts=starts) is None:
                raise DatasetError(
                    f"{where}: the robot config's consistency_scale {self.scale:g} makes every "
                    f'tolerance of the kinematic consistency check {1 / self.scale:.4g} x '
                    'tighter than derived from the limits and the IPO period, and only so do '
                    f'{count} sample(s) fail (the first: sample {sample}, {worst.describe()}); '
                    'at consistency_scale 1 every sample passes: raise it to 1 (below 1 it '
                    'refuses even clean recordings)'
                )
        raise DatasetError(
            f'{where}: sample {sample} (stamp {int(stamps_ns[sample])} ns) does not follow from '
            f'the samples before it: {worst.describe()}; {count} such sample(s) in all. '
            'Positions, velocities and accelerations must describe one motion (a jump, a '
            'swapped or rescaled column, or a velocity of another signal does not); if the '
            "robot's recorded velocities lag or are filtered, raise consistency_scale in its "
            'robot config'
        )


class _ScaleWatch:
    """The whole-recording scale check on a stream, over its last ``SCALE_HORIZON_S``.

    Windows of ``SCALE_WINDOW_S`` sum the position change and the velocity integral of the
    pairs of samples that passed the local gate and were followed by a full window of samples
    that passed it too (the local gate looks that far back): a jump, a hole or a short
    contradiction is the local gate's, it never poisons the scale.
    """

    def __init__(self, gate: KinematicConsistency) -> None:
        self.gate = gate
        self.stride = max(1, round(SCALE_WINDOW_S / gate.period_s))
        self.horizon = max(1, round(SCALE_HORIZON_S / SCALE_WINDOW_S))  # windows
        self._windows: deque[tuple[np.ndarray, np.ndarray]] = deque(maxlen=self.horizon)
        self._dq = np.zeros(len(gate.joints))
        self._integral = np.zeros(len(gate.joints))
        self._count, self._pairs = 0, 0
        self._pending: deque[tuple[np.ndarray, np.ndarray]] = deque()
        self.failure: Inconsistency | None = None

    def forget_pending(self) -> None:
        """Pairs not yet confirmed are dropped (a hole: nothing after them will judge them)."""
        self._pending.clear()

    def add(self, pair: tuple[np.ndarray, np.ndarray] | None, passed: bool) -> None:
        """One sample: its pair's position change and velocity integral (None: no pair)."""
        if not passed:
            self._pending.clear()
        elif pair is not None:
            self._pending.append(pair)
        if len(self._pending) > self.gate.window:
            dq, integral = self._pending.popleft()
            self._dq += dq
            self._integral += integral
            self._pairs += 1
        self._count += 1
        if self._count < self.stride:
            return
        if self._pairs:
            self._windows.append((self._dq, self._integral))
            self._judge()
        self._dq, self._integral = np.zeros_like(self._dq), np.zeros_like(self._integral)
        self._count, self._pairs = 0, 0

    def _judge(self) -> None:
        dq = np.stack([w[0] for w in self._windows])
        integral = np.stack([w[1] for w in self._windows])
        span = len(self._windows) * self.stride * self.gate.period_s
        # A velocity bias the local gate allows (its floor) shifts the integral by up to
        # floor_v * span: judged only where the travel is 4 times that, so that no such bias
        # moves the factor by more than a quarter (slow motion is the local floor's).
        errors = self.gate.judge_scale(dq, integral, BIAS_MARGIN * self.gate.floor_v * span)
        if not errors:
            self.failure = None
            return
        name, factor, _ = max(errors, key=lambda e: np.inf if e[1] <= 0 else max(e[1], 1 / e[1]))
        self.failure = Inconsistency(name, 'scale', factor, 1.0, self.gate.scale_limit, span)


class ConsistencyStream:
    """The gate sample by sample (the predictor).

    Holds the samples of the last window and their velocity integral: ``check`` then ``push``
    each sample, ``reset`` after a hole in the stamps. Over the last ``SCALE_HORIZON_S`` it
    also judges the velocities' scale against the positions (``KinematicConsistency``'s
    whole-recording check): while a joint's factor is outside the limit, every sample fails.
    """

    def __init__(self, gate: KinematicConsistency) -> None:
        self.gate = gate
        # (stamp [ns], q, v, a or None, integral of v since the first [rad]), oldest first.
        self._history: deque[tuple[int, np.ndarray, np.ndarray, np.ndarray | None, np.ndarray]]
        self._history = deque(maxlen=gate.window)
        self._scale = _ScaleWatch(gate)
        self._passed = True

    @property
    def recovery_samples(self) -> int:
        """After samples scaled against their positions, valid ones pass from at most this-th.

        The scaled windows have left the horizon then (the one in progress, and ``horizon``
        more; a pair counts a local window after it).
        """
        return self._scale.stride * (self._scale.horizon + 1) + self.gate.window + 1

    def reset(self) -> None:
        """Forget the history: the next sample is compared with none."""
        self._history.clear()
        self._scale.forget_pending()

    def regate(self, gate: KinematicConsistency) -> bool:
        """Judge by ``gate`` from the next sample on (runtime settings); whether state was kept.

        A gate of the same joints and IPO period (another scale, or the same) keeps the window and
        the scale horizon; one of another period counts in other samples: no history (False).
        """
        if (gate.joints, gate.period_s) != (self.gate.joints, self.gate.period_s):
            self.__init__(gate)  # type: ignore[misc]  # a new stream, as after a hole
            return False
        self.gate = self._scale.gate = gate  # the scale's verdict stands to its next window
        return True

    def check(
        self, stamp_ns: int, q: np.ndarray, v: np.ndarray, a: np.ndarray | None
    ) -> Inconsistency | None:
        """The worst failing joint of this sample against the history, or None when it agrees.

        Stamps must increase (the caller's stamp guard).
        """
        found = self._local(stamp_ns, q, v, a)
        self._passed = found is None
        return found if found is not None else self._scale.failure

    def _local(
        self, stamp_ns: int, q: np.ndarray, v: np.ndarray, a: np.ndarray | None
    ) -> Inconsistency | None:
        history = self._history
        if not history:
            return None
        gate = self.gate
        last_stamp, last_q, last_v, last_a, last_integral = history[-1]
        dt = (stamp_ns - last_stamp) * 1e-9
        step = 0.5 * (last_v + v) * dt
        dq = q - last_q
        pair = gate.position_terms(dt, 1, dq, step, np.maximum(np.abs(v), np.abs(last_v)))
        half_a = 0.0 if a is None or last_a is None else 0.5 * (last_a + a) * dt
        dv = v - last_v
        velocity = gate.velocity_terms(dt, dv, half_a)
        old_stamp, old_q, old_v, _, old_integral = history[0]
        span = (stamp_ns - old_stamp) * 1e-9
        integral = last_integral + step - old_integral
        dq_window = q - old_q
        ends = np.maximum(np.abs(v), np.abs(old_v))
        window = gate.position_terms(span, len(history), dq_window, integral, ends)
        ratios = [mismatch / tolerance for mismatch, tolerance in (pair, window, velocity)]
        worst = [float(ratio.max()) for ratio in ratios]
        if max(worst) <= 1.0:
            return None
        kind = int(np.argmax(worst))
        j = int(np.argmax(ratios[kind]))
        tolerance = float((pair, window, velocity)[kind][1][j])
        if kind == 2:
            recorded = not isinstance(half_a, float)
            expected = 0.0 if isinstance(half_a, float) else float(half_a[j])
            return Inconsistency(
                gate.joints[j], 'velocity', float(dv[j]), expected, tolerance, dt, recorded
            )
        change, expected, over = (
            (dq[j], step[j], dt) if kind == 0 else (dq_window[j], integral[j], span)
        )
        return Inconsistency(
            gate.joints[j], 'position', float(change), float(expected), tolerance, over
        )

    def push(self, stamp_ns: int, q: np.ndarray, v: np.ndarray, a: np.ndarray | None) -> None:
        """Append a sample to the history (after ``check``, whether it passed or not)."""
        history = self._history
        pair: tuple[np.ndarray, np.ndarray] | None = None
        if history:
            last_stamp, last_q, last_v, _, last_integral = history[-1]
            step = 0.5 * (last_v + v) * ((stamp_ns - last_stamp) * 1e-9)
            integral = last_integral + step
            pair = (q - last_q, step)
        else:
            integral = np.zeros_like(v, dtype=float)
        history.append((stamp_ns, q, v, a, integral))
        self._scale.add(pair, self._passed)
        self._passed = True
