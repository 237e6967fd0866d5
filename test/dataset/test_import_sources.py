"""A folder source: its log files are read, its subfolders holding logs are named, not read."""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np
import pytest

from id_learning.dataset.importer import (
    ColumnSpec,
    ImportMapping,
    JointColumns,
    import_logs,
    log_files,
)
from id_learning.errors import DatasetError


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


def test_a_file_with_a_log_suffix_in_the_folder_is_read_and_refused_when_no_log(
    tmp_path: Path,
) -> None:
    # Consistent with the subfolders: nothing that looks like a log is passed over silently.
    logs = _nested(tmp_path)
    (logs / 'notes.txt').write_text('calibrated on Monday\n', encoding='utf-8')
    with pytest.raises(DatasetError, match=r'notes\.txt'):
        import_logs([logs], mapping(), tmp_path / 'bag')
