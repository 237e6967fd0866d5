"""A label that lost its sign (``|I|`` or ``-|I|`` recorded) is named per joint; signed ones never.

Over generated motions and labels: the magnitude of any label that crosses zero is found on a
joint that moves both ways; a signed label (noisy, quantised, offset), a label held on one side
by gravity, and the magnitude on a joint moving one way only are never found.
"""

from __future__ import annotations

import logging
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from support import sine_recording

from id_learning.dataset.content import check_content, sign_findings
from id_learning.dataset.inspect import inspect_bag
from id_learning.dataset.recording import write_recording
from id_learning.physics.rigid_body import RigidBodyDynamics

PERIOD_S = 0.008


def signals(seed: int, n_samples: int, frequency: float, amplitude: float, offset: float):
    """A joint going back and forth, and a signed label of inertia, friction and an offset."""
    rng = np.random.default_rng(seed)
    t = np.arange(n_samples) * PERIOD_S
    phase = rng.uniform(0, 2 * np.pi)
    q = 0.5 * np.sin(2 * np.pi * frequency * t + phase)
    qd = np.gradient(q, PERIOD_S)
    inertia = np.sin(2 * np.pi * frequency * t + phase + 0.7)
    return q, amplitude * (inertia + 0.3 * np.tanh(qd / 0.01) + offset)


def quantised(x: np.ndarray, step: float) -> np.ndarray:
    return x if step == 0 else np.round(x / step) * step


SIGNALS = {
    'seed': st.integers(0, 2**16),
    'periods': st.floats(1.2, 6.0),
    'frequency': st.floats(0.1, 1.0),
    'amplitude': st.floats(0.05, 50.0),
    'offset': st.floats(-0.8, 0.8),
    'noise_share': st.floats(0.002, 0.05),
    'step_share': st.sampled_from([0.0, 1e-3, 5e-3]),
}


def _make(seed, periods, frequency, amplitude, offset, noise_share, step_share):
    n_samples = int(periods / (frequency * PERIOD_S))
    q, label = signals(seed, n_samples, frequency, amplitude, offset)
    noise = np.random.default_rng(seed + 1).normal(0, noise_share * amplitude, n_samples)
    return q, quantised(label + noise, step_share * amplitude)


@given(sign=st.sampled_from([1.0, -1.0]), **SIGNALS)
def test_the_magnitude_of_any_label_crossing_zero_is_found_lost(sign, **drawn):
    q, label = _make(**drawn)
    lost = sign * np.abs(label)
    findings = sign_findings(q[:, None], lost[:, None], ('joint_4',))
    assert [(f.joint, f.kind, f.refuses) for f in findings] == [('joint_4', 'sign_lost', False)]
    side = '<= 0' if sign < 0 else '>= 0'
    assert findings[0].text.startswith(f'joint_4: the motor current is {side} in every sample')
    assert 'record the signed motor current' in findings[0].text


@given(**SIGNALS)
def test_a_signed_label_is_never_found_lost(**drawn):
    q, label = _make(**drawn)
    assert sign_findings(q[:, None], label[:, None], ('joint_1',)) == []


@given(
    seed=st.integers(0, 2**16),
    frequency=st.floats(0.1, 1.0),
    amplitude=st.floats(0.05, 50.0),
    hold=st.floats(1.6, 20.0),
)
def test_a_label_held_on_one_side_by_gravity_is_not_lost(seed, frequency, amplitude, hold):
    q, label = signals(seed, int(3 / (frequency * PERIOD_S)), frequency, amplitude, 0.0)
    held = label - hold * amplitude  # gravity holds it below zero, the motion rides on top
    assert np.all(held < 0)
    assert sign_findings(q[:, None], held[:, None], ('joint_2',)) == []


@given(seed=st.integers(0, 2**16), amplitude=st.floats(0.05, 50.0))
def test_a_magnitude_on_a_joint_moving_one_way_is_not_judged(seed, amplitude):
    n_samples = 2000
    q = np.linspace(-1.0, 1.0, n_samples)  # no reversal: the torque may keep its sign
    label = amplitude * np.abs(np.sin(np.linspace(0, 6 * np.pi, n_samples)))
    label += np.random.default_rng(seed).normal(0, 0.001 * amplitude, n_samples)
    assert sign_findings(q[:, None], np.abs(label)[:, None], ('joint_6',)) == []


def test_a_lost_sign_is_warned_on_load_and_listed_by_inspect(
    mabi, tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    recording = sine_recording(2000)
    current = recording.current.copy()
    current[:, 0] = -np.abs(current[:, 0])
    lost = replace(recording, current=current, source='lost')
    with caplog.at_level(logging.WARNING):
        warnings = check_content(lost.position, lost.current, lost.joints, where='lost')
    assert [w for w in warnings if 'sign is lost' in w] == [
        w for w in warnings if w.startswith('joint_1: the motor current is <= 0')
    ]
    assert len(warnings) == 1
    assert any(r.getMessage().startswith('lost: joint_1: ') for r in caplog.records)
    gravity = RigidBodyDynamics.from_config(mabi).gravity
    problems = inspect_bag(write_recording(lost, tmp_path / 'lost'), robot=mabi, gravity=gravity)
    assert [p for p in problems.problems if 'sign is lost' in p] == [
        f'/motor_currents: {warnings[0]}'
    ]
    clean = write_recording(recording, tmp_path / 'clean')
    assert not [p for p in inspect_bag(clean, robot=mabi, gravity=gravity).problems if 'lost' in p]


@given(seed=st.integers(0, 2**16), mean=st.floats(1.0, 5.0), noise_share=st.floats(0.05, 0.3),
       off_share=st.floats(0.0, 0.3))  # fmt: skip
def test_a_noisy_held_label_and_a_drive_switched_off_are_not_lost(
    seed, mean, noise_share, off_share
):
    rng = np.random.default_rng(seed)
    n = 4000
    q = 0.5 * np.sin(2 * np.pi * 0.5 * np.arange(n) * PERIOD_S)
    label = np.clip(mean + noise_share * mean * rng.standard_normal(n), 1e-9, None)  # held
    label[: int(off_share * n)] = 0.0  # the drive off before the motion
    assert sign_findings(q[:, None], label[:, None], ('joint_2',)) == []


def test_a_magnitude_with_a_few_samples_across_zero_says_how_many():
    n = 3000
    t = np.arange(n) * PERIOD_S
    q = 0.5 * np.sin(2 * np.pi * 0.3 * t)
    label = np.abs(np.sin(2 * np.pi * 0.7 * t))
    label[[100, 900]] = -0.001  # two stray samples
    (finding,) = sign_findings(q[:, None], label[:, None], ('joint_3',))
    assert 'is >= 0 in all but 2 samples' in finding.text


@given(
    seed=st.integers(0, 2**16),
    frequency=st.floats(0.1, 1.0),
    amplitude=st.floats(0.05, 50.0),
    hold=st.floats(1.0001, 1.6),
)
def test_a_label_gravity_holds_close_to_zero_is_not_lost_where_gravity_is_known(
    seed, frequency, amplitude, hold
):
    q, label = signals(seed, int(3 / (frequency * PERIOD_S)), frequency, amplitude, 0.0)
    gravity = -hold * amplitude * (1.0 + 0.2 * np.cos(q))  # one-signed along the motion
    held = label + gravity
    held = np.minimum(held, -1e-9)  # one-signed, as it comes (noise clipped at its edge)
    assert sign_findings(q[:, None], held[:, None], ('joint_3',), held=gravity[:, None]) == []


@given(sign=st.sampled_from([1.0, -1.0]), **SIGNALS)
def test_a_magnitude_is_still_lost_where_gravity_crosses_zero(sign, **drawn):
    q, label = _make(**drawn)
    gravity = 0.5 * np.sin(q)  # crosses zero along the motion: it holds nothing on one side
    findings = sign_findings(
        q[:, None], sign * np.abs(label)[:, None], ('joint_1',), held=gravity[:, None]
    )
    assert [f.joint for f in findings] == ['joint_1']


def test_a_twin_joint_that_gravity_holds_below_zero_is_not_called_lost(mabi) -> None:
    """A 26 s default twin: joint_3's tau_u stays below zero, gravity holds it there."""
    from support import twin_config

    from id_learning.twin import simulate

    recording = simulate(twin_config(26.0, seed=5)).recording
    gravity = RigidBodyDynamics.from_config(mabi).gravity
    warnings = check_content(
        recording.position, recording.current, recording.joints, where='twin',
        nominal=(mabi, gravity), warn=False,
    )  # fmt: skip
    assert not [w for w in warnings if 'sign is lost' in w]
