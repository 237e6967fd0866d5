"""A log with standard CSV quoting ("time_ms","q1") reads exactly as the same log unquoted.

Probe I09: a log whose header names are quoted was refused. Quoting as the csv module writes
it (a quoted header, quoted numbers: ``csv.QUOTE_ALL``) is read by the csv module's rules for
every delimiter, whitespace too, and such a log in a folder is taken as a log, not as notes.
"""

from __future__ import annotations

import csv
import io
from pathlib import Path

import numpy as np
import pytest

from id_learning.bag import read_joint_states
from id_learning.dataset.import_readers import read_table
from id_learning.dataset.import_sources import log_problem
from id_learning.dataset.importer import ColumnSpec, ImportMapping, JointColumns, import_logs

HEADER = ['t_ms', 'q1', 'v1']


def mapping(**options: object) -> ImportMapping:
    joint = JointColumns('joint_1', ColumnSpec('q1', 'rad'), ColumnSpec('v1', 'rad/s'))
    return ImportMapping(joints=(joint,), time=ColumnSpec('t_ms', 'ms'), **options)  # type: ignore[arg-type]


def rows(n: int = 300) -> np.ndarray:
    t_ms = 8.0 * np.arange(n)
    q = 0.3 * np.sin(1e-3 * t_ms)
    return np.column_stack([t_ms, q, np.gradient(q, 8e-3)])


def write(path: Path, quoting: int, delimiter: str = ',') -> Path:
    """The log as the csv module writes it (numbers as their exact repr text)."""
    text = io.StringIO()
    writer = csv.writer(text, delimiter=delimiter, quoting=quoting, lineterminator='\n')
    writer.writerow(HEADER)
    writer.writerows([repr(float(x)) for x in row] for row in rows())
    path.write_text(text.getvalue(), encoding='utf-8')
    return path


def imported(source: Path, out: Path, **options: object) -> tuple[np.ndarray, ...]:
    import_logs([source], mapping(**options), out)
    states = read_joint_states(out, '/joint_states')
    assert states.velocity is not None
    return states.stamps_ns, states.position, states.velocity


@pytest.mark.parametrize('delimiter', [' ', '\t', ',', ';'])
def test_quoted_header_and_numbers_read_as_the_unquoted_log(
    tmp_path: Path, delimiter: str
) -> None:
    plain = write(tmp_path / 'plain.csv', csv.QUOTE_NONE, delimiter)
    quoted = write(tmp_path / 'quoted.csv', csv.QUOTE_ALL, delimiter)
    assert quoted.read_text().startswith(delimiter.join(f'"{name}"' for name in HEADER))
    expected = read_table(plain, mapping())
    table = read_table(quoted, mapping())
    assert list(table.columns) == HEADER
    for name in HEADER:
        np.testing.assert_array_equal(table.columns[name], expected.columns[name])
    np.testing.assert_array_equal(table.line_numbers, expected.line_numbers)


def test_a_whitespace_log_with_quoted_names_imports_the_same_samples(tmp_path: Path) -> None:
    plain = imported(write(tmp_path / 'plain.txt', csv.QUOTE_NONE, ' '), tmp_path / 'a')
    quoted = imported(write(tmp_path / 'quoted.txt', csv.QUOTE_ALL, ' '), tmp_path / 'b')
    for ours, theirs in zip(quoted, plain, strict=True):
        np.testing.assert_array_equal(ours, theirs)


def test_a_quoted_name_holding_the_delimiter_is_one_name(tmp_path: Path) -> None:
    path = tmp_path / 'log.dat'
    path.write_text('"t ms"  "q 1" "v1"\n0 0.1 0\n8 0.2 0\n', encoding='utf-8')
    table = read_table(path, mapping(delimiter='whitespace'))
    assert list(table.columns) == ['t ms', 'q 1', 'v1']
    np.testing.assert_array_equal(table.columns['q 1'], ['0.1', '0.2'])


def test_a_fully_quoted_log_in_a_folder_is_a_log_not_notes(tmp_path: Path) -> None:
    folder = tmp_path / 'logs'
    folder.mkdir()
    plain = imported(write(tmp_path / 'plain.csv', csv.QUOTE_NONE), tmp_path / 'a')
    for delimiter, name in ((',', 'a.csv'), (' ', 'b.txt')):
        assert log_problem(write(tmp_path / name, csv.QUOTE_ALL, delimiter)) is None
    write(folder / 'a.csv', csv.QUOTE_ALL)
    quoted = imported(folder, tmp_path / 'b')
    for ours, theirs in zip(quoted, plain, strict=True):
        np.testing.assert_array_equal(ours, theirs)
