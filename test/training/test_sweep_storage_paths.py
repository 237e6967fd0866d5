"""A SQLite storage that is a folder or read-only is named so at once (probe 10, S03 and S05).

Before, a folder waited out the storage timeout and was blamed on a lock, and a read-only file
gave optuna's 'invalid data in the commit, e.g. exceeding max length'.
"""

from __future__ import annotations

import contextlib
import os
import shutil
import sqlite3
import subprocess
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

from id_learning.errors import ConfigError
from id_learning.training.sweep import run_sweep

#: The storage timeout of these sweeps [s]: a refusal well within it is one that did not wait.
TIMEOUT_S = 10.0


def _sweep(tmp_path: Path, mabi, storage: str) -> None:
    # No bag exists: the storage is opened first, so its refusal comes before any reading.
    run_sweep([tmp_path / 'no_such_bag'], mabi, 'motor', 'rnea_lq', tmp_path / 'out', trials=1,
              storage=storage, progress=False, storage_timeout_s=TIMEOUT_S)  # fmt: skip


def test_a_sqlite_storage_that_is_a_folder_is_refused_at_once_as_one(tmp_path: Path, mabi):
    folder = tmp_path / 'dbdir'
    folder.mkdir()
    start = time.monotonic()
    with pytest.raises(
        ConfigError, match=rf'{folder} is a folder, not a SQLite file; name a file \(sqlite:///'
    ):
        _sweep(tmp_path, mabi, f'sqlite:///{folder}')
    assert time.monotonic() - start < TIMEOUT_S / 2


@contextlib.contextmanager
def _read_only(path: Path) -> Iterator[None]:
    """``path`` read-only for this process: immutable for root (who writes any mode), else 0444."""
    if os.geteuid() != 0:
        path.chmod(0o444)
        yield
        return
    chattr = shutil.which('chattr')
    if chattr is None:
        pytest.skip('root writes a file of any mode, and chattr (to make it immutable) is missing')
    made = subprocess.run([chattr, '+i', str(path)], capture_output=True, check=False)
    if made.returncode != 0:
        pytest.skip(f'root writes a file of any mode, and chattr +i failed: {made.stderr!r}')
    try:
        yield
    finally:
        subprocess.run([chattr, '-i', str(path)], check=True)


def test_a_read_only_sqlite_storage_is_refused_as_read_only_naming_it(tmp_path: Path, mabi):
    path = tmp_path / 'study.db'
    with contextlib.closing(sqlite3.connect(path)) as db:
        db.execute('CREATE TABLE earlier (x)')
        db.commit()
    with _read_only(path):
        with (  # the precondition: it is
            contextlib.closing(sqlite3.connect(path)) as db,
            pytest.raises(sqlite3.OperationalError, match='readonly'),
        ):
            db.execute('CREATE TABLE more (x)')
        start = time.monotonic()
        with pytest.raises(ConfigError, match=rf'{path} is read-only, and every trial is written'):
            _sweep(tmp_path, mabi, f'sqlite:///{path}')
        assert time.monotonic() - start < TIMEOUT_S / 2
