"""``header: true`` over a CSV whose first row holds numbers only: said as a missing header.

Before, the first data row was read as column names and the error spoke of names given twice.
"""

from __future__ import annotations

from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from id_learning.dataset.import_readers import read_table
from id_learning.dataset.importer import ColumnSpec, ImportMapping, JointColumns
from id_learning.errors import DatasetError


def mapping(
    header: bool | str, time: str | int = 't', position: str | int = 'q1'
) -> ImportMapping:
    joint = JointColumns('joint_1', ColumnSpec(position, 'rad'))
    return ImportMapping(joints=(joint,), time=ColumnSpec(time, 'ms'), header=header)  # type: ignore[arg-type]


numbers = st.lists(
    st.floats(-1e6, 1e6, allow_nan=False).map(repr) | st.integers(-99, 99).map(str),
    min_size=2,
    max_size=6,
)


@settings(max_examples=30)
@given(rows=st.lists(numbers, min_size=2, max_size=5))
def test_a_numeric_first_row_under_header_true_is_no_header(
    tmp_path_factory: pytest.TempPathFactory, rows: list[list[str]]
) -> None:
    width = len(rows[0])
    rows = [row[:width] + ['0'] * (width - len(row)) for row in rows]
    path = tmp_path_factory.mktemp('csv') / 'log.csv'
    path.write_text('# exported\n' + '\n'.join(','.join(row) for row in rows) + '\n')
    with pytest.raises(DatasetError, match=r'the mapping says header: true, but line 2, the '
                       r'first row, holds only numbers .*set header: false') as err:  # fmt: skip
        read_table(path, mapping(True))
    assert 'more than once' not in str(err.value)
    table = read_table(path, mapping(False, 0, 1))  # the same file read without a header
    assert len(table.columns[0]) == len(rows)


def test_a_header_row_of_the_mapped_names_is_a_header(tmp_path: Path) -> None:
    path = tmp_path / 'log.csv'
    path.write_text('t,q1\n0,0.1\n8,0.2\n')
    assert list(read_table(path, mapping(True)).columns) == ['t', 'q1']
    numeric = tmp_path / 'numeric.csv'  # names that are numbers, all of them mapped: a header
    numeric.write_text('1,2\n0,0.1\n8,0.2\n')
    assert list(read_table(numeric, mapping(True, '1', '2')).columns) == ['1', '2']
