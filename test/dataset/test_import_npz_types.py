"""NPZ arrays that hold no real numbers, a time too coarse for its samples, odd array shapes.

Probe 15 (A24-A27): a bool current imported as 0 and 1 A, a complex one without its imaginary
part (numpy's ComplexWarning the only word); float32 epoch seconds (a 128 s step) were refused
as "repeated times"; a 0-d or 3-D array was told to "give index".
"""

from __future__ import annotations

import io
import logging
import warnings
import zipfile
from pathlib import Path

import numpy as np
import pytest

from id_learning.bag import read_joint_states
from id_learning.dataset.importer import ColumnSpec, ImportMapping, JointColumns, import_log
from id_learning.errors import ConfigError, DatasetError

N = 200
EPOCH_S = 1_767_225_600.0  # 2026-01-01T00:00:00Z


def mapping(time_unit: str = 's') -> ImportMapping:
    joint = JointColumns('joint_1', ColumnSpec('q', 'rad'), current=ColumnSpec('i', 'A'))
    return ImportMapping(joints=(joint,), time=ColumnSpec('t', time_unit))


def arrays(**replace: np.ndarray) -> dict[str, np.ndarray]:
    t = 0.008 * np.arange(N)
    return {'t': t, 'q': 0.2 * np.sin(t), 'i': 3.0 * np.cos(t), **replace}


def save(path: Path, **replace: np.ndarray) -> Path:
    np.savez(path, **arrays(**replace))
    return path


@pytest.mark.parametrize(
    ('array', 'said'),
    [
        (3.0 * np.cos(0.008 * np.arange(N)) > 0, 'true/false values (dtype bool)'),
        (3.0 * np.cos(0.008 * np.arange(N)) + 5j, 'complex numbers (dtype complex128)'),
        (np.arange(N).astype('datetime64[ms]'), 'dates (dtype datetime64[ms])'),
        (np.zeros(N, dtype=[('a', 'f8'), ('b', 'f8')]), 'records (a structured array)'),
    ],
)
def test_an_array_of_no_real_numbers_is_refused_naming_it_and_its_dtype(
    tmp_path: Path, array: np.ndarray, said: str
) -> None:
    source = save(tmp_path / 'log.npz', i=array)
    with pytest.raises(DatasetError) as error:
        import_log(source, mapping(), tmp_path / 'bag')
    assert f"array 'i' (column 'i' (joint joint_1 current)) is {said}" in str(error.value)
    assert 'log.npz' in str(error.value)
    assert not (tmp_path / 'bag').exists()


def test_float32_epoch_seconds_are_refused_naming_their_resolution(tmp_path: Path) -> None:
    t = (EPOCH_S + 0.008 * np.arange(N)).astype(np.float32)
    source = save(tmp_path / 'log.npz', t=t)
    with pytest.raises(
        DatasetError, match=r"array 't' \(time\) is float32: .* resolves only 128 s"
    ):
        import_log(source, mapping(), tmp_path / 'bag')
    save(tmp_path / 'log64.npz', t=EPOCH_S + 0.008 * np.arange(N))
    import_log(tmp_path / 'log64.npz', mapping(), tmp_path / 'bag64')


def test_float32_time_fine_enough_for_its_steps_imports_exactly(tmp_path: Path) -> None:
    t_ms = (8.0 * np.arange(N)).astype(np.float32)  # exact in float32
    source = save(tmp_path / 'log.npz', t=t_ms)
    import_log(source, mapping('ms'), tmp_path / 'bag')
    states = read_joint_states(tmp_path / 'bag', '/joint_states')
    assert np.array_equal(np.diff(states.stamps_ns), np.full(N - 1, 8_000_000))
    assert np.allclose(states.position[:, 0], arrays()['q'])


def test_float16_positions_still_import_with_a_warning(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    source = save(tmp_path / 'log.npz', q=arrays()['q'].astype(np.float16))
    with caplog.at_level(logging.WARNING):
        import_log(source, mapping(), tmp_path / 'bag')
    assert "array 'q' is float16" in caplog.text


@pytest.mark.parametrize(
    ('shape', 'hint'),
    [
        ((), 'a column is a 1-D array (N,), or a 2-D one (N, k) with index'),
        ((5, 4, 10), 'a column is a 1-D array (N,), or a 2-D one (N, k) with index'),
        ((1, N), 'one row of values: transposed? Store it as a 1-D array (N,)'),
        ((N, 2), 'give index to pick one of its columns'),
    ],
)
def test_an_array_of_another_shape_gets_the_hint_that_fits_it(
    tmp_path: Path, shape: tuple[int, ...], hint: str
) -> None:
    source = save(tmp_path / 'log.npz', q=np.zeros(shape))
    with pytest.raises(ConfigError, match=r'is an array of shape ') as error:
        import_log(source, mapping(), tmp_path / 'bag')
    assert f'{shape} in ' in str(error.value)
    assert str(error.value).endswith(hint) or f'; {hint}' in str(error.value)


def test_an_archive_holding_one_array_twice_is_refused(tmp_path: Path) -> None:
    # Probe 15 (A89): the second 'i.npy' member (1.5 x the first) was imported without a word.
    source = save(tmp_path / 'log.npz')
    with zipfile.ZipFile(source, 'a') as archive, warnings.catch_warnings():
        warnings.simplefilter('ignore', UserWarning)  # zipfile's "Duplicate name"
        buffer = io.BytesIO()
        np.save(buffer, 1.5 * arrays()['i'])
        archive.writestr('i.npy', buffer.getvalue())
    with pytest.raises(DatasetError, match=r"holds array\(s\) \['i'\] more than once"):
        import_log(source, mapping(), tmp_path / 'bag')
