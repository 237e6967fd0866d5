"""Import faults of a CSV log's shape: fields longer than the csv module's default limit, rows
torn short, a body split by another delimiter than its header (or a decimal comma), and a YAML
mapping given as the log.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from id_learning.bag import read_joint_states
from id_learning.dataset.import_readers import MAX_LINE_CHARS, read_table
from id_learning.dataset.importer import ColumnSpec, ImportMapping, JointColumns, import_log
from id_learning.errors import DatasetError

N_ROWS = 40
COLUMNS = ('t_ms', 'q1', 'q2', 'note')


def mapping(**options: object) -> ImportMapping:
    """Time [ms] in 't_ms'; joint j's position [deg] in 'q<j>'; 'note' is not read."""
    joints = tuple(JointColumns(f'joint_{j}', ColumnSpec(f'q{j}', 'deg')) for j in (1, 2))
    return ImportMapping(joints=joints, time=ColumnSpec('t_ms', 'ms'), **options)  # type: ignore[arg-type]


def rows() -> list[list[str]]:
    t_ms = 8.0 * np.arange(N_ROWS)
    q1 = 37.0 + 2.0 * np.sin(t_ms / 300.0)
    q2 = -20.0 + 3.0 * np.cos(t_ms / 300.0)
    return [
        [repr(float(a)), repr(float(b)), repr(float(c)), 'x']
        for a, b, c in zip(t_ms, q1, q2, strict=True)
    ]


def write(path: Path, body: list[list[str]], delimiter: str = ',', header: str = '') -> Path:
    lines = [header or delimiter.join(COLUMNS)] + [delimiter.join(row) for row in body]
    path.write_text('\n'.join(lines) + '\n', encoding='utf-8')
    return path


# -- 1: fields over csv's default field_size_limit (131072) ---------------------------------------
@pytest.mark.parametrize('row', [0, 2, N_ROWS - 1])
@pytest.mark.parametrize('quoted', [False, True])
def test_a_200_kb_unmapped_field_imports_the_mapped_columns(
    tmp_path: Path, row: int, quoted: bool
) -> None:
    body = rows()
    long = 'n' * 200_000
    body[row][3] = f'"{long}"' if quoted else long
    path = write(tmp_path / 'log.csv', body)
    table = read_table(path, mapping())
    assert table.columns['note'][row] == long
    np.testing.assert_array_equal(table.columns['q1'].astype(float), [float(r[1]) for r in rows()])
    import_log(path, mapping(), tmp_path / 'bag')
    states = read_joint_states(tmp_path / 'bag', '/joint_states')
    np.testing.assert_allclose(states.position[:, 0], np.deg2rad([float(r[1]) for r in rows()]))


def test_a_long_header_line_is_read_not_a_traceback(tmp_path: Path) -> None:
    extra = [f'extra_{k}' for k in range(30_000)]  # ~300 KB, one field when sniffed by tab
    header = ','.join([*COLUMNS, *extra])
    body = [row + [''] * len(extra) for row in rows()[:5]]
    table = read_table(write(tmp_path / 'log.csv', body, header=header), mapping())
    assert 'extra_29999' in table.columns
    assert table.columns['t_ms'][4] == rows()[4][0]


def test_a_line_beyond_the_bound_is_refused_in_one_line(tmp_path: Path) -> None:
    body = rows()
    body[3][3] = 'n' * (MAX_LINE_CHARS + 1)
    path = write(tmp_path / 'log.csv', body)
    with pytest.raises(
        DatasetError, match=r'log\.csv: line 5 has .* characters, more than'
    ) as err:
        read_table(path, mapping())
    assert '\n' not in str(err.value)
    assert len(str(err.value)) < 1000


def test_a_long_quoted_field_left_open_is_refused_at_its_line_in_one_short_line(
    tmp_path: Path,
) -> None:
    path = tmp_path / 'log.csv'
    path.write_text('t_ms,q1,q2\n0,1,2\n1,2,"' + 'n' * 200_000 + '\n', encoding='utf-8')
    with pytest.raises(DatasetError, match=r'line 3: a quoted field opens here and is not') as err:
        read_table(path, mapping(delimiter=','))
    assert len(str(err.value)) < 1000


# -- 2: a row with fewer cells than the header ----------------------------------------------------
@pytest.mark.parametrize('nan_policy', ['refuse', 'drop'])
def test_a_torn_row_is_refused_as_such_whatever_the_nan_policy(
    tmp_path: Path, nan_policy: str
) -> None:
    body = rows()
    body[10] = body[10][:2]
    path = write(tmp_path / 'log.csv', body)
    with pytest.raises(
        DatasetError, match=r'log\.csv: line 12 has 2 cells, 2 fewer than the 4 of the header'
    ):
        import_log(path, mapping(nan_policy=nan_policy), tmp_path / 'bag')


def test_empty_trailing_cells_still_pass(tmp_path: Path) -> None:
    body = [[*row, ''] for row in rows()]
    path = write(tmp_path / 'log.csv', body, header=','.join(COLUMNS) + ',')
    body[5] = body[5][:4]  # this row lacks the trailing empty cell only
    assert read_table(write(path, body, header=','.join(COLUMNS) + ','), mapping()).columns


# -- 3: mixed delimiters, a decimal comma ---------------------------------------------------------
def test_a_body_split_by_another_delimiter_than_its_header_is_hinted(tmp_path: Path) -> None:
    path = tmp_path / 'log.csv'
    lines = [','.join(COLUMNS)] + [';'.join(row) for row in rows()]
    path.write_text('\n'.join(lines) + '\n', encoding='utf-8')
    with pytest.raises(
        DatasetError, match=r"line 2 has 1 cells.*the header is split by ',' but line 2 by ';'\?"
    ):
        read_table(path, mapping(delimiter=','))


def test_a_decimal_comma_split_by_comma_is_hinted(tmp_path: Path) -> None:
    body = [[cell.replace('.', ',') for cell in row] for row in rows()]
    path = write(tmp_path / 'log.csv', body, delimiter=';')
    with pytest.raises(
        DatasetError,
        match=r"line 2 has 4 cells.*the header and line 2 split by ';' into 4 cells: set "
        r"delimiter: ';' \(a decimal comma\?\)",
    ):
        read_table(path, mapping(delimiter=','))


def test_a_decimal_comma_with_semicolons_is_named_not_just_no_number(tmp_path: Path) -> None:
    body = [[cell.replace('.', ',') for cell in row] for row in rows()]
    path = write(tmp_path / 'log.csv', body, delimiter=';')
    with pytest.raises(
        DatasetError, match=r"line 2, column 'q1': '37,0' is not a number: a decimal comma\?"
    ):
        import_log(path, mapping(), tmp_path / 'bag')


# -- 4: a mapping (YAML) given as the log ---------------------------------------------------------
def test_a_yaml_file_given_as_the_log_is_named_a_mapping_not_a_log(tmp_path: Path) -> None:
    path = tmp_path / 'mapping.yaml'
    path.write_text(
        'time:\n  column: t_ms\n  unit: ms\njoints:\n  - name: joint_1\n    position:\n'
        '      column: q1\n      unit: deg\n',
        encoding='utf-8',
    )
    said = r': this looks like a mapping or other YAML/JSON file \(%s\), not a log'
    with pytest.raises(DatasetError, match=r'mapping\.yaml' + said % "its suffix is '.yaml'"):
        import_log(path, mapping(format='csv'), tmp_path / 'bag')
    with pytest.raises(DatasetError, match=r'mapping\.yaml: a YAML/JSON file \(a mapping\?\)'):
        read_table(path, mapping())
    renamed = path.rename(tmp_path / 'mapping.txt')
    with pytest.raises(
        DatasetError,
        match=r'mapping\.txt' + said % "its first line reads 'time:', a YAML key: value",
    ):
        import_log(renamed, mapping(), tmp_path / 'bag')
    assert not (tmp_path / 'bag').exists()
