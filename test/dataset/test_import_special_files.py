"""A folder source's entry named like a log that is no regular file is refused, never opened.

Probe Q03: a FIFO ``b.csv`` in an import folder was passed over without a word (the folder was
listed with ``is_file``), so a log recorded there would be silently left out of the bag. A FIFO,
a device, a socket or a link to nothing named like a log is now refused, naming it and what it
is; it is never opened (a FIFO would wait for a writer).
"""

from __future__ import annotations

import os
import socket
from pathlib import Path

import numpy as np
import pytest
from support import no_hang

from id_learning.dataset.importer import log_files
from id_learning.errors import DatasetError


def _logs(tmp_path: Path) -> Path:
    """logs/a.csv, a log of 50 rows."""
    folder = tmp_path / 'logs'
    folder.mkdir()
    rows = np.column_stack([8.0 * np.arange(50), np.linspace(0, 0.5, 50), np.zeros(50)])
    lines = ['t_ms,q1,v1'] + [','.join(repr(float(x)) for x in row) for row in rows]
    (folder / 'a.csv').write_text('\n'.join(lines) + '\n', encoding='utf-8')
    return folder


def _refusal(folder: Path) -> str:
    with no_hang(), pytest.raises(DatasetError) as err:
        log_files([folder])
    return str(err.value)


def test_a_fifo_named_like_a_log_in_a_folder_is_refused_naming_it(tmp_path: Path) -> None:
    folder = _logs(tmp_path)
    os.mkfifo(folder / 'b.csv')
    message = _refusal(folder)
    assert message.startswith(f'{folder / "b.csv"}: a FIFO (named pipe)')
    assert 'not a log file' in message


def test_a_device_named_like_a_log_in_a_folder_is_refused_naming_it(tmp_path: Path) -> None:
    folder = _logs(tmp_path)
    (folder / 'b.csv.gz').symlink_to('/dev/null')
    assert _refusal(folder).startswith(f'{folder / "b.csv.gz"}: a character device')


def test_a_socket_named_like_a_log_in_a_folder_is_refused_naming_it(tmp_path: Path) -> None:
    folder = _logs(tmp_path)
    path = folder / 'c.npz'
    with socket.socket(socket.AF_UNIX) as server:
        try:
            server.bind(str(path))
        except OSError as err:  # a path too long for a socket address
            pytest.skip(f'cannot bind a socket at {path}: {err}')
        assert _refusal(folder).startswith(f'{path}: a socket')


def test_a_link_to_nothing_named_like_a_log_in_a_folder_is_refused_naming_it(
    tmp_path: Path,
) -> None:
    folder = _logs(tmp_path)
    (folder / 'b.csv').symlink_to(tmp_path / 'elsewhere.csv')
    assert _refusal(folder).startswith(
        f'{folder / "b.csv"}: a link to {tmp_path / "elsewhere.csv"}, which does not exist'
    )


def test_entries_that_are_no_logs_by_name_are_still_passed_over(tmp_path: Path) -> None:
    """A FIFO or folder without a log's suffix is nothing the import would read: no refusal."""
    folder = _logs(tmp_path)
    os.mkfifo(folder / 'control')
    (folder / 'plots.csv').mkdir()  # a folder named like a log: a subfolder, not read
    other = tmp_path / 'other.csv'  # a link to a log is a log
    other.write_text('t_ms,q1,v1\n' + '\n'.join(f'{8 * k},0.{k},0' for k in range(9)) + '\n')
    (folder / 'link.csv').symlink_to(other)
    with no_hang():
        assert log_files([folder]) == [folder / 'a.csv', folder / 'link.csv']
