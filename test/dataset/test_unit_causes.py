"""A refused value names its real cause: a unit, the robot config's limit or setting, not the bag.

Judged on the worst samples and on what else could explain them (the URDF's limits, the
consistency tolerance derived from the limits, the time column's unit).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from support import sine_recording

from id_learning.dataset.import_mapping import ColumnSpec, ImportMapping, JointColumns
from id_learning.dataset.importer import import_log
from id_learning.dataset.inspect import inspect_bag
from id_learning.dataset.plausibility import (
    RATE_DEGREES_FACTOR,
    VELOCITY_FACTOR,
    check_motion,
    rate_in_degrees,
    urdf_position_limits,
)
from id_learning.dataset.recording import load_recording, write_recording
from id_learning.errors import DatasetError

N = 500


def test_velocities_in_deg_per_s_are_named_as_a_unit_even_when_the_first_is_just_beyond(
    tmp_path, mabi
):
    recording = sine_recording(N)
    velocity = recording.velocity.copy()
    # Joint 1 ramps up to 1.6 rad/s, logged in deg/s: its first sample beyond the bound lies
    # just beyond (a limit question taken alone), its worst 36 x beyond.
    velocity[:, 0] = np.degrees(np.linspace(0.0, 1.6, N))
    with pytest.raises(DatasetError) as caught:
        check_motion(recording.joints, recording.stamps_ns, recording.position, velocity,
                     limits=mabi.limits, where='bag: /joint_states')  # fmt: skip
    text = str(caught.value)
    assert 'joint joint_1: velocity' in text
    assert '% of the limit; the largest |velocity| of this joint, 91.6732 rad/s, lies' in text
    assert 'limit question' not in text
    assert 'the velocities are in deg/s, they must be in rad/s' in text
    # Every joint in deg/s: the loader says the same and counts them.
    everywhere = replace(recording, velocity=np.degrees(recording.velocity))
    with pytest.raises(DatasetError) as caught:
        load_recording(write_recording(everywhere, tmp_path / 'bag'), mabi)
    text = str(caught.value)
    assert 'the velocities are in deg/s, they must be in rad/s' in text
    assert '6 joints exceed (joint_1, joint_2, joint_3, joint_4, joint_5, joint_6)' in text


@given(peak_share=st.floats(1.01, 1.06), seed=st.integers(0, 100))
def test_a_velocity_just_beyond_its_bound_stays_a_limit_question(mabi, peak_share, seed):
    recording = sine_recording(200)
    velocity = recording.velocity.copy()
    bound = VELOCITY_FACTOR * mabi.limits.velocity[2]
    velocity[:, 2] = peak_share * bound * np.sin(np.linspace(0, 3, 200) + seed)
    assert not rate_in_degrees(velocity[:, 2], bound)
    with pytest.raises(DatasetError) as caught:
        check_motion(recording.joints, recording.stamps_ns, recording.position, velocity,
                     limits=mabi.limits, where='bag')  # fmt: skip
    assert 'a limit question rather than a unit one' in str(caught.value)
    assert 'deg/s' not in str(caught.value)


@given(peak=st.floats(0.01, 3.0), seed=st.integers(0, 100))
def test_rates_read_as_degrees_only_when_degrees_fit_a_real_motion(peak, seed):
    bound = 2.0
    rng = np.random.default_rng(seed)
    in_rad = peak * bound * np.sin(np.linspace(0, 10, 300) + rng.uniform(0, 6))
    top = float(np.abs(in_rad).max())
    fits = RATE_DEGREES_FACTOR * bound < np.degrees(top) and top <= bound
    assert rate_in_degrees(np.degrees(in_rad), bound) == fits
    assert not rate_in_degrees(in_rad, bound)  # up to 3 x the bound in rad/s: never degrees
    # Columns share a unit: a slow joint in deg/s is judged with a fast one.
    slow = np.degrees(0.05 * bound * np.sin(np.linspace(0, 10, 300)))
    fast = np.degrees(0.8 * bound * np.cos(np.linspace(0, 10, 300)))
    assert not rate_in_degrees(slow, bound)
    assert rate_in_degrees(np.column_stack([slow, fast]), np.array([bound, bound]))


def test_a_narrow_config_limit_is_named_against_the_urdf_not_as_degrees(tmp_path, mabi):
    recording = sine_recording(N)  # 0.5 rad sines: inside the URDF's limits
    narrow = replace(
        mabi,
        limits=replace(
            mabi.limits,
            position_lower=np.full(6, -0.1),
            position_upper=np.full(6, 0.1),
        ),
    )
    bag = write_recording(recording, tmp_path / 'bag')
    with pytest.raises(DatasetError) as caught:
        load_recording(bag, narrow)
    text = str(caught.value)
    joint = text.split('joint joint_')[1][0]
    lower, upper = urdf_position_limits(mabi.urdf_path, f'joint_{joint}')
    assert f"every value of this joint fits the URDF's limits [{lower:.4g}, {upper:.4g}] rad" in (
        text
    )
    assert "the robot config's limits are narrower than the URDF's" in text
    assert f'limits.position_lower/position_upper of joint_{joint} in the robot config' in text
    assert 'degrees' not in text
    # Positions that fit neither are still named as degrees.
    degrees = replace(recording, position=np.degrees(recording.position))
    with pytest.raises(DatasetError, match='the log is in degrees'):
        load_recording(write_recording(degrees, tmp_path / 'deg'), mabi)


def test_urdf_limits_are_read_by_joint_name(mabi):
    lower, upper = urdf_position_limits(mabi.urdf_path, 'joint_2')
    assert lower <= mabi.limits.position_lower[1] < mabi.limits.position_upper[1] <= upper
    assert urdf_position_limits(mabi.urdf_path, 'no_such_joint') is None


def test_a_consistency_scale_at_its_minimum_is_blamed_not_the_bag(tmp_path, mabi):
    bag = write_recording(sine_recording(N), tmp_path / 'bag')
    load_recording(bag, mabi)  # clean at the derived tolerance
    with pytest.raises(DatasetError) as caught:
        load_recording(bag, replace(mabi, consistency_scale=0.001))
    text = str(caught.value)
    assert text.startswith(
        f"{bag}: /joint_states: the robot config's consistency_scale 0.001 makes every tolerance "
        'of the kinematic consistency check 1000 x tighter'
    )
    assert 'at consistency_scale 1 every sample passes: raise it to 1' in text
    assert 'accelerations say' not in text  # the bag carries none
    assert 'the samples carry no accelerations' in text
    (problem,) = inspect_bag(bag, replace(mabi, consistency_scale=0.001)).problems
    assert "only the robot config's consistency_scale 0.001 makes them fail" in problem


def test_a_time_column_in_ms_declared_as_s_is_named_as_its_unit(tmp_path, mabi):
    recording = sine_recording(300)
    t_ms = np.arange(300) * 8.0
    rows = [['t', *(f'{k}{j}' for k in 'qvi' for j in range(1, 7))]]
    arrays = np.column_stack([t_ms, recording.position, recording.velocity, recording.current])
    rows += [[repr(float(x)) for x in row] for row in arrays]
    log = tmp_path / 'log.csv'
    log.write_text('\n'.join(','.join(row) for row in rows) + '\n', encoding='utf-8')
    joints = tuple(
        JointColumns(name, ColumnSpec(f'q{j}', 'rad'), ColumnSpec(f'v{j}', 'rad/s'),
                     current=ColumnSpec(f'i{j}', 'A'))
        for j, name in enumerate(mabi.joints, start=1)
    )  # fmt: skip
    for unit in ('s', 'us'):
        mapping = ImportMapping(joints=joints, time=ColumnSpec('t', unit))  # type: ignore[arg-type]
        with pytest.raises(DatasetError) as caught:
            import_log(log, mapping, tmp_path / f'out_{unit}', robot=mabi)
        text = str(caught.value)
        assert f"the time column 't', declared in {unit}, steps" in text
        assert 'read in ms it steps 8 ms, the IPO period: the column is in ms' in text
        assert 'set time.unit: ms in the mapping' in text
        assert 'resample: {method: interpolate}' not in text
    mapping = ImportMapping(joints=joints, time=ColumnSpec('t', 'ms'))  # type: ignore[arg-type]
    import_log(log, mapping, tmp_path / 'out_ms', robot=mabi)
