"""The plausibility gate names the first impossible sample: where, sample, stamp, joint, value."""

from __future__ import annotations

import numpy as np
import pytest

from id_learning.dataset.plausibility import POSITION_MARGIN_RAD, VELOCITY_FACTOR, check_motion
from id_learning.errors import DatasetError

N = 50
T0_NS = 1_767_225_600_000_000_000


@pytest.fixture
def motion(mabi):
    """Slow sines well inside the MABI limits, in its joint order."""
    t = np.arange(N) * 0.008
    middle = 0.5 * (mabi.limits.position_lower + mabi.limits.position_upper)
    q = middle + 0.2 * np.sin(t[:, None] + np.arange(6))
    v = 0.2 * np.cos(t[:, None] + np.arange(6))
    stamps = T0_NS + np.arange(N, dtype=np.int64) * 8_000_000
    return mabi.joints, stamps, q, v


def check(mabi, joints, stamps, q, v):
    check_motion(joints, stamps, q, v, limits=mabi.limits, where='run.mcap: /joint_states')


def test_motion_inside_the_limits_passes(mabi, motion):
    check(mabi, *motion)
    joints, stamps, q, _ = motion
    check_motion(joints, stamps, q, None, limits=None, where='no limits')


def test_a_non_finite_value_is_named_with_its_sample_stamp_and_joint(mabi, motion):
    joints, stamps, q, v = motion
    v = v.copy()
    v[17, 4] = np.inf
    with pytest.raises(DatasetError) as caught:
        check(mabi, joints, stamps, q, v)
    text = str(caught.value)
    assert text.startswith('run.mcap: /joint_states: velocity: sample 17')
    assert f'stamp {stamps[17]} ns' in text
    assert 'joint joint_5' in text
    assert 'inf is not finite' in text


def test_stamps_that_do_not_increase_are_refused(mabi, motion):
    joints, stamps, q, v = motion
    stamps = stamps.copy()
    stamps[30] = stamps[29]
    with pytest.raises(DatasetError, match='stamps must increase: sample 30'):
        check(mabi, joints, stamps, q, v)


def test_a_position_beyond_the_limits_and_margin_is_named_with_the_limits(mabi, motion):
    joints, stamps, q, v = motion
    q = q.copy()
    upper = mabi.limits.position_upper[1]
    q[40, 1] = upper + POSITION_MARGIN_RAD * 0.5  # inside the margin: accepted
    check(mabi, joints, stamps, q, v)
    q[41, 1] = upper + POSITION_MARGIN_RAD * 2.0
    with pytest.raises(DatasetError, match=r'sample 41 .*joint joint_2: position .* outside'):
        check(mabi, joints, stamps, q, v)


def test_positions_in_degrees_are_named_as_degrees(mabi, motion):
    joints, stamps, q, v = motion
    q = q.copy()
    q[:, 0] = np.degrees(np.linspace(-1.5, 1.5, N))  # joint_1 logged in degrees
    with pytest.raises(DatasetError, match=r'joint joint_1.*the log is in degrees'):
        check(mabi, joints, stamps, q, v)
    q[:, 0] = 10.0  # far outside, but not degrees of a valid motion
    with pytest.raises(DatasetError) as caught:
        check(mabi, joints, stamps, q, v)
    assert 'degrees' not in str(caught.value)


def test_a_position_just_past_a_wide_joints_limit_is_a_limit_question_not_degrees(mabi, motion):
    joints, stamps, q, v = motion
    q = q.copy()
    lower, upper = mabi.limits.position_lower[3], mabi.limits.position_upper[3]  # +-5.1 rad
    q[:, 3] = np.linspace(lower + 0.1, upper + 0.02 * (upper - lower), N)  # spans over 2 pi
    assert np.ptp(q[:, 3]) > 2 * np.pi
    with pytest.raises(DatasetError) as caught:
        check(mabi, joints, stamps, q, v)
    text = str(caught.value)
    assert 'joint joint_4: position' in text
    assert "beyond the upper limit 5.1 rad, 2 % of the joint's range" in text
    assert 'limit question' in text
    assert 'degrees' not in text


def test_a_velocity_beyond_the_stated_factor_of_its_limit_is_refused(mabi, motion):
    joints, stamps, q, v = motion
    v = v.copy()
    limit = mabi.limits.velocity[0]
    v[5, 0] = 0.99 * VELOCITY_FACTOR * limit
    check(mabi, joints, stamps, q, v)
    v[6, 0] = 6.0 * limit
    with pytest.raises(DatasetError, match=r'sample 6 .*joint joint_1: velocity .* exceeds 1.5 x'):
        check(mabi, joints, stamps, q, v)


def test_arrays_that_do_not_match_the_joints_are_named(mabi, motion):
    joints, stamps, q, _ = motion
    with pytest.raises(DatasetError, match=r'velocity has shape \(50, 0\)'):
        check(mabi, joints, stamps, q, np.zeros((N, 0)))
