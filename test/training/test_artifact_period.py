"""A model file says the IPO period it was trained at; another period is refused or warned of."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import pytest

from id_learning.errors import CheckpointError
from id_learning.models.registry import _check_period, load_model, make_model


def test_a_model_file_holds_the_period_it_was_trained_at(run, mabi):
    document = json.loads((run.out / 'models' / 'mlp' / 'model.json').read_text())

    assert document['robot']['ipo_period_s'] == mabi.ipo_period_s


def test_another_period_is_warned_of_for_a_model_of_one_sample(run, mabi, caplog):
    at_4_ms = replace(mabi, ipo_period_s=0.004)

    model = load_model(run.out / 'models' / 'rnea_lq', at_4_ms)

    assert model.robot.ipo_period_s == 0.004
    assert 'trained on recordings at an IPO period of 8 ms; the robot config says 4 ms' in (
        caplog.text
    )


@pytest.mark.parametrize('now_s', [0.004, 0.001, 0.016])
def test_a_sequence_model_at_another_period_is_refused(mabi, now_s):
    lstm = make_model('lstm', replace(mabi, ipo_period_s=now_s))

    with pytest.raises(CheckpointError, match=r'lstm: trained .* 8 ms.*window counts samples'):
        _check_period(lstm, 0.008, Path('runs/x/models/lstm'))
    _check_period(lstm, now_s, Path('runs/x/models/lstm'))  # its own period: accepted
    _check_period(lstm, None, Path('runs/x/models/lstm'))  # a file from before: accepted


def test_the_weights_are_as_readable_as_model_json(run):
    folder = run.out / 'models' / 'mlp'
    files = ('model.json', 'weights.safetensors')

    modes = {name: (folder / name).stat().st_mode & 0o777 for name in files}

    assert modes['weights.safetensors'] == modes['model.json']
