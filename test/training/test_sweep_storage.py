"""A sweep's storage: a locked SQLite file or an unreachable server is refused in bounded time."""

from __future__ import annotations

import sqlite3
import time
from pathlib import Path

import pytest

from id_learning.errors import ConfigError
from id_learning.training.sweep import _engine_options, run_sweep


def _sweep(tmp_path: Path, mabi, storage: str, timeout_s: float) -> None:
    # No bag exists: the storage is opened first, so its refusal comes before any reading.
    run_sweep([tmp_path / 'no_such_bag'], mabi, 'motor', 'rnea_lq', tmp_path / 'out', trials=1,
              storage=storage, progress=False, storage_timeout_s=timeout_s)  # fmt: skip


def test_a_locked_sqlite_storage_is_refused_after_the_timeout_naming_it(tmp_path: Path, mabi):
    path = tmp_path / 'locked.db'
    holder = sqlite3.connect(path, isolation_level=None)
    holder.execute('CREATE TABLE held (x)')
    holder.execute('BEGIN EXCLUSIVE')
    try:
        start = time.monotonic()
        with pytest.raises(
            ConfigError, match=r'locked\.db.* within 0\.5 s \(database is locked\)'
        ):
            _sweep(tmp_path, mabi, f'sqlite:///{path}', 0.5)
        waited = time.monotonic() - start
    finally:
        holder.rollback()
        holder.close()
    assert 0.5 <= waited < 5.0


def test_an_unreachable_postgresql_server_is_refused_within_the_timeout(tmp_path: Path, mabi):
    pytest.importorskip('psycopg', reason='psycopg is not installed')
    storage = 'postgresql+psycopg://nobody@127.0.0.1:9/none'  # the discard port: nothing listens
    start = time.monotonic()
    with pytest.raises(ConfigError, match=r"'postgresql\+psycopg://nobody@127\.0\.0\.1:9/none'"):
        _sweep(tmp_path, mabi, storage, 1.0)
    assert time.monotonic() - start < 10.0


def test_each_storage_kind_gets_a_bounded_connection_wait():
    assert _engine_options('sqlite:///x.db', 7.0) == {'connect_args': {'timeout': 7.0}}
    assert _engine_options('postgresql+psycopg://h/db', 0.5) == {
        'connect_args': {'connect_timeout': 2}
    }
    assert _engine_options('mysql://h/db', 7.0) == {}


@pytest.mark.parametrize(
    ('settings', 'match'),
    [
        ({'storage_timeout_s': float('nan')}, 'storage timeout'),
        ({'storage_timeout_s': 1e9}, 'storage timeout'),
        ({'max_seconds_per_trial': float('inf')}, '--max-seconds-per-trial'),
        ({'trials': True}, '--trials'),
    ],
)
def test_sweep_settings_that_are_no_finite_numbers_in_range_are_refused(
    tmp_path: Path, mabi, settings: dict, match: str
):
    values = {'trials': 1, 'progress': False, **settings}
    with pytest.raises(ConfigError, match=match):
        run_sweep([tmp_path / 'no_bag'], mabi, 'motor', 'rnea_lq', tmp_path, **values)
