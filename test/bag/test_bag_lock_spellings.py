"""The lock of a bag is the lock of what its path resolves to, and names its live readers.

Probe R07: a replay played ``link60 -> sim60c`` (its lock ``link60.lock``) while ``simulate
--force --out sim60c`` (its lock ``sim60c.lock``) replaced the bag under it. Probe R06: readers A
and B; B left; a writer was refused naming B's pid (exited), not A's.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from id_learning.bag import JOINT_STATE, BagWriter, encode_joint_state
from id_learning.outputs import OutputError, locked, output_lock, read_lock

JOINTS = ('joint_1', 'joint_2')


def _bag(folder: Path) -> Path:
    with BagWriter(folder) as writer:
        writer.add_topic('/joint_states', JOINT_STATE)
        for k in range(5):
            q = [0.1 * k, 0.2]
            writer.write('/joint_states', k, encode_joint_state(k, JOINTS, q, q, q))
    return folder


def _spellings(tmp_path: Path) -> tuple[Path, Path, Path]:
    target = _bag(tmp_path / 'sim60c')
    link = tmp_path / 'link60'
    link.symlink_to('sim60c')
    (tmp_path / 'sub').mkdir()
    dotted = tmp_path / 'sub' / '..' / 'sim60c'
    return target, link, dotted


@pytest.mark.parametrize(('read_as', 'write_as'), [(1, 0), (0, 1), (2, 1), (1, 2)])
def test_a_reader_and_a_writer_meet_at_one_lock_however_the_bag_is_spelled(
    tmp_path: Path, read_as: int, write_as: int
) -> None:
    paths = _spellings(tmp_path)
    with read_lock(paths[read_as]) as held:
        assert held
        with pytest.raises(OutputError, match='is reading it'), output_lock(paths[write_as]):
            pass
        with pytest.raises(OutputError, match='is reading it'):
            BagWriter(paths[write_as], overwrite=True).open()
    with output_lock(paths[write_as]):  # read no more: it may be written
        pass


def test_a_writer_through_a_link_keeps_out_a_reader_through_the_target(tmp_path: Path) -> None:
    target, link, _ = _spellings(tmp_path)
    with locked(link), pytest.raises(OutputError, match='is writing it'), read_lock(target):
        pass


def _reader_that_leaves(bag: Path, how: str) -> int:
    """The pid of a process that read ``bag`` and is gone (``how``: left, or died in it)."""
    end = 'os._exit(0)' if how == 'died' else 'pass'
    code = (
        'import os; from pathlib import Path; from id_learning.outputs import read_lock\n'
        f'with read_lock(Path({str(bag)!r})) as held:\n'
        f'    print(os.getpid(), flush=True); {end}\n'
    )
    done = subprocess.run(
        [sys.executable, '-c', code], capture_output=True, text=True, check=True, timeout=60
    )
    return int(done.stdout.split()[0])


@pytest.mark.parametrize('how', ['left', 'died'])
def test_a_writer_is_refused_naming_the_reader_still_reading(tmp_path: Path, how: str) -> None:
    bag = _bag(tmp_path / 'bag')
    with read_lock(bag):  # reader A: this process
        gone = _reader_that_leaves(bag, how)  # reader B
        with pytest.raises(OutputError) as caught:
            BagWriter(bag, overwrite=True).open()
    text = str(caught.value)
    assert f'pid {os.getpid()}' in text
    assert str(gone) not in text
