"""Import faults: a column mapped twice, one log given twice in other bytes, float16 arrays,
and files whose format is not the one they are read as (an NPZ as CSV, gzip-compressed logs).
"""

from __future__ import annotations

import gzip
import logging
import shutil
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
import yaml

from id_learning.bag import read_joint_states
from id_learning.dataset.importer import (
    ColumnSpec,
    ImportMapping,
    JointColumns,
    import_log,
    import_logs,
    load_import_mapping,
)
from id_learning.errors import ConfigError, DatasetError

REPO = Path(__file__).resolve().parents[2]
EXAMPLE_MAPPING = REPO / 'config/import_example.yaml'
N_ROWS = 40
COLUMNS = ('t_ms', 'q1', 'q2', 'v1', 'v2')


def mapping(unit: str = 'deg', **options: object) -> ImportMapping:
    """Time [ms] in 't_ms'; joint j's position in 'q<j>' [unit], velocity in 'v<j>' [unit/s]."""
    joints = tuple(
        JointColumns(f'joint_{j}', ColumnSpec(f'q{j}', unit), ColumnSpec(f'v{j}', f'{unit}/s'))
        for j in (1, 2)
    )
    return ImportMapping(joints=joints, time=ColumnSpec('t_ms', 'ms'), **options)  # type: ignore[arg-type]


def log_values(seed: int = 0) -> dict[str, np.ndarray]:
    """One smooth motion of two joints around 37 deg, 8 ms steps, by column name."""
    t_s = 0.008 * np.arange(N_ROWS)
    phase = 2 * np.pi * 0.5 * t_s + seed
    return {
        't_ms': 1000.0 * t_s,
        'q1': 37.0 + 2.0 * np.sin(phase),
        'q2': -20.0 + 3.0 * np.cos(phase),
        'v1': 2.0 * np.pi * np.cos(phase),
        'v2': -3.0 * np.pi * np.sin(phase),
    }


def write_csv(
    path: Path,
    values: dict[str, np.ndarray],
    cell: Callable[[float], str] = repr,
    newline: str = '\n',
) -> Path:
    """A CSV of the columns, each value written by ``cell`` (exact ``repr`` by default)."""
    rows = np.column_stack([values[name] for name in COLUMNS])
    lines = [','.join(COLUMNS)] + [','.join(cell(float(x)) for x in row) for row in rows]
    path.write_bytes((newline.join(lines) + newline).encode())
    return path


# -- R10: one column mapped to two fields ---------------------------------------------------------
def test_one_current_column_mapped_to_two_joints_is_refused_at_load(tmp_path: Path) -> None:
    spec = yaml.safe_load(EXAMPLE_MAPPING.read_text(encoding='utf-8'))
    spec['joints'][1]['current']['column'] = 'i1_a'
    path = tmp_path / 'mapping.yaml'
    path.write_text(yaml.safe_dump(spec), encoding='utf-8')
    with pytest.raises(
        ConfigError,
        match=r"mapping\.yaml: column 'i1_a' is mapped twice \(joint_1 current, joint_2 current\)",
    ):
        load_import_mapping(path)


@pytest.mark.parametrize(
    ('joint', 'uses'),
    [
        (JointColumns('a', ColumnSpec('t', 'rad')), 'time, a position'),
        (
            JointColumns('a', ColumnSpec('q', 'rad'), ColumnSpec('q', 'rad/s')),
            'a position, a velocity',
        ),
        (
            JointColumns('a', ColumnSpec('q', 'rad'), torque=ColumnSpec('q', 'Nm')),
            'a position, a torque',
        ),
    ],
)
def test_a_column_mapped_to_two_quantities_is_refused_naming_both(
    joint: JointColumns, uses: str
) -> None:
    with pytest.raises(ConfigError, match=rf"column '(t|q)' is mapped twice \({uses}\)"):
        ImportMapping(joints=(joint,), time=ColumnSpec('t', 'ms'))


def test_one_npz_array_is_mapped_once_per_index() -> None:
    def joints(second: int) -> tuple[JointColumns, ...]:
        return tuple(
            JointColumns(name, ColumnSpec('q', 'rad', index=k))
            for name, k in (('a', 0), ('b', second))
        )

    assert len(ImportMapping(joints=joints(1), period_s=0.008).joints) == 2
    with pytest.raises(
        ConfigError, match=r"column 'q'\[:, 0\] is mapped twice \(a position, b position\)"
    ):
        ImportMapping(joints=joints(0), period_s=0.008)


# -- R11: one log given twice ---------------------------------------------------------------------
def test_a_byte_identical_copy_is_refused_before_reading(tmp_path: Path) -> None:
    good = write_csv(tmp_path / 'good.csv', log_values())
    copy = tmp_path / 'copy.csv'
    shutil.copy(good, copy)
    with pytest.raises(
        ConfigError, match=r'import: .*copy\.csv holds the same data as .*good\.csv'
    ):
        import_logs([good, copy], mapping(), tmp_path / 'bag')
    assert not (tmp_path / 'bag').exists()


def _crlf(path: Path, values: dict[str, np.ndarray]) -> Path:
    return write_csv(path.with_suffix('.csv'), values, newline='\r\n')


def _other_float_text(path: Path, values: dict[str, np.ndarray]) -> Path:
    return write_csv(path.with_suffix('.csv'), values, cell=lambda x: f'{x:.17e}')


def _npz_export(path: Path, values: dict[str, np.ndarray]) -> Path:
    np.savez(path.with_suffix('.npz'), **values)
    return path.with_suffix('.npz')


def _gzipped(path: Path, values: dict[str, np.ndarray]) -> Path:
    plain = write_csv(path.with_suffix('.csv'), values)
    packed = path.with_suffix('.csv.gz')
    packed.write_bytes(gzip.compress(plain.read_bytes()))
    plain.unlink()
    return packed


def _time_shifted(path: Path, values: dict[str, np.ndarray]) -> Path:
    return write_csv(path.with_suffix('.csv'), {**values, 't_ms': values['t_ms'] + 5000.0})


@pytest.mark.parametrize(
    'write_copy', [_crlf, _other_float_text, _npz_export, _gzipped, _time_shifted]
)
def test_the_same_samples_in_other_bytes_are_refused_naming_both_files(
    tmp_path: Path, write_copy: Callable[[Path, dict[str, np.ndarray]], Path]
) -> None:
    values = log_values()
    good = write_csv(tmp_path / 'good.csv', values)
    copy = write_copy(tmp_path / 'copy', values)
    assert copy.read_bytes() != good.read_bytes()
    with pytest.raises(
        ConfigError,
        match=rf'import: .*{copy.name} holds the same samples as .*good\.csv \({N_ROWS} samples, '
        r'stamps and values identical after parsing\); give each recording once',
    ):
        import_logs([good, copy], mapping(), tmp_path / 'bag')
    assert not (tmp_path / 'bag').exists()


def test_a_copy_edited_in_one_value_is_refused_for_the_rows_it_still_shares(
    tmp_path: Path,
) -> None:
    values = log_values()
    good = write_csv(tmp_path / 'good.csv', values)
    other = {**values, 'q2': values['q2'].copy()}
    other['q2'][17] += 1e-9
    edited = write_csv(tmp_path / 'other.csv', other)
    # Not identical (one sample differs), but the other 39 samples would be in the bag twice.
    with pytest.raises(
        ConfigError,
        match=rf'import: .*other\.csv lines 2-41 repeat {N_ROWS - 1} rows of .*good\.csv lines '
        r'2-41 \(time column t_ms 0 to 312\): the files overlap',
    ):
        import_logs([good, edited], mapping(), tmp_path / 'bag')
    # Two recordings of their own (another motion at the same times) are two segments.
    own = write_csv(tmp_path / 'own.csv', log_values(seed=1))
    reports = import_logs([good, own], mapping(), tmp_path / 'bag')
    assert [r.n_rows_written for r in reports] == [N_ROWS, N_ROWS]


# -- R12: float16 arrays --------------------------------------------------------------------------
def test_a_float16_array_is_imported_with_one_warning_naming_its_resolution(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    values = log_values()
    arrays = {**values, 'q1': values['q1'].astype(np.float16)}
    np.savez(tmp_path / 'half.npz', **arrays)
    with caplog.at_level(logging.WARNING, logger='id_learning'):
        import_log(tmp_path / 'half.npz', mapping(), tmp_path / 'bag')
    warnings = [r.getMessage() for r in caplog.records if r.levelno == logging.WARNING]
    assert len(warnings) == 1, warnings
    largest = float(np.abs(arrays['q1']).max())
    assert warnings[0] == (
        f"{tmp_path / 'half.npz'}: array 'q1' is float16: at its largest magnitude "
        f'{largest:.4g} deg it resolves only 0.0312 deg; store it as float32 or float64'
    )
    states = read_joint_states(tmp_path / 'bag', '/joint_states')
    assert states.position is not None
    np.testing.assert_allclose(states.position[:, 0], np.radians(arrays['q1'].astype(float)))


def test_a_2d_float16_array_warns_once_and_float32_is_silent(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    values = log_values()
    q = np.column_stack([values['q1'], values['q2']])
    np.savez(tmp_path / 'half.npz', t=values['t_ms'], q=q.astype(np.float16))
    np.savez(tmp_path / 'single.npz', t=values['t_ms'], q=q.astype(np.float32))
    joints = tuple(JointColumns(f'joint_{k}', ColumnSpec('q', 'deg', index=k)) for k in (0, 1))
    indexed = ImportMapping(joints=joints, time=ColumnSpec('t', 'ms'))
    with caplog.at_level(logging.WARNING, logger='id_learning'):
        import_log(tmp_path / 'single.npz', indexed, tmp_path / 'bag32')
        assert not caplog.records
        import_log(tmp_path / 'half.npz', indexed, tmp_path / 'bag16')
    assert [r.getMessage().split(': at')[0] for r in caplog.records] == [
        f"{tmp_path / 'half.npz'}: array 'q' is float16"
    ]


# -- R18: a file read as another format -----------------------------------------------------------
def test_an_npz_read_as_csv_is_named_as_an_npz_archive(tmp_path: Path) -> None:
    npz = _npz_export(tmp_path / 'good', log_values())
    with pytest.raises(
        ConfigError,
        match=r"good\.npz: the mapping's format: csv does not fit this file, which looks like an "
        r'NPZ \(zip\) archive \(it starts with PK\\x03\\x04\); set format: npz',
    ):
        import_log(npz, mapping(format='csv'), tmp_path / 'bag')
    misnamed = tmp_path / 'misnamed.csv'
    shutil.copy(npz, misnamed)
    with pytest.raises(ConfigError, match=r"its suffix '\.csv' does not fit .* set format: npz"):
        import_log(misnamed, mapping(), tmp_path / 'bag')


def test_a_csv_read_as_npz_names_the_format_to_set(tmp_path: Path) -> None:
    csv = write_csv(tmp_path / 'good.csv', log_values())
    with pytest.raises(
        ConfigError,
        match=r"good\.csv: the mapping's format: npz does not fit this file, which is no NPZ "
        r"\(zip\) archive \(it starts with b't_ms'\); for a CSV log set format: csv",
    ):
        import_log(csv, mapping(format='npz'), tmp_path / 'bag')


def test_a_gzipped_csv_is_read_as_its_text_also_in_a_folder(tmp_path: Path) -> None:
    folder = tmp_path / 'logs'
    folder.mkdir()
    packed = _gzipped(folder / 'run', log_values())
    plain = write_csv(tmp_path / 'plain.csv', log_values(seed=1))
    for source, out in ((packed, 'one'), (folder, 'folder')):
        report = import_logs([source], mapping(), tmp_path / out)[0]
        assert (report.source, report.n_rows_written) == (packed, N_ROWS)
    import_log(plain, mapping(format='csv'), tmp_path / 'plain')
    plain.write_bytes(gzip.compress(plain.read_bytes()))  # gzip content under a .csv name
    import_log(plain, mapping(), tmp_path / 'renamed')
    expected, got = (
        read_joint_states(tmp_path / b, '/joint_states') for b in ('plain', 'renamed')
    )
    np.testing.assert_array_equal(got.position, expected.position)
    np.testing.assert_array_equal(got.stamps_ns, expected.stamps_ns)


def test_a_broken_gzip_stream_and_a_gzipped_npz_are_refused(tmp_path: Path) -> None:
    broken = tmp_path / 'broken.csv.gz'
    broken.write_bytes(gzip.compress(b't_ms,q1\n0.0,1.0\n' * 50)[:-12])
    with pytest.raises(DatasetError, match=r'broken\.csv\.gz: cannot decompress this gzip file'):
        import_log(broken, mapping(), tmp_path / 'bag')
    npz = _npz_export(tmp_path / 'good', log_values())
    packed = tmp_path / 'good.npz.gz'
    packed.write_bytes(gzip.compress(npz.read_bytes()))
    with pytest.raises(
        DatasetError, match=r'good\.npz\.gz: this file is gzip-compressed; decompress it'
    ):
        import_log(packed, mapping(), tmp_path / 'bag')
