"""A recording too short to diagnose is refused with one length that suffices, not a moving one."""

from __future__ import annotations

import re

import pytest
from support import twin_config

from id_learning.diagnosis import run_diagnosis
from id_learning.errors import DatasetError
from id_learning.twin import simulate


def _advice(duration_s: float) -> tuple[float, int]:
    config = twin_config(duration_s)
    with pytest.raises(DatasetError, match='too short to diagnose') as raised:
        run_diagnosis(simulate(config).recording, config.robot)
    recorded = float(re.search(r': ([\d.]+) s is too short', str(raised.value)).group(1))
    return recorded, int(re.search(r'record at least (\d+) s', str(raised.value)).group(1))


def test_the_length_advised_is_the_same_from_any_short_recording():
    short, advised = _advice(30.0)
    longer, advised_again = _advice(60.0)
    assert longer > short
    assert advised > longer  # the longer one is still too short for what was advised
    assert advised_again == pytest.approx(advised, rel=0.1)


def test_the_training_part_says_its_lengths_are_not_the_recordings():
    from id_learning.dataset import prepare_dataset
    from id_learning.diagnosis import diagnose_training_part

    config = twin_config(60.0)
    dataset = prepare_dataset(simulate(config).recording, config.robot)

    with pytest.raises(DatasetError, match='too short to diagnose') as raised:
        diagnose_training_part(dataset, config.robot)

    share = dataset.n_train / len(dataset.q)
    assert f'of the training part only ({share:.0%} of the recordings)' in str(raised.value)
    assert f'need about {1 / share:.2g} times as long' in str(raised.value)
