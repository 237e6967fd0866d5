"""A run finds its training bag wherever the command runs from, and never another bag."""

from __future__ import annotations

import pytest
from support import sine_recording

from id_learning.dataset.recording import write_recording
from id_learning.errors import CheckpointError
from id_learning.training.datasets import bag_sha256
from id_learning.training.run_folder import training_bag


def _run(bag, **extra):
    return {'training_data': {'bags': [{'path': 'bag', 'sha256': bag_sha256(bag), **extra}]}}


def test_a_relative_bag_is_found_beside_the_run_from_another_folder(tmp_path, monkeypatch):
    bag = write_recording(sine_recording(40), tmp_path / 'bag')
    elsewhere = tmp_path / 'elsewhere'
    elsewhere.mkdir()
    monkeypatch.chdir(elsewhere)
    assert training_bag(_run(bag), tmp_path / 'run') == tmp_path / 'bag'
    # The absolute path written since is tried first.
    moved = _run(bag, absolute_path=str(bag.resolve()))
    assert training_bag(moved, tmp_path / 'nowhere' / 'run') == bag.resolve()


def test_a_bag_of_the_same_name_with_other_data_is_refused(tmp_path, monkeypatch):
    bag = write_recording(sine_recording(40), tmp_path / 'bag')
    run = _run(bag)
    other = tmp_path / 'elsewhere'
    write_recording(sine_recording(41), other / 'bag')
    monkeypatch.chdir(other)
    far = tmp_path / 'far' / 'run'
    with pytest.raises(CheckpointError, match=r'bag holds other data \(another SHA-256\)'):
        training_bag(run, far)
    (other / 'bag').rename(other / 'gone')
    with pytest.raises(CheckpointError, match=r'training bag bag is not found \(tried '):
        training_bag(run, far)
