"""A sweep storage the sweep does not own is refused before anything is written to it.

Probe 15 (A56): ``sqlite:///BAG/sweep.db`` (inside a bag), ``sqlite:///RUN/sweep.db`` (inside a
train result) and a user's own SQLite file with a ``measurements`` table were all taken without
a word: Optuna added its tables to the user's database, and its file to the bag and the run.
"""

from __future__ import annotations

import sqlite3
from pathlib import Path

import optuna
import pytest

from id_learning.errors import ConfigError, IdLearningError
from id_learning.training.sweep import run_sweep


def _sweep(tmp_path: Path, mabi, storage: str) -> None:
    # No bag exists: the storage is checked first, so its refusal comes before any reading.
    run_sweep([tmp_path / 'no_such_bag'], mabi, 'motor', 'rnea_lq', tmp_path / 'out', trials=1,
              storage=storage, progress=False, storage_timeout_s=10.0)  # fmt: skip


@pytest.mark.parametrize(
    ('files', 'what', 'below'),
    [
        (['metadata.yaml', 'x_0.mcap'], 'a bag', ''),
        (['run.json', 'report.md'], 'a train run', ''),
        (['run.json', 'report.md'], 'a train run', 'models'),  # a bag has no folders
    ],
)
def test_a_database_inside_a_bag_or_a_run_is_refused(
    tmp_path: Path, mabi, files: list[str], what: str, below: str
) -> None:
    owned = tmp_path / 'owned'
    (owned / below).mkdir(parents=True, exist_ok=True)
    for name in files:
        (owned / name).write_text('{}\n')
    before = sorted(p.relative_to(owned) for p in owned.rglob('*'))
    storage = owned / below / 'sweep.db'
    with pytest.raises(ConfigError, match=rf'lies inside {owned}, which holds {what} '):
        _sweep(tmp_path, mabi, f'sqlite:///{storage}')
    assert sorted(p.relative_to(owned) for p in owned.rglob('*')) == before


def test_a_second_worker_joins_the_first_ones_default_storage(tmp_path: Path, mabi) -> None:
    first = tmp_path / 'first'
    first.mkdir()
    optuna.create_study(study_name='shared', storage=f'sqlite:///{first / "sweep.db"}')
    (first / 'best.yaml').write_text('{}\n')
    with pytest.raises(IdLearningError, match='no_such_bag'):  # after the storage opened
        _sweep(tmp_path, mabi, f'sqlite:///{first / "sweep.db"}')


def test_another_programs_sqlite_database_is_refused_and_left_as_it_was(
    tmp_path: Path, mabi
) -> None:
    path = tmp_path / 'user.db'
    with sqlite3.connect(path) as db:
        db.execute('CREATE TABLE measurements (t REAL, value REAL)')
        db.execute('INSERT INTO measurements VALUES (0.0, 1.5)')
    before = path.read_bytes()
    with pytest.raises(
        ConfigError, match=r"user\.db is another SQLite database \(tables \['measurements'\]\)"
    ):
        _sweep(tmp_path, mabi, f'sqlite:///{path}')
    assert path.read_bytes() == before


def test_a_file_that_is_no_sqlite_database_is_refused(tmp_path: Path, mabi) -> None:
    path = tmp_path / 'notes.db'
    path.write_text('my notes\n')
    with pytest.raises(ConfigError, match=r'notes\.db is no SQLite database'):
        _sweep(tmp_path, mabi, f'sqlite:///{path}')
    assert path.read_text() == 'my notes\n'


def test_an_optuna_storage_and_an_empty_file_are_taken(tmp_path: Path, mabi) -> None:
    existing = tmp_path / 'shared.db'
    optuna.create_study(study_name='other', storage=f'sqlite:///{existing}')
    (tmp_path / 'empty.db').touch()
    for path in (existing, tmp_path / 'empty.db'):
        with pytest.raises(IdLearningError, match='no_such_bag'):  # after the storage opened
            _sweep(tmp_path, mabi, f'sqlite:///{path}')
        tables = {
            row[0] for row in sqlite3.connect(path).execute('SELECT name FROM sqlite_master')
        }
        assert 'studies' in tables
