"""A run.json whose status the package never writes is refused, naming it."""

from __future__ import annotations

import json

import numpy as np
import pytest

from id_learning.errors import CheckpointError
from id_learning.training.run_folder import RUN_FILE, RUN_FORMAT, read_run


def test_a_status_the_package_never_writes_is_refused(tmp_path):
    (tmp_path / RUN_FILE).write_text(json.dumps({'format': RUN_FORMAT, 'status': 'partial'}))
    (tmp_path / 'metrics.json').write_text('{}')
    with pytest.raises(
        CheckpointError, match=r"status 'partial'; a run is complete or incomplete"
    ):
        read_run(tmp_path)


def test_a_hand_assembled_run_is_said_stray_folders_and_foreign_models(tmp_path, mabi, caplog):
    from predictor.tiny_artifacts import build_tiny_artifacts

    from id_learning.dataset.inputs import InputDefinition
    from id_learning.training.fitting import ModelResult
    from id_learning.training.trainer import _say_what_does_not_belong

    models = tmp_path / 'run' / 'models'
    folders = build_tiny_artifacts(models, mabi, kinds=['rnea_lq', 'mlp'])
    (models / 'notes').mkdir()
    # rnea_lq fitted on a controller's inputs, mlp (no definition stored) on the study's.
    meta = folders['rnea_lq'] / 'model.json'
    document = json.loads(meta.read_text())
    fitting = InputDefinition.controller(np.full(6, 10.0)).to_dict()
    document['preprocessing'] = {'inputs': fitting, 'fitting_inputs': fitting}
    meta.write_text(json.dumps(document))
    results = {kind: ModelResult(kind, None, folder, {}) for kind, folder in folders.items()}
    _say_what_does_not_belong(tmp_path / 'run', {'kinds': ['rnea_lq', 'mlp']}, results)
    assert 'models hold(s) notes, which run.json does not list' in caplog.text
    assert 'fitted on different inputs' in caplog.text
    assert 'study: mlp' in caplog.text


@pytest.mark.parametrize('how', ['copied', 'linked'])
def test_a_model_another_run_saved_is_refused_as_this_run_s(tmp_path, mabi, how):
    """A model folder is self-consistent wherever it came from: run.json's digest tells."""
    import shutil

    from predictor.tiny_artifacts import build_tiny_artifacts

    from id_learning.models.artifact import ARTIFACT_HASH
    from id_learning.training.run_folder import ARTIFACTS_KEY, check_run_model, load_run_model

    models = tmp_path / 'run' / 'models'
    own = build_tiny_artifacts(models, mabi, kinds=['rnea_lq', 'mlp'])
    digests = {
        kind: json.loads((folder / 'model.json').read_text())[ARTIFACT_HASH]
        for kind, folder in own.items()
    }
    run = {'format': RUN_FORMAT, 'status': 'complete', 'kinds': list(own),
           'preprocessing': {'target': 'motor'}, ARTIFACTS_KEY: digests}  # fmt: skip
    (tmp_path / 'run' / RUN_FILE).write_text(json.dumps(run))
    (tmp_path / 'run' / 'metrics.json').write_text('{}')
    assert load_run_model(tmp_path / 'run', run, 'mlp', mabi) is not None
    check_run_model(own['mlp'])  # reads run.json itself

    other = build_tiny_artifacts(tmp_path / 'other' / 'models', mabi, kinds=['mlp'])['mlp']
    shutil.rmtree(own['mlp'])
    if how == 'copied':
        shutil.copytree(other, own['mlp'])
    else:
        own['mlp'].symlink_to(other, target_is_directory=True)
    with pytest.raises(CheckpointError, match=r'models/mlp: not the mlp model this run trained'):
        load_run_model(tmp_path / 'run', run, 'mlp', mabi)
    with pytest.raises(CheckpointError, match=r'copied or linked in from another run'):
        check_run_model(own['mlp'])
    check_run_model(own['rnea_lq'])  # the run's own model still passes
    # A run from before the record: nothing to compare with.
    del run[ARTIFACTS_KEY]
    (tmp_path / 'run' / RUN_FILE).write_text(json.dumps(run))
    check_run_model(own['mlp'])


def test_a_model_in_a_folder_called_models_outside_a_run_is_not_judged_as_a_run_s(tmp_path, mabi):
    from predictor.tiny_artifacts import build_tiny_artifacts

    from id_learning.predictor.provenance import incomplete_run
    from id_learning.training.run_folder import check_run_model

    lone = build_tiny_artifacts(tmp_path / 'deploy' / 'models', mabi, kinds=['rnea_lq'])
    check_run_model(lone['rnea_lq'])  # no run.json beside models/: nothing to compare with
    assert incomplete_run(lone['rnea_lq']) is None
