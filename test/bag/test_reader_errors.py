"""The reader's refusals: storage that does not match metadata.yaml, and duplicate recordings."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest
import yaml
from support import sine_recording

from id_learning.bag import JOINT_STATE, BagWriter, bag_info, iter_raw
from id_learning.bag.reader import check_distinct
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
