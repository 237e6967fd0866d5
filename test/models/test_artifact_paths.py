"""An artifact path that is no model folder is named for what it is, never opened or waited on.

Probe P02: ``predictor -p artifact:=<a FIFO>`` said 'f1/model.json: Not a directory'. A FIFO, a
device, a regular file or a link to nothing given as the artifact is now named as such.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import pytest
from support import no_hang

from id_learning.errors import CheckpointError
from id_learning.models.registry import load_model


def _refusal(path: Path, robot: Any) -> str:
    with no_hang(), pytest.raises(CheckpointError) as err:
        load_model(path, robot)
    return str(err.value)


def test_a_fifo_given_as_the_artifact_is_named_a_fifo_not_a_model_folder(
    tmp_path: Path, mabi: Any
) -> None:
    fifo = tmp_path / 'f1'
    os.mkfifo(fifo)
    message = _refusal(fifo, mabi)
    assert message.startswith(f'{fifo}: a FIFO (named pipe), not a model folder')
    assert 'Not a directory' not in message
    assert 'model.json' in message  # what a model folder holds


def test_a_regular_file_given_as_the_artifact_is_named_a_file(tmp_path: Path, mabi: Any) -> None:
    path = tmp_path / 'model.json'
    path.write_text('{}')
    message = _refusal(path, mabi)
    assert message.startswith(
        f'{path}: a regular file, not a model folder (expected a folder with model.json and '
        'weights.safetensors)'
    )
    assert 'Not a directory' not in message


def test_a_device_given_as_the_artifact_is_named_a_device(tmp_path: Path, mabi: Any) -> None:
    link = tmp_path / 'dev'
    link.symlink_to('/dev/null')
    assert _refusal(link, mabi).startswith(f'{link}: a character device, not a model folder')


def test_an_artifact_link_to_nothing_is_named_as_one(tmp_path: Path, mabi: Any) -> None:
    link = tmp_path / 'model'
    link.symlink_to(tmp_path / 'moved')
    assert _refusal(link, mabi).startswith(
        f'{link}: a link to {tmp_path / "moved"}, which does not exist'
    )


def test_a_missing_artifact_is_still_said_to_be_no_model_artifact(
    tmp_path: Path, mabi: Any
) -> None:
    """The wording nodes and tests rely on for a path that does not exist stays."""
    assert 'not a model artifact' in _refusal(tmp_path / 'none', mabi)
    assert 'not a model artifact' in _refusal(tmp_path, mabi)  # an empty folder


def test_a_missing_relative_artifact_names_the_working_directory(
    tmp_path: Path, mabi: Any, monkeypatch: pytest.MonkeyPatch
) -> None:
    # Probe 15 (B93): config/nodes.yaml run from another folder gave only 'not a model artifact'.
    monkeypatch.chdir(tmp_path)
    said = _refusal(Path('out/demo/run/models/mlp'), mabi)
    assert 'out/demo/run/models/mlp: no such folder, so not a model artifact' in said
    assert f'a path relative to the working directory {tmp_path}' in said
    assert 'working directory' not in _refusal(tmp_path / 'none', mabi)
