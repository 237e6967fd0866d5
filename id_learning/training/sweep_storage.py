"""Where a sweep's trials are stored: the checks on a SQLite URL before Optuna opens it.

SQLite reports most of what is wrong with a path as 'unable to open database file', which the
retries would wait out and blame on a lock: the cause is named at once. A file the sweep does
not own (inside a bag or a train result, or another program's database) is refused.
"""

from __future__ import annotations

import contextlib
import os
import sqlite3
from pathlib import Path

from id_learning.errors import ConfigError

__all__ = ['check_sqlite_file']

#: The first 16 bytes of every SQLite 3 database file.
_SQLITE_MAGIC = b'SQLite format 3\x00'
#: Tables every Optuna RDB storage has (a file without them is someone else's database).
_OPTUNA_TABLES = frozenset(('studies', 'version_info'))
#: How long reading the table names waits for a worker's write [s].
_READ_TIMEOUT_S = 5.0


def check_sqlite_file(storage: str) -> None:
    """Refuse a SQLite URL whose file or folder cannot be written or is another's, before any wait.

    SQLite reports a missing or read-only folder, and a folder named as the file, as 'unable to
    open database file', which the retries would wait out and then blame on a lock; a
    read-only file reaches optuna as 'invalid data in the commit'. The cause is named at once.

    A database inside a bag or a train result would be taken for part of it (and deleted with
    it); an existing SQLite file that holds other tables than Optuna's is someone's database.

    Raises:
        ConfigError: names the URL, the file or folder, and what it is.
    """
    from sqlalchemy.engine import make_url
    from sqlalchemy.exc import ArgumentError

    if not storage.startswith('sqlite'):
        return
    try:
        database = make_url(storage).database
    except ArgumentError as err:
        raise ConfigError(f'sweep: the storage {storage!r} is no valid URL: {err}') from None
    if not database or database == ':memory:' or database.startswith('file:'):
        return
    folder = Path(database).absolute().parent
    if not folder.is_dir():
        raise ConfigError(
            f'sweep: the storage {storage!r}: folder {folder} does not exist; create it or '
            'name another'
        )
    if not os.access(folder, os.W_OK | os.X_OK):
        raise ConfigError(f'sweep: the storage {storage!r}: folder {folder} is not writable')
    path = Path(database).absolute()
    if path.is_dir():
        raise ConfigError(
            f'sweep: the storage {storage!r}: {path} is a folder, not a SQLite file; name a '
            f'file (sqlite:///{path / "sweep.db"})'
        )
    if path.exists() and not path.is_file():
        raise ConfigError(f'sweep: the storage {storage!r}: {path} is not a regular file')
    if path.exists() and not os.access(path, os.R_OK | os.W_OK):  # also immutable, read-only fs
        raise ConfigError(
            f'sweep: the storage {storage!r}: {path} is read-only, and every trial is written '
            'to it: make it writable, or copy it and name the copy'
        )
    _refuse_foreign(storage, folder, path)


#: Files that make a folder a bag (rosbag2) or a train result, which a sweep must not write into.
_OWNED_BY = {'metadata.yaml': 'a bag', 'run.json': 'a train result'}


def _refuse_foreign(storage: str, folder: Path, path: Path) -> None:
    """Refuse a database in a bag or a run folder, or a SQLite file with tables not Optuna's."""
    for marker, what in _OWNED_BY.items():
        if (folder / marker).is_file():
            raise ConfigError(
                f'sweep: the storage {storage!r}: {folder} is {what} (it holds {marker}); a '
                'sweep database there would be taken for part of it: name a file elsewhere'
            )
    if not path.is_file() or path.stat().st_size == 0:
        return
    with path.open('rb') as stream:
        if stream.read(16) != _SQLITE_MAGIC:
            raise ConfigError(
                f'sweep: the storage {storage!r}: {path} is no SQLite database (it does not '
                'start as one): name a new file'
            )
    try:
        uri = f'{path.as_uri()}?mode=ro'
        with contextlib.closing(sqlite3.connect(uri, uri=True, timeout=_READ_TIMEOUT_S)) as db:
            rows = db.execute("SELECT name FROM sqlite_master WHERE type='table'").fetchall()
    except sqlite3.Error:
        return  # busy (another worker writes) or damaged: opening it names what is wrong
    tables = {str(row[0]) for row in rows}
    if tables and not tables >= _OPTUNA_TABLES:
        raise ConfigError(
            f'sweep: the storage {storage!r}: {path} is another SQLite database (tables '
            f'{sorted(tables)[:5]}), no Optuna storage: name a new file'
        )
