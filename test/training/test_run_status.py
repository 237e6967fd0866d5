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
