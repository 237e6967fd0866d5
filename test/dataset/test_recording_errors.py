"""Every bad input of the bag contract gets one clear error naming file, topic, joint or sample."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays
from support import sine_recording, write_contract_bag

from id_learning.dataset.recording import Recording, load_recording
from id_learning.errors import BagError, DatasetError


def broken(recording: Recording, **changes) -> Recording:
    fields = {
        key: getattr(recording, key)
        for key in (
            'joints',
            'stamps_ns',
            'position',
            'velocity',
            'current',
            'joint_torque',
            'source',
        )
    }
    return Recording(**{**fields, **changes})


def test_a_valid_bag_loads_in_the_robots_joint_order(tmp_path, mabi):
    recording = sine_recording(500)
    order = (2, 0, 1, 5, 4, 3)
    shuffled = broken(
        recording,
        joints=tuple(recording.joints[i] for i in order),
        position=recording.position[:, order],
        velocity=recording.velocity[:, order],
        current=recording.current[:, order],
    )
    loaded = load_recording(write_contract_bag(tmp_path / 'bag', shuffled), mabi)
    assert loaded.joints == mabi.joints
    np.testing.assert_array_equal(loaded.position, recording.position)
    np.testing.assert_array_equal(loaded.current, recording.current)


def test_a_missing_topic_is_named(tmp_path, mabi):
    path = write_contract_bag(tmp_path / 'bag', sine_recording(200), topics=('/joint_states',))
    with pytest.raises(BagError, match=r'missing topic.*/motor_currents'):
        load_recording(path, mabi)


def test_joint_names_that_differ_from_the_config_are_named(tmp_path, mabi):
    names = ('joint_1', 'joint_2', 'joint_3', 'joint_4', 'joint_5', 'wrist_roll')
    path = write_contract_bag(tmp_path / 'bag', sine_recording(200), names_js=names)
    with pytest.raises(
        DatasetError, match=r"/joint_states: joint names .*missing \['joint_6'\].*'wrist_roll'"
    ):
        load_recording(path, mabi)


def test_joint_names_that_differ_between_topics_are_named(tmp_path, mabi):
    names = ('joint_1', 'joint_2', 'joint_3', 'joint_4', 'joint_5', 'joint_7')
    path = write_contract_bag(tmp_path / 'bag', sine_recording(200), names_mc=names)
    with pytest.raises(DatasetError, match=r'/motor_currents: joint names'):
        load_recording(path, mabi)


@pytest.mark.parametrize('value', [np.nan, np.inf, -np.inf])
def test_non_finite_samples_are_refused_naming_sample_and_joint(tmp_path, mabi, value):
    recording = sine_recording(300)
    current = recording.current.copy()
    current[123, 4] = value
    path = write_contract_bag(tmp_path / 'bag', broken(recording, current=current))
    with pytest.raises(DatasetError, match=r'/motor_currents effort: sample 123 .* joint joint_5'):
        load_recording(path, mabi)


@pytest.mark.parametrize(
    ('field', 'value', 'message'),
    [
        ('position', 1e300, r'joint joint_2: position 1e\+300 rad is outside the limits'),
        ('velocity', 10.0, r'joint joint_2: velocity 10 rad/s exceeds 1.5 x its limit'),
    ],
)
def test_motion_beyond_the_robots_limits_is_refused_naming_sample_and_joint(
    tmp_path, mabi, field, value, message
):
    recording = sine_recording(300)
    values = getattr(recording, field).copy()
    values[77, 1] = value
    path = write_contract_bag(tmp_path / 'bag', broken(recording, **{field: values}))
    with pytest.raises(DatasetError, match=rf'/joint_states: sample 77 .*{message}'):
        load_recording(path, mabi)


def test_a_current_no_drive_of_the_robot_can_carry_is_refused(tmp_path, mabi):
    recording = sine_recording(300)
    current = recording.current.copy()
    current[88, 5] = -1e300
    path = write_contract_bag(tmp_path / 'bag', broken(recording, current=current))
    with pytest.raises(
        DatasetError, match=r'/motor_currents effort: sample 88 .*joint_6: current \[A\] -1e\+300'
    ):
        load_recording(path, mabi)


def test_stamps_that_go_backwards_are_refused(tmp_path, mabi):
    recording = sine_recording(300)
    stamps = recording.stamps_ns.copy()
    stamps[[100, 101]] = stamps[[101, 100]]
    path = write_contract_bag(tmp_path / 'bag', broken(recording, stamps_ns=stamps))
    with pytest.raises(
        DatasetError, match=r'/joint_states: time stamp goes backwards at sample 101'
    ):
        load_recording(path, mabi)


def test_repeated_stamps_are_refused(tmp_path, mabi):
    recording = sine_recording(300)
    stamps = recording.stamps_ns.copy()
    stamps[200] = stamps[199]
    path = write_contract_bag(tmp_path / 'bag', broken(recording, stamps_ns=stamps))
    with pytest.raises(DatasetError, match=r'time stamp repeats at sample 200'):
        load_recording(path, mabi)


def test_gaps_longer_than_a_few_ipo_periods_are_refused(tmp_path, mabi):
    recording = sine_recording(300)
    stamps = recording.stamps_ns.copy()
    stamps[150:] += 5 * 8_000_000
    path = write_contract_bag(tmp_path / 'bag', broken(recording, stamps_ns=stamps))
    with pytest.raises(DatasetError, match=r'gap of 48.0 ms before sample 150'):
        load_recording(path, mabi)
    assert load_recording(path, mabi, max_gap_periods=10).n_samples == 300


def test_current_stamps_that_do_not_match_the_joint_states_are_refused(tmp_path, mabi):
    recording = sine_recording(300)
    stamps_mc = recording.stamps_ns.copy()
    stamps_mc[77:] += 1_000_000  # 1 ms: more than 10 % of the 8 ms IPO period
    path = write_contract_bag(tmp_path / 'bag', recording, stamps_mc=stamps_mc)
    with pytest.raises(
        DatasetError, match=r'stamps differ by 1000.0 us at sample 77, more than the 800 us'
    ):
        load_recording(path, mabi)


@settings(max_examples=8, deadline=None, derandomize=True)
@given(offsets=arrays(np.int64, 300, elements=st.integers(-800_000, 800_000)))
def test_currents_stamped_apart_by_a_driver_pair_with_the_joint_states(
    tmp_path_factory, mabi, offsets
):
    """Within 10 % of the IPO period, each current belongs to the joint state of its index."""
    recording = sine_recording(300)
    stamps_mc = recording.stamps_ns + offsets
    path = write_contract_bag(
        tmp_path_factory.mktemp('bag') / 'bag', recording, stamps_mc=stamps_mc
    )

    loaded = load_recording(path, mabi)

    np.testing.assert_array_equal(loaded.stamps_ns, recording.stamps_ns)
    np.testing.assert_array_equal(loaded.current, recording.current)


def test_an_effort_of_nan_is_left_out_where_the_currents_are_the_label(tmp_path, mabi, caplog):
    recording = sine_recording(300)
    effort = np.full_like(recording.position, np.nan)  # a driver without torque sensors
    path = write_contract_bag(tmp_path / 'bag', broken(recording, joint_torque=effort))

    loaded = load_recording(path, mabi)

    assert loaded.joint_torque is None
    np.testing.assert_array_equal(loaded.current, recording.current)
    assert '1800 of 1800 values are not finite; left out' in caplog.text
    with pytest.raises(
        DatasetError, match=r'/joint_states effort: sample 0 .*joint_1.*not finite'
    ):
        load_recording(path, mabi, require_current=False)  # the effort is the label there


def test_a_truncated_mcap_file_is_refused_with_a_recovery_hint(tmp_path, mabi):
    path = write_contract_bag(tmp_path / 'bag', sine_recording(3000))
    mcap = next(path.glob('*.mcap'))
    data = mcap.read_bytes()
    mcap.write_bytes(data[: len(data) // 2])
    with pytest.raises(BagError, match=r'bag.*recover'):
        load_recording(path, mabi)


def test_a_corrupt_chunk_is_refused(tmp_path, mabi):
    path = write_contract_bag(tmp_path / 'bag', sine_recording(20000))
    mcap = next(path.glob('*.mcap'))
    data = bytearray(mcap.read_bytes())
    middle = len(data) // 2
    data[middle : middle + 256] = bytes(range(256))
    mcap.write_bytes(bytes(data))
    with pytest.raises(BagError, match=str(path)):
        load_recording(path, mabi)


def test_a_folder_without_metadata_is_refused(tmp_path, mabi):
    path = write_contract_bag(tmp_path / 'bag', sine_recording(100))
    (path / 'metadata.yaml').unlink()
    with pytest.raises(BagError, match=r'no metadata\.yaml'):
        load_recording(path, mabi)
    with pytest.raises(BagError, match='no such bag'):
        load_recording(tmp_path / 'nowhere', mabi)


def test_an_unpaired_tail_from_a_torn_recording_is_refused_or_trimmed_on_request(tmp_path, mabi):
    recording = sine_recording(300)
    path = write_contract_bag(tmp_path / 'bag', recording)
    short = broken(
        recording,
        stamps_ns=recording.stamps_ns[:298],
        position=recording.position[:298],
        velocity=recording.velocity[:298],
        current=recording.current[:298],
    )
    # Joint states for all 300 samples, currents for the first 298 only.
    from id_learning.bag import JOINT_STATE, BagWriter, encode_joint_state

    torn = tmp_path / 'torn'
    with BagWriter(torn) as writer:
        writer.add_topic('/joint_states', JOINT_STATE)
        writer.add_topic('/motor_currents', JOINT_STATE)
        for k, stamp in enumerate(recording.stamps_ns.tolist()):
            writer.write(
                '/joint_states',
                stamp,
                encode_joint_state(
                    stamp, recording.joints, recording.position[k], recording.velocity[k], []
                ),
            )
            if k < len(short.stamps_ns):
                writer.write(
                    '/motor_currents',
                    stamp,
                    encode_joint_state(stamp, recording.joints, [], [], recording.current[k]),
                )
    with pytest.raises(
        DatasetError, match=r'last 2 message\(s\) of /joint_states have no partner'
    ):
        load_recording(torn, mabi)
    trimmed = load_recording(torn, mabi, trim_unpaired_tail=True)
    assert trimmed.n_samples == 298
    np.testing.assert_array_equal(trimmed.current, recording.current[:298])
    assert load_recording(path, mabi).n_samples == 300


@pytest.mark.parametrize(
    ('change', 'message'),
    [
        ('jump', r'sample 250 .* position of joint_2 changed by 0\.99\d* rad in 8 ms'),
        ('still', r'sample 25\d .* joint_4 changed by'),
        ('flip', r'velocity of joint_6 changed by'),
    ],
)  # fmt: skip
def test_a_recording_whose_motion_contradicts_itself_is_refused_naming_it(
    tmp_path, mabi, change, message
):
    recording = sine_recording(500)
    position, velocity = recording.position.copy(), recording.velocity.copy()
    if change == 'jump':
        position[250:, 1] += 1.0
    elif change == 'still':
        position[250:, 3] = position[250, 3]
        velocity[250:, 3] = 1.3
    else:
        velocity[250::2, 5] += 1.3
    bad = broken(recording, position=position, velocity=velocity)
    with pytest.raises(DatasetError, match=message):
        load_recording(write_contract_bag(tmp_path / 'bag', bad), mabi)
