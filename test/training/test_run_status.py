"""A run.json whose status the package never writes is refused, naming it."""

from __future__ import annotations

import json

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
