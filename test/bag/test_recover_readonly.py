"""In-place recovery of a bag whose folder cannot be written is refused before any work, in one
line suggesting --out; a rename that fails while installing is undone, and said in one line."""

from __future__ import annotations

import shutil
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest
from support import immutable as immutable_folder

from id_learning.bag import JOINT_STATE, BagWriter, encode_joint_state
from id_learning.bag.recover import recover_bag
from id_learning.cli.main import main
from id_learning.errors import BagError

JOINTS = ('joint_1', 'joint_2')


def _bag(folder: Path) -> Path:
    """A complete bag of 600 JointState messages in small chunks."""
    rng = np.random.default_rng(5)
    with BagWriter(folder, chunk_bytes=2048) as writer:
        writer.add_topic('/joint_states', JOINT_STATE)
        for k in range(600):
            q = rng.normal(size=len(JOINTS))
            writer.write('/joint_states', k, encode_joint_state(k, JOINTS, q, q, q))
    return folder


def _torn_bag(folder: Path, name: str) -> Path:
    """A bag as a killed writer leaves it, in ``folder``: its file ``name``, cut, no metadata."""
    source = _bag(folder.with_name(folder.name + '-source'))
    folder.mkdir()
    data = (source / f'{source.name}_0.mcap').read_bytes()
    (folder / name).write_bytes(data[: len(data) // 2])
    shutil.rmtree(source)
    return folder


def _files(folder: Path) -> dict[str, bytes]:
    return {p.name: p.read_bytes() for p in folder.iterdir() if p.is_file()}


@pytest.fixture
def immutable(tmp_path: Path) -> Iterator[Path]:
    """A torn bag in a folder that cannot be written."""
    with immutable_folder(_torn_bag(tmp_path / 'ro', 'ro_0.mcap')) as bag:
        yield bag


def test_a_bag_in_a_folder_that_cannot_be_written_is_refused_before_any_work(
    immutable: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    before = _files(immutable)
    assert main(['bag', 'recover', str(immutable)]) == 2
    said = capsys.readouterr().err.strip().splitlines()
    assert said == [
        f'id-learning bag: error: {immutable}: cannot write in {immutable} (Operation not '
        'permitted), where its files are replaced when recovering in place; recover into a '
        'new folder with --out NEW_FOLDER'
    ]
    assert _files(immutable) == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ['ro']  # no staging folder, no lock
    report = recover_bag(immutable, tmp_path / 'copy')  # what the line suggests works
    assert report.messages > 0
    assert sorted(p.name for p in (tmp_path / 'copy').iterdir()) == [
        'copy_0.mcap',
        'metadata.yaml',
    ]


def test_a_complete_bag_in_a_folder_that_cannot_be_written_is_still_said_complete(
    tmp_path: Path,
) -> None:
    with immutable_folder(_bag(tmp_path / 'complete')) as bag:
        assert recover_bag(bag).is_intact  # nothing to write: nothing to refuse


def test_a_rename_that_fails_while_installing_is_undone_and_said(tmp_path: Path) -> None:
    # The rebuilt file is named after the folder; a folder there cannot be replaced by it.
    bag = _torn_bag(tmp_path / 'bag', 'recorded_0.mcap')
    (bag / 'bag_0.mcap' / 'in_the_way').mkdir(parents=True)
    before = _files(bag)
    with pytest.raises(BagError) as raised:
        recover_bag(bag)
    said = str(raised.value)
    assert said.startswith(f'{bag / "bag_0.mcap"}: Is a directory (installing the recovered')
    assert 'the original files are back in place' in said
    assert '--out NEW_FOLDER' in said
    assert _files(bag) == before  # no .damaged file, no metadata.yaml
    assert sorted(p.name for p in bag.iterdir()) == ['bag_0.mcap', 'recorded_0.mcap']
    assert sorted(p.name for p in tmp_path.iterdir()) == ['bag']  # no staging folder, no lock
