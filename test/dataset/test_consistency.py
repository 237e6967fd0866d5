"""The kinematic consistency gate against closed-form motions and the faults it exists for."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from id_learning.dataset.consistency import ConsistencyStream, KinematicConsistency
from id_learning.errors import DatasetError

PERIOD_NS = 8_000_000


def sine(n: int, amplitude: float, omega: float, phase: float = 0.0):
    """q = A sin(w t + p) per joint, with its exact velocity and acceleration."""
    stamps = 10**18 + PERIOD_NS * np.arange(n, dtype=np.int64)
    angle = omega * PERIOD_NS * 1e-9 * np.arange(n)[:, None] + phase + np.arange(6)
    return (stamps, amplitude * np.sin(angle), amplitude * omega * np.cos(angle),
            -amplitude * omega**2 * np.sin(angle))  # fmt: skip


@pytest.fixture
def gate(mabi) -> KinematicConsistency:
    return KinematicConsistency(tuple(mabi.joints), mabi.limits, mabi.ipo_period_s)


@settings(max_examples=50, deadline=None)
@given(amplitude=st.floats(0.01, 0.5), omega=st.floats(0.1, 2.0), phase=st.floats(0, 6.3))
def test_any_motion_within_the_limits_passes_with_or_without_accelerations(
    mabi, amplitude, omega, phase
):
    gate = KinematicConsistency(tuple(mabi.joints), mabi.limits, mabi.ipo_period_s)
    stamps, q, v, a = sine(80, amplitude, omega, phase)
    assert gate.first_failure(stamps, q, v, a) is None
    assert gate.first_failure(stamps, q, v) is None


@pytest.mark.parametrize(
    ('name', 'quantity'),
    [('jump', 'position'), ('alternate', 'position'), ('still', 'position'),
     ('flip', 'velocity')],
)  # fmt: skip
def test_each_fault_fails_at_its_sample_naming_the_joint_and_quantity(gate, name, quantity):
    stamps, q, v, _ = sine(60, 0.2, 1.0)
    if name == 'jump':
        q[30:, 1] += 1.0
    elif name == 'alternate':
        q[30::2, 1] += 0.8
    elif name == 'still':  # still from sample 30 on, joint_2 saying 1.3 rad/s from the start
        q[30:] = q[30]
        v[:, 1] = 1.3
        q[:30, 1] = q[0, 1] + 1.3 * PERIOD_NS * 1e-9 * np.arange(30)
        q[30:, 1] = q[29, 1]
    else:
        v[30::2, 1] = 1.3
        v[31::2, 1] = -1.3
    found = gate.first_failure(stamps, q, v)
    assert found is not None
    sample, _, worst = found
    assert 30 <= sample <= 31 + gate.window
    assert (worst.joint, worst.quantity) == ('joint_2', quantity)
    with pytest.raises(DatasetError, match=rf'bag: sample {sample} .* joint_2'):
        gate.check(stamps, q, v, where='bag')


def test_the_pair_tolerance_is_the_closed_form_of_the_docstring(gate, mabi):
    dt = mabi.ipo_period_s
    accel = 2.0 * mabi.limits.acceleration[0]
    expected = accel * dt * (dt / 2 + 2 * dt) + 0.05 * mabi.limits.velocity[0] * dt
    stamps = np.array([0, PERIOD_NS])
    q = np.zeros((2, 6))
    q[1, 0] = 1.001 * expected  # just beyond, at rest
    assert gate.failing(stamps, q, np.zeros((2, 6)))[1]
    q[1, 0] = 0.999 * expected
    assert not gate.failing(stamps, q, np.zeros((2, 6))).any()


def test_nothing_is_compared_across_a_segment_start(gate):
    stamps, q, v, _ = sine(40, 0.2, 1.0)
    q[20:] += 1.0  # a new segment starts there
    assert gate.first_failure(stamps, q, v) is not None
    assert gate.first_failure(stamps, q, v, starts=(0, 20)) is None


@settings(max_examples=40, deadline=None)
@given(jump_at=st.integers(1, 50), size=st.floats(-1.0, 1.0), with_a=st.booleans())
def test_the_stream_gate_agrees_with_the_batch_gate_sample_by_sample(mabi, jump_at, size, with_a):
    gate = KinematicConsistency(tuple(mabi.joints), mabi.limits, mabi.ipo_period_s)
    stamps, q, v, a = sine(60, 0.3, 1.5)
    q[jump_at:, 2] += size
    a = a if with_a else None
    batch = gate.failing(stamps, q, v, a)
    stream = ConsistencyStream(gate)
    online = []
    for k in range(len(stamps)):
        a_k = None if a is None else a[k]
        online.append(stream.check(int(stamps[k]), q[k], v[k], a_k) is not None)
        stream.push(int(stamps[k]), q[k], v[k], a_k)
    np.testing.assert_array_equal(np.array(online), batch)


def test_a_robot_config_widens_the_gate_for_its_signals(mabi):
    from dataclasses import replace

    stamps, q, v, _ = sine(60, 0.5, 2.0)
    scaled = 3.0 * v  # a velocity signal three times its positions' (another gear ratio)
    assert KinematicConsistency.for_robot(mabi).first_failure(stamps, q, scaled) is not None
    wide = replace(mabi, consistency_scale=2.5)
    assert KinematicConsistency.for_robot(wide).first_failure(stamps, q, scaled) is None
