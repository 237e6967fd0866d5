"""Bags written by the package read back bit-exact through rosbags, with valid rosbag2 metadata."""

from __future__ import annotations

import numpy as np
import yaml
from rosbags.highlevel import AnyReader
from support import sine_recording

from id_learning.bag import JOINT_STATE, BagWriter, bag_info, encode_joint_state, iter_raw
from id_learning.dataset.recording import Recording, load_recording, write_recording


def test_recording_round_trips_bit_exact_through_a_bag(tmp_path, mabi):
    rng = np.random.default_rng(3)
    base = sine_recording(2000)
    noisy = Recording(
        base.joints,
        base.stamps_ns,
        base.position + rng.standard_normal(base.position.shape) * 1e-5,  # an encoder's noise
        base.velocity,
        base.current,
        joint_torque=rng.standard_normal(base.position.shape) * 100,
    )
    path = write_recording(noisy, tmp_path / 'bag')
    loaded = load_recording(path, mabi)
    for key in ('stamps_ns', 'position', 'velocity', 'current', 'joint_torque'):
        np.testing.assert_array_equal(getattr(loaded, key), getattr(noisy, key))


def test_serialized_bytes_and_log_times_are_stored_unchanged(tmp_path):
    names = ('a', 'b')
    written = []
    with BagWriter(tmp_path / 'raw', chunk_bytes=2048) as writer:
        writer.add_topic('/joint_states', JOINT_STATE)
        for k in range(500):
            data = encode_joint_state(1_000 + k, names, [k, -k], [0.5 * k, 1.0], [])
            writer.write('/joint_states', 10_000 + 7 * k, data)
            written.append((10_000 + 7 * k, data))
    read = [(log, data) for _, log, data in iter_raw(tmp_path / 'raw', ['/joint_states'])]
    assert read == written


def test_bags_are_readable_by_rosbags_with_rosbag2_metadata(tmp_path, mabi):
    recording = sine_recording(800)
    path = write_recording(recording, tmp_path / 'bag', mabi.topics)
    metadata = yaml.safe_load((path / 'metadata.yaml').read_text())['rosbag2_bagfile_information']
    assert metadata['storage_identifier'] == 'mcap'
    assert metadata['version'] == 9
    assert metadata['message_count'] == 1600
    counts = {
        t['topic_metadata']['name']: t['message_count']
        for t in metadata['topics_with_message_count']
    }
    assert counts == {'/joint_states': 800, '/motor_currents': 800}
    with AnyReader([path]) as reader:
        assert {c.topic: c.msgtype for c in reader.connections} == {
            '/joint_states': JOINT_STATE,
            '/motor_currents': JOINT_STATE,
        }
        first = next(reader.messages())
        msg = reader.deserialize(first[2], first[0].msgtype)
        assert list(msg.name) == list(recording.joints)
    info = bag_info(path)
    assert info.duration_ns == int(recording.stamps_ns[-1] - recording.stamps_ns[0])


def test_splitting_by_duration_writes_several_files_that_read_back_whole(tmp_path):
    with BagWriter(tmp_path / 'split', split_duration_ns=1_000_000_000) as writer:
        writer.add_topic('/joint_states', JOINT_STATE)
        for k in range(500):  # 4 s at 8 ms
            stamp = k * 8_000_000
            writer.write('/joint_states', stamp, encode_joint_state(stamp, ('j',), [k], [0.0], []))
    info = bag_info(tmp_path / 'split')
    assert len(info.files) == 4
    metadata = yaml.safe_load((tmp_path / 'split/metadata.yaml').read_text())[
        'rosbag2_bagfile_information'
    ]
    assert sum(f['message_count'] for f in metadata['files']) == 500
    logs = [log for _, log, _ in iter_raw(tmp_path / 'split', ['/joint_states'])]
    assert logs == [k * 8_000_000 for k in range(500)]


def test_flushed_messages_survive_an_unfinished_writer(tmp_path):
    from id_learning.bag.recover import recover_bag

    writer = BagWriter(tmp_path / 'live', chunk_bytes=1 << 24).open()
    writer.add_topic('/joint_states', JOINT_STATE)
    for k in range(50):
        writer.write('/joint_states', k, encode_joint_state(k, ('j',), [k], [0.0], []))
    writer.flush()
    writer.write('/joint_states', 50, encode_joint_state(50, ('j',), [50], [0.0], []))
    # The process "dies" here: no close(), no metadata.yaml, the last message still buffered.
    recover_bag(tmp_path / 'live', tmp_path / 'recovered')
    logs = [log for _, log, _ in iter_raw(tmp_path / 'recovered', ['/joint_states'])]
    assert logs == list(range(50))
