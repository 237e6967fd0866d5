"""A study table row keyed by no model kind is refused, naming the file, the key and a kind.

Probe R09: a row keyed ``RNEA-ID`` (no kind: the kinds are ``rnea_id``, ...) was read and then
left out of the comparison without a word, since the report looks rows up by kind.
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from id_learning.errors import ConfigError
from id_learning.evaluation.study import load_study_table
from id_learning.models.registry import MODEL_KINDS

AXES = [f'axis_{k}' for k in range(1, 7)]
ROW = [0.1, 0.2, 0.3, 0.4, 0.5, 0.6]


def _table(tmp_path: Path, rows: dict[str, list[float]]) -> Path:
    path = tmp_path / 'table1.json'
    path.write_text(json.dumps({'joints': AXES, 'rmse_normalised': rows}))
    return path


def test_a_row_keyed_by_no_kind_is_refused_with_the_closest_kind_and_the_known_ones(
    tmp_path: Path,
) -> None:
    path = _table(tmp_path, {'mlp': ROW, 'RNEA-ID': ROW})
    with pytest.raises(ConfigError) as err:
        load_study_table(path, n_joints=6)
    message = str(err.value)
    assert message.startswith(f"{path}: rmse_normalised.RNEA-ID: 'RNEA-ID' is no model kind")
    assert "(did you mean 'rnea_id'?)" in message
    assert all(kind in message for kind in MODEL_KINDS)


def test_a_row_keyed_by_the_study_s_label_is_pointed_to_its_kind(tmp_path: Path) -> None:
    path = _table(tmp_path, {'RNEA+MLP': ROW})
    with pytest.raises(
        ConfigError, match=r"rmse_normalised\.RNEA\+MLP: .*\(did you mean 'rnea_mlp'\?\)"
    ):
        load_study_table(path, n_joints=6)


def test_a_name_like_no_kind_is_refused_without_a_guess(tmp_path: Path) -> None:
    path = _table(tmp_path, {'transformer': ROW})
    with pytest.raises(ConfigError, match=r"'transformer' is no model kind; the kinds are") as err:
        load_study_table(path, n_joints=6)
    assert 'did you mean' not in str(err.value)


def test_every_kind_is_a_valid_row(tmp_path: Path) -> None:
    rows = dict.fromkeys(MODEL_KINDS, ROW)
    table = load_study_table(_table(tmp_path, rows), n_joints=6)
    assert table.rmse_normalised == {kind: tuple(ROW) for kind in MODEL_KINDS}
