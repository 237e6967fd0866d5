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
from id_learning.output_kinds import folder_holds

__all__ = ['check_sqlite_file']

#: The first 16 bytes of every SQLite 3 database file.
_SQLITE_MAGIC = b'SQLite format 3\x00'
#: The database kinds a sweep runs on (SQLAlchemy dialects, any driver).
_SCHEMES = ('sqlite', 'postgresql')
#: Tables every Optuna RDB storage has (a file without them is someone else's database).
_OPTUNA_TABLES = frozenset(('studies', 'version_info'))


def check_sqlite_file(storage: str, timeout_s: float = 5.0) -> None:
    """Refuse a SQLite URL whose file or folder cannot be written or is another's, before any wait.

    SQLite reports a missing or read-only folder, and a folder named as the file, as 'unable to
    open database file', which the retries would wait out and then blame on a lock; a
    read-only file reaches optuna as 'invalid data in the commit'. The cause is named at once.

    A database inside a bag or a train result would be taken for part of it (and deleted with
    it); an existing SQLite file that holds other tables than Optuna's is someone's database.

    ``timeout_s`` bounds the wait to read an existing file's table names (a worker writing).

    Raises:
        ConfigError: names the URL, the file or folder, and what it is.
    """
    from sqlalchemy.engine import make_url
    from sqlalchemy.exc import ArgumentError

    scheme = storage.split('://', 1)[0] if '://' in storage else ''
    if scheme.split('+', 1)[0] not in _SCHEMES:
        raise ConfigError(
            f'sweep: the storage {storage!r}: {scheme or "no scheme"!r} is no storage this '
            'tool supports: give sqlite:///PATH/sweep.db (one machine) or '
            'postgresql+psycopg://USER@HOST/DB (several machines)'
        )
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
    _refuse_foreign(storage, folder, path, timeout_s)


#: What a folder holding (or above) a sweep database may hold: a sweep's own files, nothing,
#: or files that are no id_learning result and no bag.
_SHARED_WITH = ('empty', 'foreign', 'sweep')


def _refuse_foreign(storage: str, folder: Path, path: Path, timeout_s: float) -> None:
    """Refuse a database in (or below) a bag or a result, or a SQLite file not Optuna's."""
    for parent in (folder, *folder.parents):
        try:
            held = folder_holds(parent)
        except OSError:
            continue  # a folder that cannot be listed says nothing
        if held.kind not in _SHARED_WITH:
            raise ConfigError(
                f'sweep: the storage {storage!r}: {path} lies inside {parent}, which holds '
                f'{held.describe()}; a sweep database there would be taken for part of it: '
                'name a file elsewhere'
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
        with contextlib.closing(sqlite3.connect(uri, uri=True, timeout=timeout_s)) as db:
            rows = db.execute("SELECT name FROM sqlite_master WHERE type='table'").fetchall()
    except sqlite3.Error:
        return  # busy (another worker writes) or damaged: opening it names what is wrong
    tables = {str(row[0]) for row in rows}
    if tables and not tables >= _OPTUNA_TABLES:
        raise ConfigError(
            f'sweep: the storage {storage!r}: {path} is another SQLite database (tables '
            f'{sorted(tables)[:5]}), no Optuna storage: name a new file'
        )
