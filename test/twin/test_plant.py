"""The twin as a plant: its inverse dynamics against the recordings', and the closed loop."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
import yaml
from support import REPO, twin_config

from id_learning.dataset.inputs import Motion
from id_learning.evaluation.closed_loop import (
    FEEDBACK_ONLY,
    LoopGains,
    compare_feed_forward,
    improvement,
    track,
)
from id_learning.twin import simulate
from id_learning.twin.plant import TwinPlant

PERIOD_S = 0.008


@pytest.fixture(scope='module')
def twin():
    """A 12 s recording of the default twin without its label-only effects (offset, delay)."""
    effects = yaml.safe_load((REPO / 'config/twin_default.yaml').read_text())['effects']
    effects['signal_delay']['enabled'] = False
    effects['torque_offset']['enabled'] = False
    config = twin_config(12.0, effects, seed=5)
    return config, simulate(config)


def test_the_plant_needs_the_torque_the_recordings_hold(twin) -> None:
    config, result = twin
    plant = TwinPlant(config)
    tau = plant.motor_torque(result.q_true, result.v_true, result.a_true)
    # simulate divides every component by the torque-constant scale: tau_u = tau_motor / s
    np.testing.assert_allclose(tau / plant.kt_scale, result.tau_u_clean, rtol=1e-9, atol=1e-6)


def test_a_step_under_the_needed_torque_gives_the_motion_s_acceleration(twin) -> None:
    config, result = twin
    plant = TwinPlant(config)
    k = 400
    q, v, a = result.q_true[k], result.v_true[k], result.a_true[k]
    state = plant.start(q, v, a)
    command = plant.motor_torque(q, v, a)[0] / plant.kt_scale
    dt = 1e-5
    after = plant.step(state, command, dt)
    np.testing.assert_allclose((after.v - v) / dt, a, rtol=1e-3, atol=1e-3)
    np.testing.assert_allclose(after.q, q + dt * after.v)


def test_the_drive_delivers_the_command_less_the_current_sensor_s_offset() -> None:
    """The current loop regulates on the offset sensor: the needed command holds the offset."""
    effects = yaml.safe_load((REPO / 'config/twin_default.yaml').read_text())['effects']
    effects['signal_delay']['enabled'] = False
    offset = np.array([12.0, -18.0, 9.0, 2.0, -1.5, 0.6])
    effects['torque_offset'] |= {'enabled': True, 'offset': offset.tolist()}
    config = twin_config(4.0, effects, seed=7)
    result = simulate(config)
    plant = TwinPlant(config)
    np.testing.assert_allclose(plant.sensor_offset, offset)
    command = plant.command(result.q_true, result.v_true, result.a_true)
    # What the labels hold, noise-free: the motion's tau_u plus the sensor's offset.
    np.testing.assert_allclose(command, result.tau_u_clean, rtol=1e-9, atol=1e-6)
    k = 200
    q, v, a = result.q_true[k], result.v_true[k], result.a_true[k]
    dt = 1e-5
    after = plant.step(plant.start(q, v, a), command[k], dt)
    np.testing.assert_allclose((after.v - v) / dt, a, rtol=1e-3, atol=1e-3)
    without = plant.step(plant.start(q, v, a), command[k] - offset, dt)
    assert np.all(np.abs((without.v - v) / dt - a) > 1e-3)  # the offset moves the arm


def test_true_feed_forward_shrinks_the_tracking_error_and_a_biased_one_less(twin) -> None:
    config, result = twin
    plant = TwinPlant(config)
    reference = Motion(result.q_true - plant.encoder_offset, result.v_true, result.a_true)
    true_ff = plant.motor_torque(result.q_true, result.v_true, result.a_true) / plant.kt_scale
    runs = compare_feed_forward(
        plant,
        reference,
        {'true': true_ff, 'half': 0.5 * true_ff},
        period_s=PERIOD_S,
        progress=False,
    )
    assert set(runs) == {FEEDBACK_ONLY, 'true', 'half'}
    assert (runs['true'].rms < runs['half'].rms).all()
    assert (runs['half'].rms < runs[FEEDBACK_ONLY].rms).all()
    best, ratio = improvement(runs, ['half', 'true'])
    assert best == 'true'
    assert (ratio > 3).all()
    assert not runs[FEEDBACK_ONLY].saturated.any()


def test_the_command_saturates_at_the_torque_limit_without_wind_up(twin) -> None:
    config, result = twin
    plant = TwinPlant(config)
    reference = Motion(result.q_true - plant.encoder_offset, result.v_true, result.a_true)
    gains = LoopGains.for_plant(plant, result.q_true[0])
    huge = np.tile(10 * config.robot.limits.torque, (len(reference.q), 1))
    run = track(plant, reference.take(slice(0, 5)), huge, gains, period_s=PERIOD_S)
    np.testing.assert_allclose(np.abs(run.command), np.tile(config.robot.limits.torque, (5, 1)))
    assert (run.saturated == 5).all()


def test_a_friction_warming_up_over_the_shift_is_the_recordings_in_the_plant() -> None:
    effects = yaml.safe_load((REPO / 'config/twin_default.yaml').read_text())['effects']
    effects['signal_delay']['enabled'] = False
    effects['torque_offset']['enabled'] = False
    for name in ('viscous_friction', 'coulomb_friction'):
        effects[name] |= {'warm_scale': 0.7, 'warm_up_s': 4.0}
    config = twin_config(8.0, effects, seed=6, shift_start_s=3.0)
    result = simulate(config)
    plant = TwinPlant(config)
    tau = plant.motor_torque(result.q_true, result.v_true, result.a_true)
    np.testing.assert_allclose(tau / plant.kt_scale, result.tau_u_clean, rtol=1e-9, atol=1e-6)
    cold = TwinPlant(replace(config, shift_start_s=0.0)).motor_torque(
        result.q_true, result.v_true, result.a_true
    )
    assert np.abs(cold - tau).max() > 1.0  # the friction has fallen since the start


def test_a_feed_forward_no_drive_can_follow_is_a_diverged_run_not_a_crash(twin) -> None:
    config, result = twin
    plant = TwinPlant(config)
    reference = Motion(result.q_true - plant.encoder_offset, result.v_true, result.a_true)
    bad = np.full_like(reference.q, np.nan)
    runs = compare_feed_forward(
        plant, reference.take(slice(0, 50)), {'nan': bad[:50]}, period_s=PERIOD_S, progress=False
    )
    assert runs['nan'].diverged_at == 0
    assert np.isinf(runs['nan'].rms).all()
    assert runs[FEEDBACK_ONLY].diverged_at is None
