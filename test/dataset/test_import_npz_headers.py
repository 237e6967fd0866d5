"""An NPZ log's array headers are checked before any array is allocated (probe I22).

An array whose header claims more data than the archive stores (1e11 float64 elements in a few
bytes), a header numpy cannot parse, an object array, a member that is no NPY array, and arrays
that would take more than ``MEMORY_SHARE`` of the memory available are refused with a
DatasetError naming the file, the array and its claimed shape; never numpy's MemoryError. A
gzipped CSV is decompressed up to the same budget.
"""

from __future__ import annotations

import ast
import gzip
import io
import re
import struct
import zipfile
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from id_learning.dataset import import_readers
from id_learning.dataset.import_readers import read_table
from id_learning.dataset.importer import ColumnSpec, ImportMapping, JointColumns, import_log
from id_learning.errors import DatasetError

N_ROWS = 40


def mapping(file_format: str = 'npz') -> ImportMapping:
    joints = (JointColumns('joint_1', ColumnSpec('q1', 'deg')),)
    return ImportMapping(joints=joints, time=ColumnSpec('t_ms', 'ms'), format=file_format)  # type: ignore[arg-type]


def npy(header: str, data: bytes = b'', version: tuple[int, int] = (1, 0)) -> bytes:
    """An NPY file of this header text (padded as numpy pads it) and these data bytes."""
    length_format = '<H' if version == (1, 0) else '<I'
    prefix = 8 + struct.calcsize(length_format)
    text = header + ' ' * ((64 - (prefix + len(header) + 1) % 64) % 64) + '\n'
    return (
        b'\x93NUMPY'
        + bytes(version)
        + struct.pack(length_format, len(text))
        + text.encode('latin1')
        + data
    )


def archive(path: Path, members: dict[str, bytes], compression: int = zipfile.ZIP_STORED) -> Path:
    with zipfile.ZipFile(path, 'w', compression=compression) as z:
        for name, content in members.items():
            z.writestr(name, content)
    return path


def good_members() -> dict[str, bytes]:
    t = np.arange(N_ROWS) * 8.0
    out = {}
    for name, values in (('t_ms', t), ('q1', np.sin(t / 100))):
        buffer = io.BytesIO()
        np.save(buffer, values)
        out[f'{name}.npy'] = buffer.getvalue()
    return out


def header(shape: object, descr: str = '<f8') -> str:
    return f"{{'descr': '{descr}', 'fortran_order': False, 'shape': {shape}, }}"


def refused(path: Path) -> str:
    with pytest.raises(DatasetError) as err:
        read_table(path, mapping())
    text = str(err.value)
    assert text.startswith(f'{path}: ')
    return text


@pytest.fixture
def no_array_read(monkeypatch: pytest.MonkeyPatch) -> None:
    """Fail the test if numpy reads (allocates) any array: the headers must refuse first."""

    def read_array(*args: object, **kwargs: object) -> None:
        raise AssertionError('an array was read before its header was checked')

    monkeypatch.setattr(np.lib.format, 'read_array', read_array)


def test_the_probes_header_claiming_1e11_elements_is_refused_before_allocating(
    tmp_path: Path, no_array_read: None
) -> None:
    # I22: np.save's header with (3,) edited into (99999999999,).
    buffer = io.BytesIO()
    np.save(buffer, np.zeros(3))
    edited = buffer.getvalue().replace(b'(3,)', b'(99999999999,)')
    path = archive(tmp_path / 'bomb.npz', {'time_ms.npy': edited})
    text = refused(path)
    assert "array 'time_ms' claims shape (99999999999,) of float64 (745 GiB)" in text
    assert 'the archive stores' in text


def test_the_probe_case_through_import_is_a_dataset_error(tmp_path: Path) -> None:
    members = good_members()
    members['t_ms.npy'] = npy(header('(99999999999,)'), b'\0' * 24)
    path = archive(tmp_path / 'bomb.npz', members)
    with pytest.raises(DatasetError, match=r"array 't_ms' claims shape \(99999999999,\)"):
        import_log(path, mapping(), tmp_path / 'bag')
    assert not (tmp_path / 'bag').exists()


@pytest.mark.parametrize(
    ('member', 'message'),
    [
        (npy(header('(5,)'), b'\0' * 39), r"'t_ms' claims shape \(5,\) of float64 \(40 bytes\)"),
        (
            npy(header(f'({2**70},)')),
            rf"'t_ms' claims shape \({2**70},\) of float64 \(8\.8e\+12 GiB\)",
        ),
        (npy(header('(2**70,)')), r"'t_ms': cannot read its NPY header: malformed node"),
        (npy(header('(True,)')), r"'t_ms': cannot read its NPY header: shape \(True,\) needs"),
        (npy(header('[3]')), r"'t_ms': cannot read its NPY header: shape is not valid"),
        (
            npy(header('(-3,)')),
            r"'t_ms': cannot read its NPY header: shape \(-3,\) needs whole numbers >= 0",
        ),
        (npy(header('(3,)', descr='<zz')), r"'t_ms': cannot read its NPY header: .*descr"),
        (npy('not a dict at all'), r"'t_ms': cannot read its NPY header"),
        (npy("{'shape': (3,)}"), r"'t_ms': cannot read its NPY header: .*correct keys"),
        (b'\x93NUMPY\x01\x00\xff', r"'t_ms': cannot read its NPY header: EOF"),
        (npy(header('(3,)'), version=(9, 0)), r"'t_ms': cannot read its NPY header: .*9"),
        (npy(header('(3,)', descr='|O'), b'\0' * 24), r"'t_ms' holds Python objects"),
        (b'hello, not an array', r"'t_ms\.npy' in the archive is no NPY array"),
    ],
)
def test_an_unreadable_or_lying_header_is_refused_naming_file_and_array(
    tmp_path: Path, no_array_read: None, member: bytes, message: str
) -> None:
    members = good_members()
    members['t_ms.npy'] = member
    assert re.search(message, refused(archive(tmp_path / 'x.npz', members)))


def test_arrays_beyond_the_memory_budget_are_refused_before_allocating(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, no_array_read: None
) -> None:
    # A compressed archive that expands to more than the memory allows: 2 arrays of 320 bytes.
    path = archive(tmp_path / 'big.npz', good_members(), zipfile.ZIP_DEFLATED)
    monkeypatch.setattr(import_readers, '_memory_budget', lambda: 500)
    text = refused(path)
    assert "array 'q1' claims shape (40,) of float64 (320 bytes)" in text
    assert 'with the arrays before it, 640 bytes: more than 50% of the 1000 bytes' in text
    assert 'split the log into shorter files' in text


def test_good_archives_stored_or_compressed_and_npy_version_2_are_read(tmp_path: Path) -> None:
    members = good_members()
    t = np.frombuffer(members['t_ms.npy'][128:], dtype='<f8')
    members['q1.npy'] = npy(header('(40,)'), t.tobytes(), version=(2, 0))
    for compression in (zipfile.ZIP_STORED, zipfile.ZIP_DEFLATED):
        path = archive(tmp_path / f'{compression}.npz', members, compression)
        table = read_table(path, mapping())
        np.testing.assert_array_equal(table.columns['t_ms'], t)
        np.testing.assert_array_equal(table.columns['q1'], t)
    # An empty array claims 0 bytes and is read as such.
    members['q1.npy'] = npy(header('(0,)'))
    table = read_table(archive(tmp_path / 'empty.npz', members), mapping())
    assert table.columns['q1'].shape == (0,)


def test_a_gzipped_csv_past_the_memory_budget_is_refused_while_decompressing(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    text = 't_ms,q1\n' + ''.join(f'{8 * k},0.5\n' for k in range(N_ROWS))
    path = tmp_path / 'log.csv.gz'
    path.write_bytes(gzip.compress(text.encode()))
    monkeypatch.setattr(import_readers, '_GUNZIP_CHUNK', 64)
    monkeypatch.setattr(import_readers, '_memory_budget', lambda: len(text) - 1)
    with pytest.raises(DatasetError, match=r'log\.csv\.gz: this gzip file decompresses to more'):
        read_table(path, mapping('csv'))
    monkeypatch.setattr(import_readers, '_memory_budget', lambda: len(text))
    assert len(read_table(path, mapping('csv')).columns['q1']) == N_ROWS


def test_a_csv_larger_than_the_memory_budget_is_refused_before_reading(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    path = tmp_path / 'log.csv'
    path.write_text('t_ms,q1\n0,1\n8,1\n')
    monkeypatch.setattr(import_readers, '_memory_budget', lambda: 10)
    with pytest.raises(DatasetError, match=r'log\.csv: cannot read CSV file: 16 bytes, more than'):
        read_table(path, mapping('csv'))


def test_the_memory_budget_is_a_share_of_the_available_memory() -> None:
    budget = import_readers._memory_budget()
    assert budget is None or budget > 0


# -- any header -----------------------------------------------------------------------------------
shapes = st.one_of(
    st.lists(st.integers(-3, 2**64), max_size=3).map(tuple),
    st.lists(st.integers(0, 50), max_size=2).map(tuple),
    st.sampled_from(['None', '[3]', "'3'", '(3.0,)', '(True,)', '()']),
)
descrs = st.sampled_from(['<f8', '<f4', '<f2', '>i4', '|u1', '|b1', '<U3', '|O', '|V8', 'x', ''])


@settings(max_examples=150, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(
    shape=shapes,
    descr=descrs,
    n_data=st.integers(0, 400),
    compression=st.sampled_from([zipfile.ZIP_STORED, zipfile.ZIP_DEFLATED]),
)
def test_any_header_is_read_or_refused_as_a_dataset_error(
    tmp_path: Path, shape: object, descr: str, n_data: int, compression: int
) -> None:
    members = good_members()
    members['t_ms.npy'] = npy(header(shape, descr), b'\x01' * n_data)
    path = archive(tmp_path / 'any.npz', members, compression)
    try:
        table = read_table(path, mapping())
    except DatasetError as err:
        refusal = str(err)
    else:
        refusal = ''
    if refusal:
        assert refusal.startswith(f'{path}: '), refusal
        assert "'t_ms" in refusal, refusal
        return
    # Read: then the header was honest, and the array is what it claims.
    claimed = ast.literal_eval(str(shape))
    claimed = (claimed,) if isinstance(claimed, int) else tuple(claimed)
    assert table.columns['t_ms'].shape == claimed
    assert table.columns['t_ms'].nbytes <= n_data
