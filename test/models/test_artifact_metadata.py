"""model.json is read bounded: too large or too deeply nested gives a CheckpointError naming it."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from id_learning.errors import CheckpointError
from id_learning.models import artifact
from id_learning.models.artifact import MAX_METADATA_DEPTH, read_metadata
from id_learning.models.registry import load_model


def _nested(depth: int) -> dict:
    document: dict = {'format': artifact.ARTIFACT_FORMAT}
    inner = document
    for _ in range(depth - 1):
        inner['x'] = {}
        inner = inner['x']
    return document


def test_metadata_nested_to_the_bound_is_read_and_one_level_more_is_refused(tmp_path: Path):
    path = tmp_path / 'model.json'
    path.write_text(json.dumps(_nested(MAX_METADATA_DEPTH)))
    assert read_metadata(path)['format'] == artifact.ARTIFACT_FORMAT
    path.write_text(json.dumps(_nested(MAX_METADATA_DEPTH + 1)))
    with pytest.raises(CheckpointError, match=r'nested deeper than a model\.json') as err:
        read_metadata(path)
    assert str(path) in str(err.value)


def test_metadata_nested_beyond_the_parsers_stack_is_refused_without_a_recursion_error(
    tmp_path: Path,
):
    path = tmp_path / 'model.json'
    path.write_text('[' * 200_000 + ']' * 200_000)
    with pytest.raises(CheckpointError, match='nested deeper'):
        read_metadata(path)


def test_oversized_metadata_is_refused_before_it_is_read(tmp_path: Path, monkeypatch):
    path = tmp_path / 'model.json'
    path.write_text(json.dumps({'format': artifact.ARTIFACT_FORMAT, 'pad': 'x' * 2000}))
    monkeypatch.setattr(artifact, 'MAX_METADATA_BYTES', 1000)
    with pytest.raises(CheckpointError, match=r'model\.json: cannot read model metadata: larger'):
        read_metadata(path)


@pytest.mark.parametrize(('text', 'match'), [('[1, 2]', 'not an object'), ('{', 'not valid JSON')])
def test_metadata_that_is_no_json_object_is_refused(tmp_path: Path, text: str, match: str):
    path = tmp_path / 'model.json'
    path.write_text(text)
    with pytest.raises(CheckpointError, match=match):
        read_metadata(path)


def test_loading_an_artifact_with_deep_metadata_names_its_model_json(tmp_path: Path, mabi):
    (tmp_path / artifact.WEIGHTS_FILE).write_bytes(b'')
    (tmp_path / artifact.METADATA_FILE).write_text('{"a":' * 5000 + '1' + '}' * 5000)
    with pytest.raises(CheckpointError, match=r'model\.json: nested deeper'):
        load_model(tmp_path, mabi)
