"""Files of one import that overlap (share rows) are refused; consecutive files are imported."""

from __future__ import annotations

import logging
import tempfile
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from id_learning.dataset.import_mapping import ResamplePolicy
from id_learning.dataset.import_overlap import MIN_SHARED_ROWS, SourceRows, shared_rows
from id_learning.dataset.importer import ColumnSpec, ImportMapping, JointColumns, import_logs
from id_learning.errors import ConfigError

N_ROWS = 300
COLUMNS = ('t_ms', 'q1', 'q2', 'v1', 'v2', 'i1', 'i2')


def mapping() -> ImportMapping:
    joints = tuple(
        JointColumns(
            f'joint_{j}',
            ColumnSpec(f'q{j}', 'deg'),
            ColumnSpec(f'v{j}', 'deg/s'),
            current=ColumnSpec(f'i{j}', 'A'),
        )
        for j in (1, 2)
    )
    return ImportMapping(joints=joints, time=ColumnSpec('t_ms', 'ms'))


def log_values(seed: int = 0, n: int = N_ROWS) -> np.ndarray:
    """(n, 7) rows of one log: time [ms] on an 8 ms grid, a smooth motion, noisy currents."""
    rng = np.random.default_rng(seed)
    t_s = 0.008 * np.arange(n)
    phase = 2 * np.pi * 0.5 * t_s + seed
    q = np.column_stack([37.0 + 2.0 * np.sin(phase), -20.0 + 3.0 * np.cos(phase)])
    v = np.column_stack([2 * np.pi * np.cos(phase), -3 * np.pi * np.sin(phase)])
    i = rng.normal(0.0, 0.5, size=(n, 2))
    return np.column_stack([1000.0 * t_s, q, v, i])


def write_csv(path: Path, rows: np.ndarray) -> Path:
    lines = [','.join(COLUMNS)] + [','.join(repr(float(x)) for x in row) for row in rows]
    path.write_text('\n'.join(lines) + '\n', encoding='utf-8')
    return path


@settings(max_examples=25, deadline=None, derandomize=True)
@given(cut=st.integers(60, 240), overlap=st.integers(-40, 60))
def test_a_log_cut_into_two_files_is_refused_exactly_when_they_share_enough_rows(
    cut: int, overlap: int
) -> None:
    rows = log_values()
    with tempfile.TemporaryDirectory() as folder:
        first = write_csv(Path(folder) / 'first.csv', rows[:cut])
        second = write_csv(Path(folder) / 'second.csv', rows[cut - overlap :])
        if overlap >= MIN_SHARED_ROWS:
            # Lines count from 2 (the header is line 1): row k is on line k + 2.
            with pytest.raises(
                ConfigError,
                match=rf'import: .*second\.csv lines 2-{overlap + 1} repeat {overlap} rows of '
                rf'.*first\.csv lines {cut - overlap + 2}-{cut + 1} \(time column t_ms '
                rf'{8 * (cut - overlap)} to {8 * (cut - 1)}\): the files overlap',
            ):
                import_logs([first, second], mapping(), Path(folder) / 'bag')
            assert not (Path(folder) / 'bag').exists()
        else:  # consecutive files, a gap between them, or a few rows repeated at the seam
            reports = import_logs([first, second], mapping(), Path(folder) / 'bag')
            assert [r.n_rows_written for r in reports] == [cut, N_ROWS - cut + overlap]


def test_a_few_rows_repeated_at_a_file_change_are_imported_with_a_warning_naming_them(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    rows = log_values()
    first = write_csv(tmp_path / 'first.csv', rows[:150])
    second = write_csv(tmp_path / 'second.csv', rows[149:])  # the logger repeats one row
    with caplog.at_level(logging.WARNING, logger='id_learning.dataset'):
        import_logs([first, second], mapping(), tmp_path / 'bag')
    warnings = [r.getMessage() for r in caplog.records if r.levelno == logging.WARNING]
    assert warnings == [
        f'import: {second} line 2 repeats 1 row of {first} line 151 (time column t_ms 1192 to '
        '1192): these samples are in the bag twice; cut them from one file'
    ]


def test_shared_rows_are_found_whatever_the_time_column_says(tmp_path: Path) -> None:
    # An export that re-based its piece of the log to 0 s still holds the same samples.
    rows = log_values()
    first = write_csv(tmp_path / 'first.csv', rows[:200])
    piece = rows[100:].copy()
    piece[:, 0] -= piece[0, 0]
    second = write_csv(tmp_path / 'second.csv', piece)
    with pytest.raises(
        ConfigError,
        match=r'second\.csv lines 2-101 repeat 100 rows of .*first\.csv lines 102-201 \(time '
        r'column t_ms 0 to 792 there, 800 to 1592 in first\.csv\)',
    ):
        import_logs([first, second], mapping(), tmp_path / 'bag')


def test_two_recordings_at_the_same_times_and_at_rest_share_no_row(tmp_path: Path) -> None:
    # Two logs of their own, both starting at 0 ms from one rest pose: distinct recordings.
    first, second = log_values(seed=1), log_values(seed=2)
    first[:50, 1:5] = second[:50, 1:5] = [37.0, -20.0, 0.0, 0.0]  # at rest, currents differ
    paths = [write_csv(tmp_path / f'{k}.csv', rows) for k, rows in enumerate((first, second))]
    reports = import_logs(paths, mapping(), tmp_path / 'bag')
    assert [r.n_rows_written for r in reports] == [N_ROWS, N_ROWS]


def test_a_still_arm_repeating_itself_is_no_shared_row() -> None:
    still = {'position': np.zeros((20, 2)), 'velocity': np.zeros((20, 2))}
    files = [
        SourceRows(Path(name), 'line', np.arange(20), None, still) for name in ('a.csv', 'b.csv')
    ]
    assert shared_rows(files) == {}


def test_npz_rows_are_named_by_their_index(tmp_path: Path) -> None:
    rows = log_values()
    first = write_csv(tmp_path / 'first.csv', rows[:200])
    second = tmp_path / 'second.npz'
    np.savez(second, **{name: rows[180:, k] for k, name in enumerate(COLUMNS)})
    with pytest.raises(
        ConfigError, match=r'second\.npz rows 0-19 repeat 20 rows of .*first\.csv lines 182-201'
    ):
        import_logs([first, second], mapping(), tmp_path / 'bag')


def test_two_logs_of_one_motion_at_other_rates_are_no_overlap(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    # Logged at 10 and 12 ms, they meet every 60 ms (the same sample at the same instant), but
    # at ever other rows: no stretch of one file is in the other. One such row is named.
    paths = []
    for step_ms in (10.0, 12.0):
        t_ms = 5000.0 + step_ms * np.arange(200)
        phase = 2 * np.pi * 0.5 * 1e-3 * t_ms[:, None] + np.arange(2)
        rows = np.column_stack([t_ms, 20 * np.sin(phase), 20 * np.cos(phase), np.sin(3 * phase)])
        paths.append(write_csv(tmp_path / f'{step_ms:g}ms.csv', rows))
    grid = ResamplePolicy(method='interpolate', period_s=0.008)
    with caplog.at_level(logging.WARNING, logger='id_learning.dataset'):
        reports = import_logs(paths, replace(mapping(), resample=grid), tmp_path / 'bag')
    assert len(reports) == 2
    warnings = [r.getMessage() for r in caplog.records if r.levelno == logging.WARNING]
    assert len(warnings) == 1
    assert 'repeats 1 row of' in warnings[0]
