"""Where a bag's files are: subfolders metadata.yaml lists, folders that are no bag, recovery.

rosbag2 resolves ``relative_file_paths`` against the bag folder, so a bag may keep its storage
in a subfolder: every reader and ``bag recover`` read it. A folder that is no recording at all
is named for what it is, not sent to ``bag recover``. ``bag recover --out`` fills an existing
empty folder (as the recorder does), never one that holds anything.
"""

from __future__ import annotations

import shutil
import tempfile
from pathlib import Path

import numpy as np
import pytest
import yaml
from hypothesis import given, settings
from hypothesis import strategies as st

from id_learning.bag import (
    JOINT_STATE,
    BagWriter,
    bag_info,
    encode_joint_state,
    iter_raw,
    read_joint_states,
)
from id_learning.bag.reader_paths import VIEW_PREFIX
from id_learning.bag.recover import recover_bag
from id_learning.errors import BagError

TOPICS = ('/joint_states', '/motor_currents')
JOINTS = ('joint_1', 'joint_2')
T0_NS = 1_700_000_000 * 1_000_000_000


def write_bag(path: Path, n: int = 50) -> Path:
    """A small two-topic bag; log times advance with the stamps."""
    empty = np.zeros(0)
    with BagWriter(path) as writer:
        for topic in TOPICS:
            writer.add_topic(topic, JOINT_STATE)
        for k in range(n):
            stamp = T0_NS + k * 8_000_000
            q = np.array([0.01 * k, -0.01 * k])
            writer.write(TOPICS[0], stamp, encode_joint_state(stamp, JOINTS, q, q, empty))
            writer.write(TOPICS[1], stamp, encode_joint_state(stamp, JOINTS, empty, empty, q))
    return path


def move_into_subfolder(bag: Path, subfolder: str) -> str:
    """Move the bag's storage file into ``subfolder`` and list it there; the new entry."""
    (file,) = bag.glob('*.mcap')
    (bag / subfolder).mkdir(parents=True)
    entry = f'{subfolder}/{file.name}'
    file.rename(bag / entry)
    meta_path = bag / 'metadata.yaml'
    meta = yaml.safe_load(meta_path.read_text(encoding='utf-8'))
    info = meta['rosbag2_bagfile_information']
    info['relative_file_paths'] = [entry]
    for item in info.get('files') or []:
        item['path'] = entry
    meta_path.write_text(yaml.safe_dump(meta, sort_keys=False), encoding='utf-8')
    return entry


def views() -> set[Path]:
    return set(Path(tempfile.gettempdir()).glob(f'{VIEW_PREFIX}*'))


@pytest.fixture(scope='module')
def bag(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return write_bag(tmp_path_factory.mktemp('flat') / 'bag')


@settings(max_examples=8)
@given(subfolder=st.sampled_from(['data', 'a/b', 'storage files', 'ü']))
def test_a_bag_listing_its_file_in_a_subfolder_reads_like_the_flat_one(
    bag: Path, tmp_path_factory: pytest.TempPathFactory, subfolder: str
) -> None:
    nested = tmp_path_factory.mktemp('nested') / 'bag'
    shutil.copytree(bag, nested)
    entry = move_into_subfolder(nested, subfolder)
    before = views()

    assert bag_info(nested).files == (entry,)
    assert list(iter_raw(nested, TOPICS)) == list(iter_raw(bag, TOPICS))
    flat, inner = read_joint_states(bag, TOPICS[0]), read_joint_states(nested, TOPICS[0])
    np.testing.assert_array_equal(inner.stamps_ns, flat.stamps_ns)
    np.testing.assert_array_equal(np.asarray(inner.position), np.asarray(flat.position))
    assert views() <= before  # the reader's view is gone once it closes
    assert recover_bag(nested).is_intact  # recover finds the file as well
    assert (nested / entry).is_file()


def test_a_missing_file_in_a_subfolder_is_named(bag: Path, tmp_path: Path) -> None:
    nested = tmp_path / 'bag'
    shutil.copytree(bag, nested)
    entry = move_into_subfolder(nested, 'data')
    (nested / entry).unlink()
    with pytest.raises(BagError, match=rf'metadata\.yaml lists {entry}, which the folder'):
        bag_info(nested)


def test_a_torn_file_in_a_subfolder_is_recovered(bag: Path, tmp_path: Path) -> None:
    nested = tmp_path / 'bag'
    shutil.copytree(bag, nested)
    entry = move_into_subfolder(nested, 'data')
    file = nested / entry
    with file.open('r+b') as stream:
        stream.truncate(file.stat().st_size * 2 // 3)

    report = recover_bag(nested)

    assert not report.is_intact
    assert report.messages > 0
    assert sum(1 for _ in iter_raw(nested, TOPICS)) == report.messages


def test_a_run_folder_is_no_recording(tmp_path: Path) -> None:
    run = tmp_path / 'run'
    (run / 'models').mkdir(parents=True)
    (run / 'run.json').write_text('{}', encoding='utf-8')
    (run / 'metrics.json').write_text('{}', encoding='utf-8')
    for read in (bag_info, recover_bag):
        with pytest.raises(BagError, match=r'holds a train run \(run\.json\), not a rec') as err:
            read(run)
        assert 'bag recover PATH' not in str(err.value)


def test_a_folder_with_mcap_files_only_in_subfolders_says_where(bag: Path, tmp_path: Path) -> None:
    outer = tmp_path / 'outer'
    outer.mkdir()
    shutil.copytree(bag, outer / 'inner')
    with pytest.raises(BagError, match=r'inner/bag_0\.mcap lie in subfolders'):
        bag_info(outer)


def test_a_torn_bag_is_still_sent_to_recover(bag: Path, tmp_path: Path) -> None:
    torn = tmp_path / 'torn'
    shutil.copytree(bag, torn)
    (torn / 'metadata.yaml').unlink()
    with pytest.raises(BagError, match='bag recover PATH'):
        bag_info(torn)


def test_a_metadata_type_that_disagrees_with_the_storage_is_named(bag: Path, tmp_path: Path):
    lie = tmp_path / 'lie'
    shutil.copytree(bag, lie)
    meta_path = lie / 'metadata.yaml'
    meta = meta_path.read_text(encoding='utf-8')
    meta_path.write_text(meta.replace(JOINT_STATE, 'std_msgs/msg/String', 1), encoding='utf-8')
    with pytest.raises(BagError, match=r'in metadata\.yaml but sensor_msgs/msg/JointState in'):
        read_joint_states(lie, TOPICS[0])


def _torn(bag: Path, target: Path) -> Path:
    shutil.copytree(bag, target)
    (target / 'metadata.yaml').unlink()
    return target


def test_recover_fills_an_existing_empty_folder(bag: Path, tmp_path: Path) -> None:
    torn = _torn(bag, tmp_path / 'torn')
    out = tmp_path / 'out'
    out.mkdir()

    report = recover_bag(torn, out)

    assert report.output == out
    assert sum(1 for _ in iter_raw(out, TOPICS)) == report.messages == 2 * 50


def test_recover_never_writes_into_a_folder_that_holds_something(bag: Path, tmp_path: Path):
    torn = _torn(bag, tmp_path / 'torn')
    out = tmp_path / 'out'
    out.mkdir()
    (out / 'notes.txt').write_text('mine', encoding='utf-8')
    with pytest.raises(BagError, match='already exists and is not an empty folder'):
        recover_bag(torn, out)
    assert [p.name for p in out.iterdir()] == ['notes.txt']


def test_a_folder_filled_while_recovering_is_not_written_over(
    bag: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The final move replaces an empty folder only: what arrived meanwhile stays."""
    from id_learning.bag import recover

    torn = _torn(bag, tmp_path / 'torn')
    out = tmp_path / 'out'
    out.mkdir()
    write = recover._write

    def write_then_fill(*args, **kwargs):  # another program writes into out meanwhile
        scans = write(*args, **kwargs)
        (out / 'arrived.txt').write_text('theirs', encoding='utf-8')
        return scans

    monkeypatch.setattr(recover, '_write', write_then_fill)
    with pytest.raises(BagError, match=r'it must be absent or an empty folder\); nothing was'):
        recover_bag(torn, out)
    assert [p.name for p in out.iterdir()] == ['arrived.txt']
    assert (torn / 'bag_0.mcap').is_file()
