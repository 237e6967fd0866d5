"""A run.json edited by hand, or a link to nothing, is refused naming the file and what differs.

Probe V05: robot.drives.gear_ratio[0] changed from 205 to 100 in a run's run.json was used by
``evaluate`` without a word. Each model's model.json (hash-checked, and the one run.json's
``artifacts`` records) holds the robot, preprocessing, scaler and data the run used: run.json
must say the same. Probe V06: a run.json that is a dangling link was said to be missing.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from id_learning.errors import CheckpointError
from id_learning.models.artifact import ARTIFACT_HASH, robot_fingerprint
from id_learning.training.run_folder import (
    ARTIFACTS_KEY,
    RUN_FILE,
    RUN_FORMAT,
    check_run_model,
    load_run_model,
    read_run,
)

#: What the run saved beside its model (as ``train`` does): preprocessing, scaler and data.
EXTRA: dict[str, Any] = {
    'preprocessing': {'target': 'motor', 'cutoff_hz': [2.0] * 6},
    'target_scaler': {'low': [-1.0] * 6, 'high': [1.0] * 6},
    'training_data': {'bags': [{'path': 'bag', 'sha256': 'ab' * 32}]},
}


@pytest.fixture(scope='module')
def saved_run(tmp_path_factory: pytest.TempPathFactory, mabi: Any) -> Path:
    """A complete run folder holding one rnea_lq model, as ``train`` writes it."""
    from predictor.tiny_artifacts import training_recording
    from support import quick_preprocess

    from id_learning.dataset import prepare_dataset
    from id_learning.models.data import TrainingData
    from id_learning.models.registry import make_model, save_model

    run_dir = tmp_path_factory.mktemp('runs') / 'run'
    data = TrainingData(
        prepare_dataset(training_recording(), mabi, quick_preprocess(mabi.n_joints)), mabi
    )
    folder = save_model(
        make_model('rnea_lq', mabi).fit(data), run_dir / 'models' / 'rnea_lq', extra=EXTRA
    )
    digest = json.loads((folder / 'model.json').read_text())[ARTIFACT_HASH]
    run = {
        'format': RUN_FORMAT,
        'status': 'complete',
        'robot': robot_fingerprint(mabi),
        'kinds': ['rnea_lq'],
        **EXTRA,
        ARTIFACTS_KEY: {'rnea_lq': digest},
    }
    (run_dir / RUN_FILE).write_text(json.dumps(run, indent=1))
    (run_dir / 'metrics.json').write_text('{}')
    return run_dir


def _copy(run_dir: Path, tmp_path: Path) -> Path:
    import shutil

    return Path(shutil.copytree(run_dir, tmp_path / 'run', symlinks=True))


def _edit(run_dir: Path, key_path: tuple[str | int, ...], value: Any) -> dict[str, Any]:
    run = json.loads((run_dir / RUN_FILE).read_text())
    holder = run
    for key in key_path[:-1]:
        holder = holder[key]
    holder[key_path[-1]] = value
    (run_dir / RUN_FILE).write_text(json.dumps(run, indent=1))
    return run


def test_the_run_as_saved_loads_its_model(saved_run: Path, mabi: Any) -> None:
    run = read_run(saved_run)
    model = load_run_model(saved_run, run, 'rnea_lq', mabi)
    assert model.kind == 'rnea_lq'
    check_run_model(saved_run / 'models' / 'rnea_lq')  # reads run.json itself


def test_a_gear_ratio_edited_in_run_json_is_refused_naming_key_and_both_values(
    saved_run: Path, tmp_path: Path, mabi: Any
) -> None:
    run_dir = _copy(saved_run, tmp_path)
    _edit(run_dir, ('robot', 'drives', 'gear_ratio', 0), 100.0)
    assert mabi.drives.gear_ratio[0] == 205.0  # the robot config the model was trained for
    expected = (
        rf'{run_dir / RUN_FILE}: robot\.drives\.gear_ratio\[0\] is 100(\.0)? there but '
        rf'205(\.0)? in {run_dir / "models/rnea_lq/model.json"}'
    )
    with pytest.raises(CheckpointError, match=expected) as err:
        load_run_model(run_dir, read_run(run_dir), 'rnea_lq', mabi)
    assert 'edited' in str(err.value)
    # The predictor's check of a run's model (``provenance``) reads run.json itself: the same.
    with pytest.raises(CheckpointError, match=expected):
        check_run_model(run_dir / 'models' / 'rnea_lq')


@pytest.mark.parametrize(
    ('key_path', 'value', 'named'),
    [
        (('preprocessing', 'target'), 'joint',
         r'preprocessing\.target is "joint" there but "motor"'),
        (('target_scaler', 'high', 3), 9.0, r'target_scaler\.high\[3\] is 9(\.0)? there but 1'),
        (('training_data', 'bags', 0, 'sha256'), 'cd' * 32, r'training_data\.bags\[0\]\.sha256'),
        (('robot', 'name'), 'other', r'robot\.name is "other" there but'),
    ],
)  # fmt: skip
def test_every_section_evaluate_reads_from_run_json_is_checked(
    saved_run: Path, tmp_path: Path, mabi: Any, key_path: tuple[Any, ...], value: Any, named: str
) -> None:
    run_dir = _copy(saved_run, tmp_path)
    _edit(run_dir, key_path, value)
    with pytest.raises(CheckpointError, match=rf'{RUN_FILE}: {named}'):
        check_run_model(run_dir / 'models' / 'rnea_lq')


def test_a_key_removed_from_run_json_s_robot_is_named_as_absent(
    saved_run: Path, tmp_path: Path
) -> None:
    run_dir = _copy(saved_run, tmp_path)
    run = json.loads((run_dir / RUN_FILE).read_text())
    del run['robot']['drives']['torque_constant_nm_per_a']
    (run_dir / RUN_FILE).write_text(json.dumps(run))
    with pytest.raises(
        CheckpointError, match=r'robot\.drives\.torque_constant_nm_per_a is absent there but'
    ):
        check_run_model(run_dir / 'models' / 'rnea_lq')


def test_a_number_written_as_an_integer_is_the_same_number(
    saved_run: Path, tmp_path: Path, mabi: Any
) -> None:
    """205 and 205.0 are one value: a run.json re-indented or re-written by a tool still reads."""
    run_dir = _copy(saved_run, tmp_path)
    _edit(run_dir, ('robot', 'drives', 'gear_ratio', 0), 205)
    assert np.isclose(read_run(run_dir)['robot']['drives']['gear_ratio'][0], 205.0)
    load_run_model(run_dir, read_run(run_dir), 'rnea_lq', mabi)


# -- V06: a run.json (or model.json) that is a link to nothing ---------------------------------
def test_a_run_json_linking_to_nothing_is_named_as_such(saved_run: Path, tmp_path: Path) -> None:
    run_dir = _copy(saved_run, tmp_path)
    (run_dir / RUN_FILE).unlink()
    (run_dir / RUN_FILE).symlink_to(tmp_path / 'gone' / RUN_FILE)
    with pytest.raises(CheckpointError) as err:
        read_run(run_dir)
    message = str(err.value)
    assert str(run_dir / RUN_FILE) in message
    assert f'a link to {tmp_path / "gone" / RUN_FILE}, which does not exist' in message
    assert f'no {RUN_FILE}' not in message
    # A model of that run is not taken for a lone artifact: the broken run.json is named.
    with pytest.raises(CheckpointError, match=r'a link to .*, which does not exist'):
        check_run_model(run_dir / 'models' / 'rnea_lq')


def test_a_model_json_linking_to_nothing_is_named_as_such(
    saved_run: Path, tmp_path: Path, mabi: Any
) -> None:
    from id_learning.models.registry import load_model

    folder = _copy(saved_run, tmp_path) / 'models' / 'rnea_lq'
    (folder / 'model.json').unlink()
    (folder / 'model.json').symlink_to(tmp_path / 'moved.json')
    with pytest.raises(
        CheckpointError,
        match=rf'{folder / "model.json"}: a link to {tmp_path / "moved.json"}, which does not '
        'exist',
    ):
        load_model(folder, mabi)
