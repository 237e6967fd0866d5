"""The predictor core's invariants over generated streams (hypothesis): whatever it is fed.

Streams are a smooth, valid motion broken by generated faults: position jumps, alternating
poses, a still position with a velocity, velocities flipping sign, NaN, stamps far ahead, back,
repeated, 50 ms ahead (``lead``, inside ``max_age_s``) or 0.6 period ahead (``nudge``, inside the
tolerance), floods (no time between arrivals) and silences. Between arrivals the node's watchdog
and command ramp run once per IPO period. Invariants, each against an independent reference:

- never a non-finite torque, never one beyond the (scaled) torque limits;
- never a change between published torques faster than the slew limit (``predictor.output``);
- never a model torque from a sample whose pair with the sample before it fails the consistency
  gate (``dataset.consistency``, evaluated here on the pair alone);
- never a model torque from a sample leading its time base by more than one IPO period (the
  quickest delivery, computed here in closed form: ``predictor.stamps``), nor from a ``lead``;
- the stamps of what is published increase, except across a resync (a new time base);
- the command stream (``predictor.command``) moves by at most one period's worth of the slew
  limit per message, around stale episodes too, ends each ramp exactly at zero, and is tau_u
  whenever tau_u is within that step of it;
- no lock-out: a valid stream after any of the above is served again within the stated bound,
  and the command stream rejoins tau_u within the steps its distance needs.
"""

from __future__ import annotations

import math
from typing import ClassVar

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from id_learning.dataset.consistency import (
    BIAS_MARGIN,
    FLOOR_SHARE,
    SCALE_HORIZON_S,
    SCALE_MIN_TRAVEL,
    SCALE_WINDOW_S,
    KinematicConsistency,
)
from id_learning.models.base import InverseDynamicsModel
from id_learning.predictor import FeedForwardPredictor, GuardConfig, ReferenceSample, Reject
from id_learning.predictor.command import CommandStream
from id_learning.predictor.stamps import DRIFT

PERIOD_NS = 8_000_000
FAULTS = ('valid', 'jump', 'alternate', 'still', 'flip', 'nan', 'ahead', 'back', 'repeat',
          'lead', 'nudge', 'flood', 'silence')  # fmt: skip


class SteepModel(InverseDynamicsModel):
    """A torque that spans the limits across the joint range: jumps in q are jumps in tau."""

    kind: ClassVar[str] = 'steep'

    def __init__(self, robot) -> None:
        self.robot = robot
        self.scale = 0.9 * robot.limits.torque

    def fit(self, data, *, progress=False):
        return self

    def predict(self, q, v, a):
        return self.scale * np.sin(2.0 * np.asarray(q)) + 50.0 * np.asarray(v) + np.asarray(a)

    def state(self):
        return {}

    def load_state(self, tensors, fitted):
        pass


def motion(k: int, phase: float, n: int = 6) -> tuple[np.ndarray, ...]:
    """A valid motion at sample k: q = 0.3 sin(2 t + phase) per joint (v, a consistent)."""
    t = k * PERIOD_NS * 1e-9
    angle = 2.0 * t + phase + np.arange(n)
    return 0.3 * np.sin(angle), 0.6 * np.cos(angle), -1.2 * np.sin(angle)


def fed(faults: list[str], phase: float, start_k: int = 0):
    """(sample, receive time) pairs of a stream with ``faults`` per sample."""
    stream = []
    receive = 5 * 10**9
    for i, fault in enumerate(faults):
        k = start_k + i
        q, v, a = motion(k, phase)
        stamp = 10**9 + k * PERIOD_NS
        receive += PERIOD_NS
        if fault == 'jump':
            q = q + 1.0
        elif fault == 'alternate':
            q = q + (0.8 if i % 2 else 0.0)
        elif fault == 'still':
            q = motion(start_k, phase)[0]
            v = np.full(6, 1.3)
        elif fault == 'flip':
            v = np.full(6, 1.3 if i % 2 else -1.3)
        elif fault == 'nan':
            q = q.copy()
            q[i % 6] = np.nan
        elif fault == 'ahead':
            stamp += 3600 * 10**9
        elif fault == 'back':
            stamp -= 3600 * 10**9
        elif fault == 'repeat':
            stamp = 10**9 + max(k - 1, 0) * PERIOD_NS
        elif fault == 'lead':  # the probe's P12: inside max_age_s, six periods ahead
            stamp += 50_000_000
        elif fault == 'nudge':  # inside the tolerance: taken, and the next valid one after it
            stamp += 6 * PERIOD_NS // 10
        elif fault == 'flood':
            receive -= PERIOD_NS - 1000
        elif fault == 'silence':
            receive += 20 * PERIOD_NS
        stream.append((ReferenceSample(stamp, tuple(f'joint_{j}' for j in range(1, 7)),
                                       q, v, a), receive))  # fmt: skip
    return stream


def predictor_for(mabi) -> FeedForwardPredictor:
    joints = tuple(mabi.joints)
    return FeedForwardPredictor(SteepModel(mabi), mabi.limits.torque, GuardConfig(),
                                limits=mabi.limits.take(range(len(joints))))  # fmt: skip


faults_strategy = st.lists(
    st.sampled_from(FAULTS).flatmap(lambda f: st.lists(st.just(f), min_size=1, max_size=6)),
    min_size=1,
    max_size=12,
).map(lambda runs: [f for run in runs for f in run])


@settings(
    max_examples=150, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
@given(faults=faults_strategy, phase=st.floats(0.0, 6.28))
def test_whatever_the_stream_the_output_is_finite_bounded_slew_limited_and_gated(
    mabi, faults, phase
):
    predictor = predictor_for(mabi)
    config = predictor.config
    slew = mabi.limits.torque / config.torque_rise_s
    gate = KinematicConsistency(tuple(mabi.joints), mabi.limits, config.period_s)
    last_tau, last_stamp = None, None
    previous = None  # the last sample taken into the history (passed joints, finite, time)
    for sample, receive in fed(faults, phase):
        result = predictor.step(sample, receive)
        taken = result.reject in (None, Reject.INCONSISTENT, Reject.REARMING)
        if result.reject is None and previous is not None:
            dt = sample.stamp_ns - previous.stamp_ns
            if 0 < dt <= config.stale_after_ns:  # a pair the gate compares
                pair = gate.failing(np.array([previous.stamp_ns, sample.stamp_ns]),
                                    np.array([previous.q, sample.q]),
                                    np.array([previous.v, sample.v]),
                                    np.array([previous.a, sample.a]))  # fmt: skip
                assert not pair[1], 'a model torque from a sample that fails the gate'
        if taken:
            previous = sample
        if result.tau is None:
            continue
        tau = result.tau
        assert np.isfinite(tau).all()
        assert (np.abs(tau) <= mabi.limits.torque * config.torque_limit_scale + 1e-9).all()
        if last_tau is not None:
            interval = min(max(sample.stamp_ns - last_stamp, PERIOD_NS), config.stale_after_ns)
            assert (np.abs(tau - last_tau) <= slew * interval * 1e-9 * (1 + 1e-9) + 1e-9).all()
        assert result.reject is None or result.is_held
        last_tau, last_stamp = tau, sample.stamp_ns


def drive(predictor: FeedForwardPredictor, stream, commands: CommandStream):
    """Step each sample as the node does, its tau_u sent as a command too; between arrivals the
    node's watchdog and command ramp run once per IPO period.

    Returns:
        the results, and the commands in order as (command, 'follow' tau or 'ramp' None,
        a ramp under way after it).
    """
    results, sent = [], []
    last = None
    for sample, receive in stream:
        tick = receive if last is None else last + PERIOD_NS
        while tick < receive:
            if predictor.check_stale(tick):
                commands.went_stale()
            command = commands.ramp()
            if command is not None:
                sent.append((command.copy(), None, commands.is_ramping))
            tick += PERIOD_NS
        last = receive
        result = predictor.step(sample, receive)
        results.append(result)
        if result.tau is not None:
            sent.append((commands.follow(result.tau).copy(), result.tau, False))
    return results, sent


def lead_ns(base: list[tuple[int, int]], stamp: int, receive: int) -> int:
    """How far ``stamp`` leads the time base of the accepted (receive, stamp) pairs ``base``:
    the quickest delivery, each pair's offset allowed to grow by DRIFT times the stamps since."""
    last_stamp = base[-1][1]
    offset = min(r - s + round(DRIFT * (last_stamp - s)) for r, s in base)
    return stamp - receive + offset


@settings(
    max_examples=150, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
@given(faults=faults_strategy, phase=st.floats(0.0, 6.28))
def test_whatever_the_stream_stamps_rise_future_stamps_get_no_torque_and_the_command_ramps(
    mabi, faults, phase
):
    predictor = predictor_for(mabi)
    config = predictor.config
    commands = CommandStream(predictor)
    step = mabi.limits.torque / config.torque_rise_s * config.period_s
    assert np.allclose(commands.step, step)
    stream = fed(faults, phase)
    results, sent = drive(predictor, stream, commands)
    # Stamps: a model torque only within one period ahead of the time base; rising outputs.
    base: list[tuple[int, int]] = []
    last_out, resynced_since = None, False
    for i, ((sample, receive), result) in enumerate(zip(stream, results, strict=True)):
        stamp = sample.stamp_ns
        if result.reject is None and base and not result.resynced:
            lead = lead_ns(base, stamp, receive)
            assert lead <= PERIOD_NS, f'a model torque for a stamp {lead} ns ahead'
        if faults[i] == 'lead' and base and 'lead' not in faults[:i]:  # ahead of a time base
            assert result.reject is not None, 'a model torque for a stamp 50 ms ahead'
        resynced_since |= result.resynced
        if result.tau is not None:
            if last_out is not None and stamp <= last_out:
                assert resynced_since, f'output stamp {stamp} after {last_out}, no resync'
            last_out, resynced_since = stamp, False
        if result.reject in (None, Reject.INCONSISTENT, Reject.REARMING):  # taken
            restart = result.resynced or (base and stamp - base[-1][1] > config.stale_after_ns)
            base = [(receive, stamp)] if restart else [*base, (receive, stamp)]
    # Commands: at most one step per message; ramps end at zero; tau_u when within a step.
    previous = None
    ramp_from, ramp_length = None, 0
    for command, tau, still_ramping in sent:
        assert np.isfinite(command).all()
        if previous is not None:
            assert (np.abs(command - previous) <= step * (1 + 1e-12) + 1e-9).all()
        if tau is None:  # a ramp command
            if ramp_length == 0:
                ramp_from = previous
            ramp_length += 1
            if not still_ramping:
                assert not command.any(), 'a ramp that ended off zero'
        else:
            if ramp_length and ramp_from is not None and previous.any():  # cut short: resumed
                assert ramp_length < np.ceil(np.max(np.abs(ramp_from) / step)) + 1
            ramp_length = 0
            if previous is None or (np.abs(tau - previous) <= step).all():
                np.testing.assert_array_equal(command, tau)
        previous = command


@settings(
    max_examples=100, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
@given(faults=faults_strategy, phase=st.floats(0.0, 6.28), new_phase=st.floats(0.0, 6.28),
       shift=st.sampled_from([0, 50, -3600 * 125, 3600 * 125]))  # fmt: skip
def test_after_any_fault_a_valid_stream_is_served_again_within_the_stated_bound(
    mabi, faults, phase, new_phase, shift
):
    predictor = predictor_for(mabi)
    commands = CommandStream(predictor)
    drive(predictor, fed(faults, phase), commands)
    # A valid motion from another pose, its stamps anywhere (an hour back or ahead included).
    bound = predictor.recovery_samples
    # The command's way back: from anywhere within the limits, at one step per message less
    # what tau_u moves meanwhile (a few % of the limit per cycle on this motion).
    rejoin = math.ceil(2.0 / (0.8 * predictor.config.period_s / predictor.config.torque_rise_s))
    tail = fed(['valid'] * (bound + rejoin + 10), new_phase, start_k=len(faults) + 30 + shift)
    offset = len(faults) * PERIOD_NS + 10**9  # receive times go on after the faults'
    tail = [(sample, receive + offset) for sample, receive in tail]
    results, sent = drive(predictor, tail, commands)
    assert all(r.reject is None and r.tau is not None for r in results[bound:]), [
        r.reject for r in results
    ]
    served = [(command, tau) for command, tau, _ in sent[-(len(results) - bound) :]]
    assert all(tau is not None for _, tau in served)
    for command, tau in served[rejoin:]:
        np.testing.assert_array_equal(command, tau)


def test_the_stated_bound_is_what_the_docs_say(mabi):
    # resync_after 5 + a 50 ms window of 7 IPO cycles + rearm_samples 2 + 1
    assert predictor_for(mabi).recovery_samples == 15


@pytest.mark.parametrize('fault', ['alternate', 'still', 'flip'])
def test_an_impossible_succession_gets_no_model_torque_but_the_hold_output(mabi, fault):
    predictor = predictor_for(mabi)
    stream = fed(['valid'] * 20 + [fault] * 20, 0.3)
    results = [predictor.step(sample, receive) for sample, receive in stream]
    assert all(r.reject is None for r in results[:20])
    bad = results[21:]  # the first of 'alternate' is the valid pose
    assert all(r.reject is Reject.INCONSISTENT for r in bad)
    held = [r for r in results[20:] if r.is_held]
    assert held
    assert predictor.counters.held_samples == len(held)
    # Held while the last served sample is at most the stale threshold old, then nothing.
    stale = predictor.config.stale_after_cycles
    assert all(r.tau is None for r in results[20 + stale + 1 :])


def test_a_jump_to_another_motion_is_held_then_served_once_consistent(mabi):
    predictor = predictor_for(mabi)
    results = [predictor.step(sample, receive)
               for sample, receive in fed(['valid'] * 20 + ['jump'] * 30, 0.3)]  # fmt: skip
    assert results[20].reject is Reject.INCONSISTENT
    assert results[20].is_held
    window = predictor.recovery_samples - predictor.config.resync_after - 1
    served_again = 20 + window
    assert all(r.reject is not None for r in results[20:served_again])
    assert all(r.reject is None for r in results[served_again:])


SCALES = [2.0, 0.5, 3.0, 1 / 3, np.pi / 180, 180 / np.pi, -1.0, 1.6, 0.6]


def scaled_stream(
    n: int, n_scaled: int, scale: float, joint: int, phase: float, rate: float, start: float
):
    """A motion whose first ``n_scaled`` samples carry one joint's velocity times ``scale``.

    That joint travels at a steady ``rate`` [rad/s] from ``start``, the others swing (0.3 rad,
    1 rad/s).
    """
    names = tuple(f'joint_{j}' for j in range(1, 7))
    stream = []
    for k in range(n):
        t = k * PERIOD_NS * 1e-9
        angle = t + phase + np.arange(6)
        q, v, a = 0.3 * np.sin(angle), 0.3 * np.cos(angle), -0.3 * np.sin(angle)
        q[joint], v[joint], a[joint] = start + rate * t, rate, 0.0
        if k < n_scaled:
            v[joint] *= scale
        stamp = 10**9 + k * PERIOD_NS
        stream.append((ReferenceSample(stamp, names, q, v, a), 5 * 10**9 + k * PERIOD_NS))
    return stream


@settings(
    max_examples=12, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
@given(scale=st.sampled_from(SCALES), joint=st.integers(0, 5), phase=st.floats(0.0, 6.28),
       share=st.floats(0.22, 0.35))  # fmt: skip
def test_velocities_scaled_against_the_positions_are_gated_then_the_stream_recovers(
    mabi, scale, joint, phase, share
):
    predictor = predictor_for(mabi)
    bound = predictor.scale_recovery_samples
    n_scaled = bound
    rate = share * float(mabi.limits.velocity[joint])  # judged from 20 % of the limit on
    start = float(mabi.limits.position_lower[joint]) + 0.1  # the ramp stays inside the limits
    stream = scaled_stream(n_scaled + bound + 5, n_scaled, scale, joint, phase, rate, start)
    results = [predictor.step(sample, receive) for sample, receive in stream]
    scaled = results[:n_scaled]
    # Judged once the joint has travelled enough, at the end of a window: no scaled sample is
    # served from there on (the sample-to-sample gate may refuse them before).
    period_s = PERIOD_NS * 1e-9
    floor_v = FLOOR_SHARE * float(mabi.limits.velocity[joint])
    travel = max(SCALE_MIN_TRAVEL, BIAS_MARGIN * floor_v * SCALE_HORIZON_S)
    judged = math.ceil(travel / (rate * period_s)) + 2 * round(SCALE_WINDOW_S / period_s)
    assert judged < n_scaled
    assert all(r.reject is not None for r in scaled[judged:])  # x57 is beyond the limits too
    named = [r.detail for r in scaled[judged:] if 'integrate to' in r.detail]
    assert all(f'the velocities of joint_{joint + 1} integrate to' in d for d in named)
    # The valid motion after them is served again from the stated bound on.
    assert all(r.reject is None for r in results[n_scaled + bound - 1 :])


def test_a_slow_crawl_with_a_velocity_bias_inside_the_floor_is_served(mabi):
    predictor = predictor_for(mabi)
    names = tuple(f'joint_{j}' for j in range(1, 7))
    bias = 0.8 * FLOOR_SHARE * mabi.limits.velocity  # what the local gate allows, nearly
    results = []
    for k in range(1500):  # 12 s crawling at 0.03 rad/s
        t = k * PERIOD_NS * 1e-9
        q, v = -0.2 + 0.03 * t * np.ones(6), 0.03 * np.ones(6) + bias
        sample = ReferenceSample(10**9 + k * PERIOD_NS, names, q, v, np.zeros(6))
        results.append(predictor.step(sample, 5 * 10**9 + k * PERIOD_NS))
    assert all(r.reject is None for r in results), {r.detail for r in results if r.reject}


def test_the_scale_bound_is_the_scale_horizon_and_the_rearm(mabi):
    # 25 cycles a window (0.2 s), 10 windows (2 s): 11 windows + a 7-cycle local window + 1,
    # then rearm_samples 2 + 1
    assert predictor_for(mabi).scale_recovery_samples == 25 * 11 + 7 + 1 + 3
