"""The whole-recording scale check: velocities a multiple of the positions' rate are refused.

A factor between the velocities and the positions (deg/s for rad/s, a x2 of a gear-side
confusion, a reversed sign) stays inside the local tolerances while the motion is slow, so the
gate also compares the velocity integral with the position change over the whole recording.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from id_learning.dataset.consistency import SCALE_LIMIT, KinematicConsistency
from id_learning.errors import DatasetError

FACTORS = [2.0, 0.5, 3.0, 1 / 3, math.pi / 180, 180 / math.pi, -1.0, -2.0, 1.6, 0.6]


def motion(mabi, seed: int, seconds: float, noisy: bool):
    """Slow multi-sine motion of every joint with realistic noise, quantisation and lag."""
    rng = np.random.default_rng(seed)
    period = mabi.ipo_period_s
    n, joints = round(seconds / period), len(mabi.joints)
    t = period * np.arange(n)[:, None]
    amplitude = rng.uniform(0.05, 0.4, (3, joints))
    omega = rng.uniform(0.3, 2.0, (3, joints))
    phase = rng.uniform(0, 2 * np.pi, (3, joints))
    q = sum(amplitude[k] * np.sin(omega[k] * t + phase[k]) for k in range(3))
    v = sum(amplitude[k] * omega[k] * np.cos(omega[k] * t + phase[k]) for k in range(3))
    if noisy:
        q = np.round(q / 2e-5) * 2e-5  # an 18-bit encoder
        lag = int(rng.integers(0, 3))  # a velocity filter's lag [periods]
        v = np.concatenate([np.repeat(v[:1], lag, axis=0), v[: n - lag]])
        v = v + rng.normal(0.0, 0.005, v.shape)
        v = np.round(v / 1e-4) * 1e-4
    stamps = 10**18 + np.round(t[:, 0] * 1e9).astype(np.int64)
    return stamps, np.asarray(q), np.asarray(v)


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 2**31), seconds=st.floats(4.0, 12.0), noisy=st.booleans())
def test_a_consistent_recording_passes(mabi, seed: int, seconds: float, noisy: bool) -> None:
    gate = KinematicConsistency.for_robot(mabi)
    stamps, q, v = motion(mabi, seed, seconds, noisy)
    assert gate.scale_errors(stamps, q, v) == []
    gate.check(stamps, q, v, where='bag: /joint_states')


@settings(max_examples=40, deadline=None)
@given(
    seed=st.integers(0, 2**31),
    factor=st.sampled_from(FACTORS),
    joint=st.integers(0, 5),
    only_one=st.booleans(),
)
def test_a_scaled_velocity_is_refused_naming_topic_joint_and_factor(
    mabi, seed: int, factor: float, joint: int, only_one: bool
) -> None:
    gate = KinematicConsistency.for_robot(mabi)
    stamps, q, v = motion(mabi, seed, 8.0, True)
    if only_one:
        v[:, joint] *= factor
    else:
        v *= factor
    found = {name: f for name, f, _ in gate.scale_errors(stamps, q, v)}
    name = mabi.joints[joint]
    assert name in found
    assert found[name] == pytest.approx(factor, rel=0.05)
    if only_one:
        assert set(found) == {name}
    with pytest.raises(DatasetError) as caught:
        gate.check(stamps, q, v, where='bag: /joint_states')
    message = str(caught.value)
    assert message.startswith('bag: /joint_states: ')
    # the per-sample gate may see a large factor first, naming its worst joint
    assert name in message if only_one else any(j in message for j in mabi.joints)


def test_the_factor_is_named_and_segments_are_not_bridged(mabi) -> None:
    gate = KinematicConsistency.for_robot(mabi)
    stamps, q, v = motion(mabi, 7, 8.0, True)
    half = len(stamps) // 2
    q[half:] += 0.5  # a seam: the second segment starts elsewhere
    gate.check(stamps, q, v, where='bag: /joint_states', starts=(0, half))
    v[:, 2] *= 2.0
    with pytest.raises(DatasetError, match=r'joint_3: its velocities integrate to 2 x'):
        gate.check(stamps, q, v, where='bag: /joint_states', starts=(0, half))


def test_a_joint_that_hardly_moves_is_not_judged(mabi) -> None:
    gate = KinematicConsistency.for_robot(mabi)
    stamps, q, v = motion(mabi, 3, 6.0, False)
    q[:, 0], v[:, 0] = 1e-4 * q[:, 0], 2e-4 * v[:, 0]  # x2, but 1e-4 of the travel
    assert mabi.joints[0] not in [name for name, _, _ in gate.scale_errors(stamps, q, v)]
    assert SCALE_LIMIT == 1.5  # the factors above (1.6, 0.6) are outside it either way


def test_inspect_names_a_scaled_velocity_the_loader_refuses(mabi, tmp_path) -> None:
    from id_learning.dataset.inspect import inspect_bag
    from id_learning.dataset.recording import Recording, load_recording, write_recording

    stamps, q, v = motion(mabi, 7, 8.0, True)
    current = np.sin(q + 0.3)  # any signed, moving label
    stamps = stamps - stamps[0] + 1_767_225_600_000_000_000

    def bag(velocity, name):
        recording = Recording(mabi.joints, stamps, q, velocity, current, None, source=name)
        return write_recording(recording, tmp_path / name)

    scaled = v.copy()
    scaled[:, 2] *= 2.0
    problems = inspect_bag(bag(scaled, 'x2'), robot=mabi).problems
    assert len(problems) == 1, problems
    assert problems[0].startswith('/joint_states: the velocities contradict the positions')
    assert 'joint_3: its velocities integrate to 2 x' in problems[0]
    with pytest.raises(DatasetError, match=r'joint_3: its velocities integrate to 2 x'):
        load_recording(tmp_path / 'x2', mabi)
    assert inspect_bag(bag(v, 'clean'), robot=mabi).problems == ()
