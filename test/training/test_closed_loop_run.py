"""closed-loop on a training run: the twin robot its bags came from, tracking with feed-forward."""

from __future__ import annotations

import json
import shutil

import numpy as np
import pytest

from id_learning.errors import ConfigError
from id_learning.evaluation.closed_loop import FEEDBACK_ONLY, TRUE_DYNAMICS
from id_learning.training.closed_loop_run import closed_loop_run


def test_closed_loop_tracks_the_test_motion_better_with_feed_forward(run, mabi, tmp_path):
    """The run's bags carry the twin's config: the plant is the robot they were recorded from."""
    result = closed_loop_run(run.out, mabi, tmp_path / 'loop', duration_s=8.0, progress=False)
    document = json.loads(result.json_path.read_text())
    assert set(document['runs']) == {FEEDBACK_ONLY, 'rnea_lq', 'mlp', TRUE_DYNAMICS}
    assert document['reference']['duration_s'] == pytest.approx(8.0)
    assert result.plot_path.is_file()
    base = np.array(document['runs'][FEEDBACK_ONLY]['rms_rad'])
    true = np.array(document['runs'][TRUE_DYNAMICS]['rms_rad'])
    assert (true < base / 3).all()
    assert document['best_model'] in ('rnea_lq', 'mlp')
    best = np.array(document['runs'][document['best_model']]['rms_rad'])
    np.testing.assert_allclose(document['improvement_best'], base / best)
    with pytest.raises(ConfigError, match=r"no model\(s\) \['lstm'\] in the run"):
        closed_loop_run(run.out, mabi, tmp_path / 'x', kinds=['lstm'], progress=False)
    # The same bag without the twin's config beside it (a copy of the data alone).
    bare, plain = tmp_path / 'bare', tmp_path / 'plain'
    shutil.copytree(run.out, bare)
    meta = json.loads((bare / 'run.json').read_text())
    for k, entry in enumerate(meta['training_data']['bags']):
        copy = plain / str(k)
        shutil.copytree(entry['path'], copy, ignore=shutil.ignore_patterns('twin_config.yaml'))
        entry['path'] = entry['absolute_path'] = str(copy)
    (bare / 'run.json').write_text(json.dumps(meta))
    with pytest.raises(ConfigError, match=r'twin_config\.yaml.*pass --twin'):
        closed_loop_run(bare, mabi, tmp_path / 'y', progress=False)
    # Probe 16 (C70): half an IPO period to track blamed the bag, not --duration.
    with pytest.raises(ConfigError, match=r'--duration 0\.004 s is shorter than two IPO periods'):
        closed_loop_run(run.out, mabi, tmp_path / 'z', duration_s=0.004, progress=False)


def test_closed_loop_tracks_another_recording_from_its_start_on_its_own_twin(
    run, bags, mabi, tmp_path
):
    from support import twin_config

    from id_learning.twin import simulate, write_twin_output

    config = twin_config(30.0, seed=13)
    unseen = write_twin_output(simulate(config), config, tmp_path / 'unseen')
    result = closed_loop_run(
        run.out, mabi, tmp_path / 'loop', duration_s=4.0, progress=False, bag=unseen
    )
    reference = json.loads(result.json_path.read_text())['reference']
    assert reference['bag'] == str(unseen)
    assert reference['rows'] == [0, 500]
    assert 'not trained on' in reference['part']
    # Probe 16 (C21): asked for more than it holds, the whole of it, not its first 70 %.
    from id_learning.dataset.preprocess import PreprocessConfig
    from id_learning.training.closed_loop_run import _reference_rows
    from id_learning.training.datasets import load_datasets

    whole = load_datasets([unseen], mabi, PreprocessConfig(), progress=False)[0]
    rows = _reference_rows(whole, PreprocessConfig(), 10**9, unseen=True)
    assert rows[:3] == (0, len(whole.q), len(whole.q))
    assert str(unseen / 'twin_config.yaml') == result.document['twin_config']
    # A training bag given as --bag is tracked on its test part, as without it.
    again = closed_loop_run(
        run.out, mabi, tmp_path / 'again', duration_s=4.0, progress=False, bag=bags[0]
    )
    default = closed_loop_run(run.out, mabi, tmp_path / 'default', duration_s=4.0, progress=False)
    assert again.document['reference']['rows'] == default.document['reference']['rows']
    assert again.document['reference']['rows'][0] > 0
