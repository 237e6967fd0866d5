"""Reading a twin bag's ground truth: a damaged file is a DatasetError naming it."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from id_learning.errors import DatasetError
from id_learning.twin import GROUND_TRUTH_ARRAYS, GROUND_TRUTH_JSON
from id_learning.twin.ground_truth import read_ground_truth


def _bag(tmp_path: Path, text: str = '{"joints": ["j"]}') -> Path:
    (tmp_path / GROUND_TRUTH_JSON).write_text(text, encoding='utf-8')
    np.savez(tmp_path / GROUND_TRUTH_ARRAYS, tau_u_clean=np.ones((4, 1)))
    return tmp_path


def test_a_bag_without_ground_truth_gives_none(tmp_path: Path) -> None:
    assert read_ground_truth(tmp_path, 'motor') is None


def test_ground_truth_is_read(tmp_path: Path) -> None:
    truth = read_ground_truth(_bag(tmp_path), 'motor')
    assert truth is not None
    assert truth.info == {'joints': ['j']}
    np.testing.assert_array_equal(truth.tau_clean, np.ones((4, 1)))


@pytest.mark.parametrize(
    ('text', 'target', 'match'),
    [
        ('{garbage', 'motor', r'ground_truth\.json: cannot read'),
        ('[1, 2]', 'motor', r'ground_truth\.json: expected a JSON object'),
        ('{}', 'joint', r'ground_truth\.npz: has no tau_joint_clean'),
    ],
)
def test_damaged_ground_truth_names_the_file(
    tmp_path: Path, text: str, target: str, match: str
) -> None:
    with pytest.raises(DatasetError, match=match):
        read_ground_truth(_bag(tmp_path, text), target)


def test_garbage_arrays_name_the_file(tmp_path: Path) -> None:
    _bag(tmp_path)
    (tmp_path / GROUND_TRUTH_ARRAYS).write_bytes(b'not a zip')
    with pytest.raises(DatasetError, match=r'ground_truth\.npz: cannot read'):
        read_ground_truth(tmp_path, 'motor')


def test_the_ground_truth_of_another_simulation_is_refused(tmp_path: Path) -> None:
    (tmp_path / GROUND_TRUTH_JSON).write_text('{}', encoding='utf-8')
    np.savez(tmp_path / GROUND_TRUTH_ARRAYS, tau_u_clean=np.ones((4, 1)),
             stamps_ns=np.arange(4) * 8_000_000)  # fmt: skip
    mine = np.arange(4) * 8_000_000
    assert read_ground_truth(tmp_path, 'motor', mine) is not None
    with pytest.raises(DatasetError, match='ground truth of another simulation'):
        read_ground_truth(tmp_path, 'motor', mine + 1)
