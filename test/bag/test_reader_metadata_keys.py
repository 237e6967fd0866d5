"""A metadata.yaml cut short, or naming another storage than its files hold, is named as such.

rosbags says only ``A metadata key is missing KeyError('type')`` or ``Cannot open database``:
the reader names the file, the key (its path in the file) or the storage and the files' magic
bytes, and ``bag recover``, which rebuilds metadata.yaml from the storage files.
"""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest
from support import sine_recording

from id_learning.bag import bag_info, iter_raw
from id_learning.bag.recover import recover_bag
from id_learning.dataset.recording import write_recording
from id_learning.errors import BagError

TOPICS = ('/joint_states', '/motor_currents')


@pytest.fixture(scope='module')
def bag(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path: Path = write_recording(sine_recording(30), tmp_path_factory.mktemp('meta') / 'bag')
    return path


def copy_with(bag: Path, target: Path, text: str) -> Path:
    """A copy of ``bag`` whose metadata.yaml holds ``text``."""
    copy = Path(shutil.copytree(bag, target))
    (copy / 'metadata.yaml').write_text(text, encoding='utf-8')
    return copy


def test_a_metadata_yaml_cut_short_names_the_key_it_lacks_and_recover_rebuilds_it(
    bag: Path, tmp_path: Path
) -> None:
    """Probe A38: cut inside the first topic's name, as a copy that stopped short leaves it."""
    text = (bag / 'metadata.yaml').read_text(encoding='utf-8')
    cut = text.index('name: /joint_states') + len('name: /joint_')
    copy = copy_with(bag, tmp_path / 'cut', text[:cut])

    with pytest.raises(BagError) as caught:
        bag_info(copy)
    assert str(caught.value) == (
        f'{copy / "metadata.yaml"} is incomplete: it lacks rosbag2_bagfile_information.'
        "topics_with_message_count[0].topic_metadata.type (topic '/joint_'); it ends mid-line "
        f'at byte {cut}: cut short; `id-learning bag recover {copy}` rebuilds metadata.yaml '
        'from the storage files'
    )

    recover_bag(copy, tmp_path / 'fixed')
    assert list(iter_raw(tmp_path / 'fixed', TOPICS)) == list(iter_raw(bag, TOPICS))


@pytest.mark.parametrize(
    ('key', 'lacks'),
    [
        ('    nanoseconds:', 'rosbag2_bagfile_information.duration.nanoseconds'),
        ('  storage_identifier:', 'rosbag2_bagfile_information.storage_identifier'),
        (
            '    message_count:',
            "topics_with_message_count[0].message_count (topic '/joint_states')",
        ),
    ],
)
def test_a_metadata_yaml_without_a_key_names_it(
    bag: Path, tmp_path: Path, key: str, lacks: str
) -> None:
    text = (bag / 'metadata.yaml').read_text(encoding='utf-8')
    edited = text.replace(key, key.replace(':', '_renamed:'), 1)  # its first occurrence
    copy = copy_with(bag, tmp_path / 'edited', edited)

    with pytest.raises(BagError) as caught:
        bag_info(copy)
    message = str(caught.value)
    assert message.startswith(f'{copy / "metadata.yaml"} is incomplete: it lacks ')
    assert lacks in message
    assert 'KeyError' not in message
    assert 'cut short' not in message  # the file ends with its newline
    assert f'`id-learning bag recover {copy}` rebuilds metadata.yaml' in message


def test_a_storage_identifier_the_files_contradict_names_both(bag: Path, tmp_path: Path) -> None:
    """Probe A39: storage_identifier sqlite3 over an MCAP file."""
    text = (bag / 'metadata.yaml').read_text(encoding='utf-8')
    assert 'storage_identifier: mcap\n' in text
    copy = copy_with(
        bag,
        tmp_path / 'sqlite',
        text.replace('storage_identifier: mcap', 'storage_identifier: sqlite3'),
    )
    (storage,) = (p.name for p in copy.glob('*.mcap'))

    with pytest.raises(BagError) as caught:
        bag_info(copy)
    assert str(caught.value) == (
        f"{copy / 'metadata.yaml'} names storage_identifier 'sqlite3', but {storage} is an MCAP "
        "file (its first bytes are b'\\x89MCAP0\\r\\n'); set storage_identifier: mcap in "
        f'metadata.yaml, or run `id-learning bag recover {copy}`, which rebuilds metadata.yaml '
        'from the files'
    )

    recover_bag(copy, tmp_path / 'fixed')
    assert list(iter_raw(tmp_path / 'fixed', TOPICS)) == list(iter_raw(bag, TOPICS))
