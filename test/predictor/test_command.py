"""The command stream (``predictor.command``): tau_u for a forward command controller, at most
one IPO period's worth of the slew limit per message, ramped to zero when the reference goes
stale and back when it resumes (the probe's P25: it dropped to zero and jumped back)."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
from predictor.test_feedforward import LinearModel, receive, sample

from id_learning.predictor import FeedForwardPredictor, GuardConfig
from id_learning.predictor.command import CommandStream


def live_core(mabi, **config) -> FeedForwardPredictor:
    core = FeedForwardPredictor(LinearModel(mabi), mabi.limits.torque, GuardConfig(**config))
    assert core.step(sample(0), receive(0)).tau is not None
    return core


def test_the_command_is_tau_u_while_it_moves_within_a_step(mabi):
    core = live_core(mabi)
    stream = CommandStream(core)
    step = mabi.limits.torque / core.config.torque_rise_s * core.config.period_s
    np.testing.assert_allclose(stream.step, step)
    first = np.array([100.0, -50.0, 3.0, 0.0, 1.0, 2.0])
    np.testing.assert_array_equal(stream.follow(first), first)  # nothing before it
    near = first + 0.5 * step
    np.testing.assert_array_equal(stream.follow(near), near)
    far = near + 3.0 * step
    np.testing.assert_allclose(stream.follow(far), near + step)


def test_a_stale_reference_ramps_the_command_to_exactly_zero_one_step_a_period(mabi):
    core = live_core(mabi, torque_rise_s=1.0)
    stream = CommandStream(core)
    tau = 0.9 * mabi.limits.torque * np.array([1, -1, 1, -1, 1, -1])
    stream.follow(tau)
    assert core.check_stale(receive(0) + core.config.stale_after_ns + 1)
    assert stream.went_stale()
    ramp = []
    while (command := stream.ramp()) is not None:
        ramp.append(command)
    steps = np.abs(np.diff([tau, *ramp], axis=0))
    assert (steps <= stream.step * (1 + 1e-12)).all()
    assert len(ramp) == math.ceil(0.9 / (core.config.period_s / 1.0))  # 0.9 s at 8 ms
    np.testing.assert_array_equal(ramp[-1], np.zeros(6))
    assert not stream.is_ramping
    # Resuming: from zero back towards tau_u, a step a message (tau_u continues from its own).
    assert core.step(sample(1), receive(0) + 2 * core.config.stale_after_ns).tau is not None
    np.testing.assert_allclose(
        stream.follow(tau), np.minimum(np.abs(tau), stream.step) * np.sign(tau)
    )


def test_the_reference_resuming_mid_ramp_ends_the_ramp_where_it_was(mabi):
    core = live_core(mabi, torque_rise_s=1.0)
    stream = CommandStream(core)
    tau = 0.9 * mabi.limits.torque
    stream.follow(tau)
    core.check_stale(receive(0) + core.config.stale_after_ns + 1)
    stream.went_stale()
    partial = [stream.ramp() for _ in range(3)][-1]
    np.testing.assert_allclose(partial, tau - 3 * stream.step)
    core.step(sample(1), receive(0) + 2 * core.config.stale_after_ns)  # live again
    assert stream.ramp() is None
    assert not stream.is_ramping
    np.testing.assert_allclose(stream.follow(tau), partial + stream.step)


def test_without_the_ramp_or_before_any_command_nothing_is_sent_when_stale(mabi):
    core = live_core(mabi)
    assert not CommandStream(core).went_stale()  # no command yet: nothing to ramp
    held = CommandStream(core, ramp_on_stale=False)
    held.follow(np.full(6, 100.0))
    core.check_stale(receive(0) + core.config.stale_after_ns + 1)
    assert not held.went_stale()
    assert held.ramp() is None
    np.testing.assert_array_equal(held.last, np.full(6, 100.0))  # the controller holds it


def test_a_runtime_change_of_torque_rise_s_applies_to_the_next_command(mabi):
    core = live_core(mabi)
    stream = CommandStream(core)
    before = stream.step.copy()
    core.update_config(replace(core.config, torque_rise_s=2 * core.config.torque_rise_s))
    np.testing.assert_allclose(stream.step, before / 2)
