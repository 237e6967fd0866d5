"""closed-loop does what it was asked, or says what it did instead: --duration and --models."""

from __future__ import annotations

import json
import logging

import pytest
from support import run_cli

from id_learning.errors import ConfigError
from id_learning.training.closed_loop_run import closed_loop_run


def test_a_duration_beyond_the_test_part_tracks_the_part_and_says_so(run, mabi, tmp_path, caplog):
    with caplog.at_level(logging.WARNING, logger='id_learning.training.closed_loop_run'):
        result = closed_loop_run(
            run.out, mabi, tmp_path / 'long', duration_s=1000.0, kinds=['rnea_lq'], progress=False
        )
    reference = json.loads(result.json_path.read_text())['reference']
    available = reference['available_s']
    assert reference['duration_s'] == pytest.approx(available)
    assert (reference['requested_duration_s'], reference['shortened']) == (1000.0, True)
    (warning,) = [r.getMessage() for r in caplog.records if r.levelno == logging.WARNING]
    assert warning.startswith(
        f'duration 1000 s asked for, but the test part of {reference["bag"]}'
    )
    assert f'holds {available:.2f} s' in warning
    assert f'tracked {available:.2f} s, not the 1000 s asked for' in result.summary()


def test_no_duration_asked_tracks_the_whole_part_without_a_warning(run, mabi, tmp_path, caplog):
    with caplog.at_level(logging.WARNING, logger='id_learning.training.closed_loop_run'):
        result = closed_loop_run(run.out, mabi, tmp_path / 'all', kinds=['rnea_lq'],
                                 progress=False)  # fmt: skip
    reference = result.document['reference']
    assert reference['shortened'] is False
    assert reference['requested_duration_s'] is None
    assert not [r for r in caplog.records if r.levelno >= logging.WARNING]
    assert 'asked for' not in result.summary()


def test_an_empty_list_of_models_is_refused_not_read_as_all(run, mabi, tmp_path):
    with pytest.raises(ConfigError, match='no model kind named'):
        closed_loop_run(run.out, mabi, tmp_path / 'none', kinds=[], progress=False)
    assert not (tmp_path / 'none').exists()
    result = run_cli('closed-loop', '--run', str(run.out), '--models', '', '--out',
                     str(tmp_path / 'cli'))  # fmt: skip
    assert result.returncode == 2
    assert result.stderr == (
        "id-learning closed-loop: error: --models '': names no model kind; name some (e.g. "
        'rnea_lq,mlp), or leave it out for all\n'
    )
    assert not (tmp_path / 'cli').exists()
