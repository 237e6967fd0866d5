"""Reader refusals: storage unlike metadata.yaml, torn or stray files, mixed types, copies."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest
import yaml
from rosbags.rosbag2 import StoragePlugin, Writer
from support import sine_recording

from id_learning.bag import (
    JOINT_STATE,
    BagWriter,
    bag_info,
    iter_raw,
    iter_typed,
    read_joint_states,
)
from id_learning.bag.distinct import check_distinct
from id_learning.bag.messages import typestore
from id_learning.dataset.recording import write_recording
from id_learning.errors import BagError, ConfigError

TOPICS = ['/joint_states', '/motor_currents']


@pytest.fixture(scope='module')
def bag(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path: Path = write_recording(sine_recording(60), tmp_path_factory.mktemp('errors') / 'bag')
    return path


def _edited(bag: Path, where: Path, edit: object) -> Path:
    """A copy of ``bag`` whose metadata.yaml ``edit`` (a callable on its info mapping) changed."""
    copy = Path(shutil.copytree(bag, where))
    meta = copy / 'metadata.yaml'
    data = yaml.safe_load(meta.read_text(encoding='utf-8'))
    edit(data['rosbag2_bagfile_information'])  # type: ignore[operator]
    meta.write_text(yaml.safe_dump(data), encoding='utf-8')
    return copy


def test_a_claimed_compression_the_files_lack_is_a_bag_error_naming_file_and_claim(
    bag: Path, tmp_path: Path
) -> None:
    def claim(info: dict[str, object]) -> None:
        info.update(compression_format='zstd', compression_mode='FILE')

    copy = _edited(bag, tmp_path / 'compressed', claim)
    with pytest.raises(BagError, match=r'compressed: .*\.mcap.*compression_format zstd'):
        bag_info(copy)


def test_a_metadata_type_other_than_the_storage_type_is_refused_naming_the_topic(
    bag: Path, tmp_path: Path
) -> None:
    def retype(info: dict[str, list[dict[str, dict[str, str]]]]) -> None:
        info['topics_with_message_count'][1]['topic_metadata']['type'] = (
            'std_msgs/msg/Float64MultiArray'
        )

    copy = _edited(bag, tmp_path / 'retyped', retype)
    with pytest.raises(BagError, match=r'/motor_currents has type std_msgs/msg/Float64Multi'):
        list(iter_raw(copy, TOPICS))
    assert len(list(iter_raw(bag, TOPICS))) == 120  # the original reads in full


def test_a_copy_with_an_edited_metadata_yaml_is_still_a_duplicate(
    bag: Path, tmp_path: Path
) -> None:
    def note(info: dict[str, object]) -> None:
        info['custom_data'] = {'writer': 'someone else', 'note': 'edited'}

    copy = _edited(bag, tmp_path / 'copy', note)
    with pytest.raises(ConfigError, match=r'--bag: .*copy holds the same data as .*bag'):
        check_distinct([bag, copy], '--bag')


def test_distinct_recordings_pass(bag: Path, tmp_path: Path) -> None:
    other = write_recording(sine_recording(61), tmp_path / 'other')
    assert check_distinct([bag, other], '--bag') == [bag, other]


def test_a_copy_stored_in_other_chunks_is_still_a_duplicate(bag: Path, tmp_path: Path) -> None:
    """Re-chunked (re-compressed) storage: other bytes, the same messages."""
    copy = tmp_path / 'rechunked'
    with BagWriter(copy, chunk_bytes=512) as writer:
        for topic in TOPICS:
            writer.add_topic(topic, JOINT_STATE)
        for topic, log_ns, data in iter_raw(bag, TOPICS):
            writer.write(topic, log_ns, data)
    assert _storage_bytes(copy) != _storage_bytes(bag)
    with pytest.raises(ConfigError, match=r'rechunked holds the same data .*stored differently'):
        check_distinct([bag, copy], '--bag')


def test_metadata_counts_the_files_do_not_hold_are_warned_naming_topic(
    bag: Path, tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    def miscount(info: dict[str, list[dict[str, object]]]) -> None:
        info['topics_with_message_count'][0]['message_count'] = 7

    copy = _edited(bag, tmp_path / 'miscounted', miscount)
    assert len(list(iter_raw(copy, TOPICS))) == 120  # the messages held are the data
    assert 'metadata.yaml message counts disagree' in caplog.text
    assert '/joint_states 7 stated, 60 held' in caplog.text


def _storage_bytes(path: Path) -> bytes:
    return b''.join(f.read_bytes() for f in sorted(path.glob('*.mcap')))


def test_a_storage_file_holding_only_its_magic_is_a_torn_bag_naming_the_file(
    bag: Path, tmp_path: Path
) -> None:
    """What a recorder killed right after opening its file leaves: 8 bytes, no records."""
    copy = Path(shutil.copytree(bag, tmp_path / 'magic'))
    (storage,) = copy.glob('*.mcap')
    storage.write_bytes(storage.read_bytes()[:8])
    for read in (bag_info, lambda path: list(iter_raw(path, TOPICS))):
        with pytest.raises(
            BagError, match=rf'magic: .*{storage.name} is torn or corrupt.*recover'
        ):
            read(copy)


@pytest.mark.parametrize('entry', ['../bag/bag_0.mcap', '/elsewhere/bag_0.mcap'])
def test_storage_files_listed_outside_the_bag_folder_are_refused_naming_the_entry(
    bag: Path, tmp_path: Path, entry: str
) -> None:
    def point_away(info: dict[str, object]) -> None:
        info['relative_file_paths'] = [entry]

    copy = _edited(bag, tmp_path / 'away', point_away)
    for file in copy.glob('*.mcap'):
        file.unlink()  # so nothing of the bag's own is there to read instead
    why = 'outside the bag folder' if entry.startswith('..') else 'an absolute path'
    for read in (bag_info, lambda path: list(iter_raw(path, TOPICS))):
        with pytest.raises(BagError, match=rf"away: .*relative_file_paths lists '{entry}', {why}"):
            read(copy)


def test_a_binary_metadata_yaml_is_named_as_not_text(bag: Path, tmp_path: Path) -> None:
    copy = Path(shutil.copytree(bag, tmp_path / 'binary'))
    (copy / 'metadata.yaml').write_bytes(bytes(range(128, 256)) * 2)
    with pytest.raises(BagError, match=r'binary/metadata\.yaml: not a text YAML file'):
        bag_info(copy)


def _with_a_string_on_joint_states(bag: Path, out: Path) -> Path:
    """``bag`` rewritten with one std_msgs/String message more on /joint_states."""
    store = typestore()
    with Writer(out, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        conns = {
            topic: writer.add_connection(topic, JOINT_STATE, typestore=store) for topic in TOPICS
        }
        string = writer.add_connection('/joint_states', 'std_msgs/msg/String', typestore=store)
        for topic, log_ns, data in iter_raw(bag, TOPICS):
            writer.write(conns[topic], log_ns, data)
        message = store.types['std_msgs/msg/String'](data='hello')
        writer.write(string, log_ns + 1, bytes(store.serialize_cdr(message, string.msgtype)))
    return out


def test_a_topic_of_two_types_is_refused_naming_both_with_counts(
    bag: Path, tmp_path: Path
) -> None:
    mixed = _with_a_string_on_joint_states(bag, tmp_path / 'mixed')
    both = (
        r'mixed: topic /joint_states holds 2 message types: sensor_msgs/msg/JointState '
        r'\(60 messages\), std_msgs/msg/String \(1 message\)'
    )
    with pytest.raises(BagError, match=both):
        list(iter_raw(mixed, TOPICS))
    with pytest.raises(BagError, match=both):
        read_joint_states(mixed, '/joint_states')
    assert len(list(iter_raw(mixed, ['/motor_currents']))) == 60  # the other topic reads
    kinds = [msgtype for topic, msgtype, _, _ in iter_typed(mixed, TOPICS) if topic == TOPICS[0]]
    assert sorted(set(kinds)) == [JOINT_STATE, 'std_msgs/msg/String']
    assert len(kinds) == 61


def test_the_motor_currents_are_read_from_effort_alone(tmp_path, mabi):
    """Position and velocity of /motor_currents are documented as ignored: a converter that
    fills them with anything (three values for six joints) does not stop a recording."""
    import numpy as np

    from id_learning.bag import JOINT_STATE, BagWriter, encode_joint_state, read_joint_states
    from id_learning.dataset.recording import load_recording
    from id_learning.errors import DatasetError

    recording = sine_recording(200)
    path = tmp_path / 'bag'
    with BagWriter(path) as writer:
        for topic in ('/joint_states', '/motor_currents'):
            writer.add_topic(topic, JOINT_STATE)
        for k, stamp in enumerate(recording.stamps_ns.tolist()):
            log_ns = int(recording.stamps_ns[0]) + k * 8_000_000
            joints, position, velocity = (
                recording.joints,
                recording.position[k],
                recording.velocity[k],
            )
            state = encode_joint_state(stamp, joints, position, velocity, np.empty(0))
            odd = encode_joint_state(stamp, joints, np.zeros(2), np.ones(3), recording.current[k])
            writer.write('/joint_states', log_ns, state)
            writer.write('/motor_currents', log_ns, odd)
    with pytest.raises(DatasetError, match='position has 2 values for 6 joints'):
        read_joint_states(path, '/motor_currents')
    currents = read_joint_states(path, '/motor_currents', fields=('effort',))
    assert currents.position is None
    assert currents.velocity is None
    np.testing.assert_allclose(currents.effort, recording.current)
    loaded = load_recording(path, mabi)
    np.testing.assert_allclose(loaded.current, recording.current)


def test_a_bag_still_being_written_is_named_so_not_torn(tmp_path: Path) -> None:
    import os

    from id_learning.bag import encode_joint_state

    path = tmp_path / 'live'
    with BagWriter(path) as writer:
        writer.add_topic('/joint_states', JOINT_STATE)
        writer.write('/joint_states', 10**9, encode_joint_state(10**9, ('a',), [0.0], [0.0], []))
        with pytest.raises(BagError, match=rf'being written by process {os.getpid()} .*lock'):
            bag_info(path)
    assert bag_info(path).topic('/joint_states').count == 1


def test_a_file_of_a_bag_given_for_the_bag_names_its_folder(bag: Path, tmp_path: Path) -> None:
    # The probe's Q03/Q04: `inspect bag/x.mcap` (as `ros2 bag info` takes it) said only 'a file'.
    for inside in [*bag.glob('*.mcap'), bag / 'metadata.yaml']:
        with pytest.raises(BagError) as err:
            bag_info(inside)
        assert str(err.value) == (
            f'{inside}: expected a rosbag2 folder (with metadata.yaml), got a file; it is a file '
            f'of the bag {bag}: give that folder'
        )
    lone = tmp_path / 'lone.mcap'
    lone.write_bytes(next(bag.glob('*.mcap')).read_bytes())
    with pytest.raises(BagError, match=r'got a file$'):  # no folder to name
        bag_info(lone)


def test_a_bag_still_being_written_is_named_where_it_is_written(tmp_path: Path) -> None:
    # Probe 15 (A95): inspect on a bag a running simulate writes said only 'no such bag'.
    from id_learning.staged_bag import STAGING_SUFFIX, staging_folder

    out = tmp_path / 'busy'
    staging_folder(out).mkdir()
    assert staging_folder(out).name == f'.busy{STAGING_SUFFIX}'
    with pytest.raises(
        BagError, match=r'busy: no such bag; it is being written in .*\.busy\.writing'
    ):
        bag_info(out)
    with pytest.raises(BagError, match=r'other: no such bag$'):
        bag_info(tmp_path / 'other')


def test_two_storage_files_overlapping_in_time_are_named(bag: Path, tmp_path: Path) -> None:
    # Probe 15 (A75): a bag listing a storage file and its copy said 'time stamp goes backwards
    # at sample 3251'.
    copy = tmp_path / 'two'
    shutil.copytree(bag, copy)
    (first,) = sorted(copy.glob('*.mcap'))
    shutil.copy(first, copy / 'second.mcap')
    meta = copy / 'metadata.yaml'
    document = yaml.safe_load(meta.read_text())
    info = document['rosbag2_bagfile_information']
    info['relative_file_paths'] = [first.name, 'second.mcap']
    info['files'] = [info['files'][0], {**info['files'][0], 'path': 'second.mcap'}]
    info['message_count'] *= 2
    for topic in info['topics_with_message_count']:
        topic['message_count'] *= 2
    meta.write_text(yaml.safe_dump(document, sort_keys=False))
    overlap = rf'{first.name} and second\.mcap overlap in log time .* a copy of the other'
    with pytest.raises(BagError, match=overlap):
        read_joint_states(copy, '/joint_states')
