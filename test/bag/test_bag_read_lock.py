"""A bag being read (a replay holds ``<bag>.lock`` shared) is never replaced under its reader:
a writer that would replace it is refused at once, naming the bag and that it is being read
(probe Y02: a recorder with overwrite:=true emptied the bag a replay played). Readers share; a
folder where the lock cannot be made is read without it."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest
from support import immutable

from id_learning.bag import JOINT_STATE, BagWriter, encode_joint_state
from id_learning.bag.recover import recover_bag
from id_learning.outputs import OutputError, read_lock

JOINTS = ('joint_1', 'joint_2')


def _bag(folder: Path) -> Path:
    with BagWriter(folder) as writer:
        writer.add_topic('/joint_states', JOINT_STATE)
        for k in range(20):
            q = [0.1 * k, 0.2]
            writer.write('/joint_states', k, encode_joint_state(k, JOINTS, q, q, q))
    return folder


def _files(folder: Path) -> dict[str, bytes]:
    return {p.name: p.read_bytes() for p in sorted(folder.iterdir())}


def _lock_file(bag: Path) -> Path:
    return bag.with_name(bag.name + '.lock')


def test_a_bag_being_read_is_not_replaced_and_the_refusal_names_it(tmp_path: Path) -> None:
    bag = _bag(tmp_path / 'bag')
    before = _files(bag)
    with read_lock(bag) as held:
        assert held
        with pytest.raises(OutputError) as caught:
            BagWriter(bag, overwrite=True, flag='overwrite:=true').open()
        text = str(caught.value)
        assert str(bag) in text
        assert 'is reading it' in text
        assert 'replay' in text
        assert _files(bag) == before
    assert not _lock_file(bag).exists()  # the last reader removes it
    BagWriter(bag, overwrite=True).open().close()  # read no more: it may be replaced
    assert _files(bag) != before


def test_readers_share_and_the_bag_is_free_only_when_the_last_leaves(tmp_path: Path) -> None:
    bag = _bag(tmp_path / 'bag')
    with read_lock(bag) as first:
        with read_lock(bag) as second:
            assert first
            assert second
        with pytest.raises(OutputError, match='is reading it'):
            BagWriter(bag, overwrite=True).open()
        assert _lock_file(bag).exists()  # another reader still holds it
    assert not _lock_file(bag).exists()


def test_a_bag_being_written_is_not_read_naming_its_writer(tmp_path: Path) -> None:
    bag = tmp_path / 'bag'
    with BagWriter(bag) as writer:
        writer.add_topic('/joint_states', JOINT_STATE)
        refused = pytest.raises(OutputError, match=r'another process \(pid \d+\) is writing it')
        with refused, read_lock(bag):
            pass


def test_recovering_a_bag_in_place_is_refused_while_it_is_read(tmp_path: Path) -> None:
    bag = _bag(tmp_path / 'bag')
    (bag / 'metadata.yaml').unlink()  # torn: recovery rewrites it in place
    with read_lock(bag), pytest.raises(OutputError, match='is reading it'):
        recover_bag(bag)


def test_a_reader_in_another_process_keeps_the_bag(tmp_path: Path) -> None:
    bag = _bag(tmp_path / 'bag')
    before = _files(bag)
    code = (
        'import sys; from pathlib import Path; from id_learning.outputs import read_lock\n'
        f'with read_lock(Path({str(bag)!r})) as held:\n'
        '    print(held, flush=True); sys.stdin.readline()\n'
    )
    reader = subprocess.Popen(
        [sys.executable, '-c', code], stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True
    )
    try:
        assert reader.stdout is not None
        assert reader.stdout.readline().strip() == 'True'
        with pytest.raises(OutputError, match=rf'{bag}: another process \(pid {reader.pid}, '):
            BagWriter(bag, overwrite=True).open()
        assert _files(bag) == before
    finally:
        reader.communicate('\n', timeout=30)
    BagWriter(bag, overwrite=True).open().close()


def test_a_bag_in_a_folder_that_cannot_be_written_is_read_without_a_lock(tmp_path: Path) -> None:
    bag = _bag(tmp_path / 'shelf' / 'bag')
    with immutable(bag.parent), read_lock(bag) as held:
        assert not held
        assert not _lock_file(bag).exists()
