"""A CSV header naming a column twice is refused only where the mapping reads that name (D04)."""

from __future__ import annotations

import logging
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from id_learning.dataset.import_readers import read_table
from id_learning.dataset.importer import ColumnSpec, ImportMapping, JointColumns
from id_learning.errors import DatasetError

MAPPING = ImportMapping(
    joints=(JointColumns('joint_1', ColumnSpec('q1', 'rad'), ColumnSpec('v1', 'rad/s')),),
    time=ColumnSpec('t', 'ms'),
)
MAPPED = ('t', 'q1', 'v1')


def _csv(path: Path, header: list[str]) -> Path:
    rows = [[str(10 * k + j) for j in range(len(header))] for k in range(3)]
    path.write_text('\n'.join(','.join(row) for row in [header, *rows]) + '\n')
    return path


def test_two_unmapped_columns_of_one_name_are_left_out_with_a_warning(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    """Probe 10's D04: two ``notes`` columns no mapping reads made the log unreadable."""
    path = _csv(tmp_path / 'log.csv', ['t', 'q1', 'v1', 'notes', 'notes'])
    with caplog.at_level(logging.WARNING):
        table = read_table(path, MAPPING)
    assert sorted(map(str, table.columns)) == ['q1', 't', 'v1']
    assert table.columns['q1'].tolist() == ['1', '11', '21']
    assert "names columns ['notes'] more than once; the mapping reads none of them" in caplog.text


def test_a_mapped_column_named_twice_is_refused_naming_it_and_where(tmp_path: Path) -> None:
    path = _csv(tmp_path / 'log.csv', ['t', 'q1', 'v1', 'q1'])
    with pytest.raises(
        DatasetError,
        match=r"the mapped column\(s\) \['q1'\] more than once \(at 0-based positions "
        r"\{'q1': \[1, 3\]\}\): which one holds the values is ambiguous",
    ):
        read_table(path, MAPPING)


@settings(max_examples=60, deadline=None)
@given(extra=st.lists(st.sampled_from(['t', 'q1', 'v1', 'notes', 'flag', 'x']), max_size=4))
def test_a_header_is_refused_exactly_when_a_mapped_name_repeats(
    tmp_path_factory: pytest.TempPathFactory, extra: list[str]
) -> None:
    header = [*MAPPED, *extra]
    path = _csv(tmp_path_factory.mktemp('csv') / 'log.csv', header)
    if any(name in MAPPED for name in extra):
        with pytest.raises(DatasetError, match='mapped column'):
            read_table(path, MAPPING)
    else:
        table = read_table(path, MAPPING)
        unique = {name for name in header if header.count(name) == 1}
        assert set(table.columns) == unique
