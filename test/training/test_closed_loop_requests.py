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


def test_the_summary_table_keeps_long_joint_names_apart_and_under_their_figures(tmp_path):
    import numpy as np

    from id_learning.evaluation.closed_loop import Tracking
    from id_learning.training.closed_loop_run import ClosedLoopResult

    joints = ['shoulder_pan_joint', 'shoulder_lift_joint', 'wrist_3_joint']
    error = np.array([[1e-3, 2e-3, 3e-3]] * 4)
    tracking = Tracking(error, np.zeros_like(error), np.zeros(3, dtype=int))
    reference = {'requested_duration_s': None, 'shortened': False, 'duration_s': 1.0,
                 'part': 'the test part', 'bag': 'b', 'available_s': 1.0}  # fmt: skip
    result = ClosedLoopResult(
        {'feedback only': tracking, 'rnea_id': tracking}, 'rnea_id', np.ones(3),
        {'joints': joints, 'reference': reference}, *(tmp_path / 'x' for _ in range(4)),
    )  # fmt: skip
    head, feedback, *_ = result.summary().splitlines()
    assert head.split()[-3:] == joints
    assert feedback.split()[-3:] == ['1.000', '2.000', '3.000']
    for joint, figure in zip(joints, ['1.000', '2.000', '3.000'], strict=True):
        assert head.index(joint) + len(joint) == feedback.index(figure) + len(figure)
