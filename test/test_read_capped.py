"""The one capped reader every whole-file read goes through: its cap, its kinds, its errors.

``config_io.read_capped`` returns a file's bytes when it holds at most the cap, refuses a device
(and, for the files of the package's own folders, ``regular=True``, a FIFO and a socket too)
without blocking or reading, and raises the boundary's own error naming the file and what it is.
"""

from __future__ import annotations

import os
import socket
import tempfile
import threading
import time
from collections.abc import Callable
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from id_learning.config_io import read_capped, special_kind
from id_learning.errors import BagError, CheckpointError, ConfigError, IdLearningError


@settings(max_examples=60, deadline=None)
@given(data=st.binary(max_size=300), limit=st.integers(min_value=0, max_value=300))
def test_a_file_is_read_whole_up_to_the_cap_and_refused_past_it(data: bytes, limit: int) -> None:
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / 'file'
        path.write_bytes(data)
        for regular in (False, True):
            if len(data) <= limit:
                assert read_capped(path, 'file', limit, regular=regular) == data
            else:
                with pytest.raises(ConfigError, match=rf'^{path}: cannot read file: larger than'):
                    read_capped(path, 'file', limit, regular=regular)


@pytest.mark.parametrize(
    ('limit', 'words'), [(100, '100 bytes'), (3 * 2**10, '3 KiB'), (4 * 2**20, '4 MiB')]
)
def test_the_cap_is_named_in_the_unit_it_was_set_in(
    tmp_path: Path, limit: int, words: str
) -> None:
    path = tmp_path / 'big'
    with path.open('wb') as stream:
        stream.truncate(limit + 1)
    with pytest.raises(ConfigError) as err:
        read_capped(path, 'study table', limit)
    assert str(err.value) == (
        f'{path}: cannot read study table: larger than {words}, which no study table is: is '
        'this the right file?'
    )


def test_a_large_regular_file_is_refused_by_its_size_before_a_byte_is_read(
    tmp_path: Path,
) -> None:
    path = tmp_path / 'huge.json'
    with path.open('wb') as stream:
        stream.truncate(2**40)  # sparse: a terabyte that takes no disk
    start = time.monotonic()
    with pytest.raises(ConfigError, match='larger than 1 KiB'):
        read_capped(path, 'run document', 2**10, regular=True)
    assert time.monotonic() - start < 1.0


def _fifo(folder: Path) -> Path:
    os.mkfifo(folder / 'pipe')
    return folder / 'pipe'


def _socket(folder: Path) -> Path:
    server = socket.socket(socket.AF_UNIX)
    server.bind(str(folder / 'sock'))
    server.close()
    return folder / 'sock'


def _device_link(folder: Path) -> Path:
    (folder / 'metadata.yaml').symlink_to('/dev/zero')
    return folder / 'metadata.yaml'


#: What is read: (how to make it in a folder, what ``special_kind`` calls it, refused unless
#: ``regular`` too?).
KINDS: dict[str, tuple[Callable[[Path], Path], str, bool]] = {
    'character device': (lambda _: Path('/dev/zero'), 'a character device', True),
    'link to a device': (_device_link, 'a character device', True),
    'socket': (_socket, 'a socket', True),
    'FIFO': (_fifo, 'a FIFO (named pipe)', False),
}


@pytest.mark.parametrize('kind', list(KINDS))
@pytest.mark.parametrize('error', [ConfigError, BagError, CheckpointError])
def test_what_is_no_regular_file_is_refused_at_once_with_the_boundarys_error(
    tmp_path: Path, kind: str, error: type[IdLearningError]
) -> None:
    make, words, always = KINDS[kind]
    path = make(tmp_path)
    assert special_kind(path) == words
    modes = (True, False) if always else (True,)  # a FIFO alone is read when not ``regular``
    for regular in modes:
        start = time.monotonic()
        with pytest.raises(error) as err:
            read_capped(path, 'bag metadata', 2**20, regular=regular, error=error)
        assert str(err.value) == f'{path}: cannot read bag metadata: {words}, not a regular file'
        assert time.monotonic() - start < 1.0


def test_a_fifo_is_read_as_it_comes_where_a_user_may_pass_one(tmp_path: Path) -> None:
    """``--study-table <(...)`` hands over a pipe: read up to the cap, then refused past it."""
    pipe = _fifo(tmp_path)
    for text, limit in ((b'{"joints": []}', 100), (b'x' * 101, 100)):
        writer = threading.Thread(target=pipe.write_bytes, args=(text,), daemon=True)
        writer.start()
        if len(text) <= limit:
            assert read_capped(pipe, 'study table', limit) == text
        else:
            with pytest.raises(ConfigError, match='larger than 100 bytes'):
                read_capped(pipe, 'study table', limit)
        writer.join(5.0)
        assert not writer.is_alive()


def test_a_regular_file_behind_a_link_is_read_and_a_folder_is_named(tmp_path: Path) -> None:
    (tmp_path / 'real.yaml').write_bytes(b'a: 1')
    (tmp_path / 'link.yaml').symlink_to(tmp_path / 'real.yaml')
    assert special_kind(tmp_path / 'link.yaml') is None
    assert read_capped(tmp_path / 'link.yaml', regular=True) == b'a: 1'
    assert special_kind(tmp_path) == 'a folder'
    assert special_kind(tmp_path / 'missing') is None
    with pytest.raises(BagError, match=r'cannot read bag metadata: Is a directory'):
        read_capped(tmp_path, 'bag metadata', regular=True, error=BagError)
    with pytest.raises(BagError, match=r'missing: cannot read bag metadata: No such file'):
        read_capped(tmp_path / 'missing', 'bag metadata', regular=True, error=BagError)
