"""A folder source: its log files are read; its subfolders holding logs and notes beside the
logs are named, not read."""

from __future__ import annotations

import gzip
import logging
import shutil
from pathlib import Path

import numpy as np
import pytest

from id_learning.dataset.import_sources import log_problem
from id_learning.dataset.importer import (
    ColumnSpec,
    ImportMapping,
    JointColumns,
    import_logs,
    log_files,
)
from id_learning.errors import ConfigError, DatasetError


def mapping() -> ImportMapping:
    joint = JointColumns('joint_1', ColumnSpec('q1', 'rad'), ColumnSpec('v1', 'rad/s'))
    return ImportMapping(joints=(joint,), time=ColumnSpec('t_ms', 'ms'))


def log_values(seed: int = 0, n: int = 300) -> np.ndarray:
    """(n, 3) rows: time [ms] on an 8 ms grid, a position and a noisy velocity."""
    t_ms = 8.0 * np.arange(n)
    noise = np.random.default_rng(seed).normal(0.0, 0.01, n)
    return np.column_stack([t_ms, 0.3 * np.sin(1e-3 * t_ms + seed), noise])


def write_csv(path: Path, rows: np.ndarray) -> Path:
    lines = ['t_ms,q1,v1'] + [','.join(repr(float(x)) for x in row) for row in rows]
    path.write_text('\n'.join(lines) + '\n', encoding='utf-8')
    return path


def _nested(tmp_path: Path) -> Path:
    """logs/a.csv, logs/sub/b.csv (the log's second half), logs/sub/deeper/c.csv, a README."""
    rows = log_values()
    logs = tmp_path / 'logs'
    (logs / 'sub' / 'deeper').mkdir(parents=True)
    write_csv(logs / 'a.csv', rows[:150])
    write_csv(logs / 'sub' / 'b.csv', rows[150:])
    write_csv(logs / 'sub' / 'deeper' / 'c.csv', log_values(seed=3))
    (logs / 'README.md').write_text('logs of the arm\n', encoding='utf-8')
    (logs / 'plots').mkdir()
    (logs / 'plots' / 'q.png').write_bytes(b'\x89PNG')
    return logs


def _warnings(caplog: pytest.LogCaptureFixture) -> list[str]:
    return [r.getMessage() for r in caplog.records if r.levelno == logging.WARNING]


def test_a_subfolder_holding_logs_is_named_in_a_warning_and_not_read(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    logs = _nested(tmp_path)
    with caplog.at_level(logging.WARNING, logger='id_learning.dataset'):
        reports = import_logs([logs], mapping(), tmp_path / 'bag')
    assert [r.source for r in reports] == [logs / 'a.csv']
    # One line: the subfolder with its log files (also those further down); no word of the
    # README or of a folder without logs.
    assert _warnings(caplog) == [
        f'{logs}: skipped 1 subfolder holding log files: sub/ (2 log files); a folder is read '
        f'without its subfolders: give a subfolder as a source too (e.g. {logs / "sub"}) to '
        'import its logs'
    ]


def test_a_subfolder_given_as_a_source_too_is_read_without_a_warning(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    logs = _nested(tmp_path)
    with caplog.at_level(logging.WARNING, logger='id_learning.dataset'):
        files = log_files([logs, logs / 'sub'])
    assert files == [logs / 'a.csv', logs / 'sub' / 'b.csv']
    assert _warnings(caplog) == [
        f'{logs / "sub"}: skipped 1 subfolder holding log files: deeper/ (1 log file); a folder '
        f'is read without its subfolders: give a subfolder as a source too (e.g. '
        f'{logs / "sub" / "deeper"}) to import its logs'
    ]


def test_a_folder_whose_logs_are_all_in_subfolders_is_refused_saying_so(tmp_path: Path) -> None:
    logs = _nested(tmp_path)
    (logs / 'a.csv').unlink()
    with pytest.raises(
        DatasetError,
        match=r'logs: no log files \(.*\) in this folder; 2 in its subfolders: give those as '
        'sources',
    ):
        log_files([logs])


def test_notes_with_a_log_suffix_beside_the_logs_are_named_and_skipped(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    logs = _nested(tmp_path)
    (logs / 'README.txt').write_text('Logs of the arm, run 2 of 3.\nSee the wiki.\n')
    (logs / 'notes.log').write_text('10:02 started\n10:07 stopped at 50 %\n')
    with caplog.at_level(logging.WARNING, logger='id_learning.dataset'):
        reports = import_logs([logs], mapping(), tmp_path / 'bag')
    assert [r.source for r in reports] == [logs / 'a.csv']
    skipped = [w for w in _warnings(caplog) if 'read as no log' in w]
    assert skipped == [
        f'{logs}: skipped 2 files that read as no log: README.txt (no table of numbers in its '
        'first 2 lines); notes.log (no table of numbers in its first 2 lines); give a file as a '
        'source itself to have it read as a log'
    ]


def test_a_folder_of_notes_only_is_refused_naming_each_file(tmp_path: Path) -> None:
    folder = tmp_path / 'logs'
    folder.mkdir()
    (folder / 'README.txt').write_text('calibrated on Monday\n', encoding='utf-8')
    (folder / 'empty.csv').write_text('\n', encoding='utf-8')
    with pytest.raises(DatasetError) as refused:
        log_files([folder])
    assert str(refused.value) == (
        f'{folder}: no file in this folder reads as a log: README.txt (no table of numbers in '
        'its one line); empty.csv (empty); give the log files themselves as sources to have '
        'them read as logs'
    )


def test_a_notes_file_given_itself_is_read_and_refused_naming_it(tmp_path: Path) -> None:
    notes = tmp_path / 'notes.txt'
    notes.write_text('calibrated on Monday\n', encoding='utf-8')
    assert log_files([notes]) == [notes]  # no judgement on a file named as a source
    with pytest.raises((DatasetError, ConfigError), match=r'notes\.txt'):
        import_logs([notes], mapping(), tmp_path / 'bag')


def test_a_subfolder_of_notes_is_not_named_as_holding_logs(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    logs = _nested(tmp_path)
    shutil.rmtree(logs / 'sub')
    (logs / 'docs').mkdir()
    (logs / 'docs' / 'README.txt').write_text('how the logs were taken\n', encoding='utf-8')
    with caplog.at_level(logging.WARNING, logger='id_learning.dataset'):
        assert log_files([logs]) == [logs / 'a.csv']
    assert _warnings(caplog) == []


@pytest.mark.parametrize(
    'text',
    [
        't_ms,q1,v1\n0,0.1,0.0\n8,0.2,0.1\n',
        '# exported by the controller\n# units: ms, rad\n\n0 0.1 0.0\n8 0.2 0.1\n',
        't\tq1\tv1\n0\t0,1\t0,0\n8\t0,2\t0,1\n',  # decimal commas, tabs
        'time;q1;state\n0;0,1;RUN\n8;0,2;RUN\n',  # a text column beside the numbers
        't,q1,v1\n0,0.1,\n8,,0.1\n16,0.3,0.2\n',  # empty cells
    ],
)
def test_a_table_of_numbers_reads_as_a_log(tmp_path: Path, text: str) -> None:
    path = tmp_path / 'log.txt'
    path.write_text(text, encoding='utf-8')
    assert log_problem(path) is None
    packed = tmp_path / 'log.csv.gz'
    packed.write_bytes(gzip.compress(text.encode()))
    assert log_problem(packed) is None


@pytest.mark.parametrize(
    ('data', 'problem'),
    [
        (b'Run 1 at 50 %\nRun 2 at 80 %\n', 'no table of numbers in its first 2 lines'),
        (b'0 0.1 0.2\n', 'no table of numbers in its one line'),  # one row is no table
        (b'', 'empty'),
        (b'\x00\x01\x02\x03' * 64, 'binary, no text'),
    ],
)
def test_notes_an_empty_or_a_binary_file_read_as_no_log(
    tmp_path: Path, data: bytes, problem: str
) -> None:
    path = tmp_path / 'notes.log'
    path.write_bytes(data)
    found = log_problem(path)
    assert found is not None
    assert found.startswith(problem)
