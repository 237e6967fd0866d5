"""Fault cases at the predictor's core fed whole streams: kinematic contradictions and time faults.

Each case plays 40 samples of the twin's recording, then a faulty span, then the recording again,
through ``FeedForwardPredictor`` on the fixture's artifact. It is ``handled`` when every published
torque is finite, within the torque limits and the slew limit, no model torque comes from the
faulty span's changed samples, and the valid samples after it are served again within the bound
the predictor states (``recovery_samples``); otherwise the first broken
invariant is named.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator

import numpy as np
from fault_kit import Case, Fixtures, Outcome

__all__ = ['stream_cases']

PERIOD_NS = 8_000_000
HOUR_NS = 3600 * 10**9
#: (sample index in the faulty span, stamp, receive, q, v) -> the same, changed.
Change = Callable[[int, int, int, np.ndarray, np.ndarray], tuple[int, int, np.ndarray, np.ndarray]]


def _play(fx: Fixtures, change: Change, *, contradiction: bool, with_a: bool) -> Outcome:
    from id_learning.predictor import FeedForwardPredictor, ReferenceSample

    rec = fx.recording
    joints = tuple(rec.joints)
    predictor = FeedForwardPredictor.from_artifact(fx.artifact, fx.robot)
    config = predictor.config
    bound = predictor.recovery_samples
    start, span, after = 300, 20, 40
    a = np.gradient(rec.velocity, rec.stamps_ns * 1e-9, axis=0)
    slew = fx.robot.limits.torque / config.torque_rise_s  # type: ignore[attr-defined]
    last: tuple[np.ndarray, int] | None = None
    served_in_span, tail = 0, []
    for i in range(start, start + 40 + span + after):
        stamp, receive = int(rec.stamps_ns[i]), 10**9 + i * PERIOD_NS
        q, v = rec.position[i].copy(), rec.velocity[i].copy()
        in_span = start + 40 <= i < start + 40 + span
        modified = False
        if in_span:
            stamp, receive, q, v = change(i - start - 40, stamp, receive, q, v)
            modified = not (
                np.array_equal(q, rec.position[i]) and np.array_equal(v, rec.velocity[i])
            )
        sample = ReferenceSample(stamp, joints, q, v, a[i] if with_a else None)
        result = predictor.step(sample, receive)
        if modified and result.reject is None and contradiction:
            served_in_span += 1
        if i >= start + 40 + span:
            tail.append(result.reject is None)
        if result.tau is None:
            continue
        tau = result.tau
        if not np.isfinite(tau).all() or (np.abs(tau) > fx.robot.limits.torque).any():  # type: ignore[attr-defined]
            return Outcome('silently_accepted', f'published {np.round(tau, 1).tolist()}')
        if last is not None:
            interval = min(max(stamp - last[1], PERIOD_NS), config.stale_after_ns) * 1e-9
            if (np.abs(tau - last[0]) > slew * interval * (1 + 1e-9)).any():
                return Outcome('silently_accepted', f'torque changed faster than the slew limit '
                                                    f'at sample {i}')  # fmt: skip
        last = (tau, stamp)
    counters = predictor.counters
    said = (f'{counters.rejected} without a model torque '
            f'{ {r.value: c for r, c in counters.rejects.items() if c} }, '
            f'{counters.held_samples} held, {counters.resyncs} resyncs')  # fmt: skip
    if served_in_span:
        return Outcome(
            'silently_accepted', f'{served_in_span} contradicting samples served; {said}'
        )
    if not all(tail[bound:]):
        return Outcome(
            'silently_accepted', f'valid samples not served again within {bound}: {said}'
        )
    return Outcome('handled', said)


def stream_cases(fx: Fixtures) -> Iterator[Case]:
    if fx.run_dir is None:
        return

    def jump(i: int, stamp: int, receive: int, q: np.ndarray, v: np.ndarray):  # type: ignore[no-untyped-def]
        return stamp, receive, q + (1.0 if i == 0 else 0.0), v

    def alternate(i, stamp, receive, q, v):  # type: ignore[no-untyped-def]
        return stamp, receive, q + (0.8 if i % 2 else 0.0), v

    def still(i, stamp, receive, q, v):  # type: ignore[no-untyped-def]
        return stamp, receive, still_pose.copy(), np.full(6, 1.3)

    def flip(i, stamp, receive, q, v):  # type: ignore[no-untyped-def]
        return stamp, receive, q, np.full(6, 1.3 if i % 2 else -1.3)

    def one_ahead(i, stamp, receive, q, v):  # type: ignore[no-untyped-def]
        return stamp + (HOUR_NS if i == 0 else 0), receive, q, v

    def clock_back(i, stamp, receive, q, v):  # type: ignore[no-untyped-def]
        return stamp - HOUR_NS, receive, q, v

    def repeated(i, stamp, receive, q, v):  # type: ignore[no-untyped-def]
        return stamp - i * PERIOD_NS, receive, q, v

    def flood(i, stamp, receive, q, v):  # type: ignore[no-untyped-def]
        return stamp, receive - (i + 1) * (PERIOD_NS - 400_000), q, v

    still_pose = fx.recording.position[340].copy()  # type: ignore[attr-defined]
    cases: tuple[tuple[str, Change, bool], ...] = (
        ('a 1 rad position jump in one cycle', jump, True),
        ('two poses 0.8 rad apart alternating', alternate, True),
        ('a still position with 1.3 rad/s velocity', still, True),
        ('velocities flipping between +1.3 and -1.3 rad/s', flip, True),
        ('one stamp an hour ahead', one_ahead, False),
        ("the sender's clock stepping an hour back", clock_back, False),
        ('one stamp repeated', repeated, False),
        ('a flood: samples 0.4 ms apart', flood, False),
    )
    for name, change, contradiction in cases:
        for with_a in (True, False):
            kind = 'trajectory' if with_a else 'joint_state'
            yield Case(f'stream: {name} ({kind})', 'predictor',
                       lambda c=change, x=contradiction, w=with_a: _play(
                           fx, c, contradiction=x, with_a=w))  # fmt: skip
