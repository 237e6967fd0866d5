"""evaluate and closed-loop record the run they scored, and refuse one replaced while they ran.

Probe C01: ``evaluate --run run1c`` and, 2.5 s later, ``train --force --out run1c`` with other
models both exited 0; the evaluation scored the old models, but its metrics.json recorded only
the run's path, which then held another run. Here the swap is made in-process, between loading
the models and writing the results (a hook on the step that scores them), as ``train --force``
makes it: the whole run folder replaced by another (``outputs.replace_folder``).
"""

from __future__ import annotations

import json
import shutil
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest

from id_learning.cli.main import main
from id_learning.errors import CheckpointError
from id_learning.models.artifact import ARTIFACT_HASH, document_digest
from id_learning.outputs import replace_folder
from id_learning.robot.config import RobotConfig
from id_learning.training import closed_loop_run as closed_loop_module
from id_learning.training import trainer
from id_learning.training.closed_loop_run import closed_loop_run
from id_learning.training.run_folder import ARTIFACTS_KEY, RUN_FILE


@pytest.fixture(scope='module')
def trained(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path, RobotConfig]:
    """(a run of one rnea_lq model, the twin bag it was trained on, the robot)."""
    from support import quick_preprocess, twin_config

    from id_learning.training import train_run
    from id_learning.twin import simulate, write_twin_output

    folder = tmp_path_factory.mktemp('replaced')
    config = twin_config(30.0, seed=11)
    bag = write_twin_output(simulate(config), config, folder / 'twin')
    robot = config.robot
    run = train_run(
        [bag], robot, 'motor', ['rnea_lq'], folder / 'run', progress=False, device='cpu',
        preprocess=quick_preprocess(robot.n_joints),
    )  # fmt: skip
    return run.out, bag, robot


def _digest(run_dir: Path) -> str:
    return str(json.loads((run_dir / 'models/rnea_lq/model.json').read_text())[ARTIFACT_HASH])


def _another_run(run_dir: Path, where: Path) -> Path:
    """A copy of the run as a later ``train`` of it writes one: another model, another time."""
    other = Path(shutil.copytree(run_dir, where))
    meta_path = other / 'models/rnea_lq/model.json'
    metadata = json.loads(meta_path.read_text())
    metadata['hyperparameters'] = {**metadata['hyperparameters'], 'retrained': True}
    metadata[ARTIFACT_HASH] = document_digest(metadata)
    meta_path.write_text(json.dumps(metadata, indent=1))
    run = json.loads((other / RUN_FILE).read_text())
    run['created_unix_s'] += 60.0
    run[ARTIFACTS_KEY] = {'rnea_lq': metadata[ARTIFACT_HASH]}
    (other / RUN_FILE).write_text(json.dumps(run, indent=1))
    return other


def _swapping(step: Callable[..., Any], run_dir: Path, other: Path) -> Callable[..., Any]:
    """``step``, after which ``other`` replaces ``run_dir`` (train --force finishing)."""

    def swapped(*args: Any, **kwargs: Any) -> Any:
        result = step(*args, **kwargs)
        replace_folder(other, run_dir)
        return result

    return swapped


@pytest.fixture
def run_copy(trained: tuple[Path, Path, RobotConfig], tmp_path: Path) -> Path:
    """The run, copied: a test may replace it."""
    return Path(shutil.copytree(trained[0], tmp_path / 'run1c'))


def test_evaluate_records_the_run_s_creation_and_each_scored_model_s_digest(
    trained: tuple[Path, Path, RobotConfig], run_copy: Path, tmp_path: Path
) -> None:
    _, bag, robot = trained
    result = trainer.evaluate_run(run_copy, [bag], robot, tmp_path / 'eval', progress=False)
    metrics = json.loads((result.out / 'metrics.json').read_text())
    created = json.loads((run_copy / RUN_FILE).read_text())['created_unix_s']
    assert metrics['run'] == str(run_copy)
    assert metrics['run_identity'] == {
        'created_unix_s': created,
        'artifacts': {'rnea_lq': _digest(run_copy)},
    }


def test_evaluate_of_a_run_replaced_while_it_ran_fails_and_leaves_no_result(
    trained: tuple[Path, Path, RobotConfig],
    run_copy: Path,
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
) -> None:
    """Probe C01: the old models scored, the run replaced before the results are written."""
    _, bag, _ = trained
    scored = _digest(run_copy)
    other = _another_run(run_copy, tmp_path / 'run1c.new')
    replaced_by = _digest(other)
    monkeypatch.setattr(
        trainer, 'evaluate_models', _swapping(trainer.evaluate_models, run_copy, other)
    )
    out = tmp_path / 'eval'

    code = main(['evaluate', '--run', str(run_copy), '--bag', str(bag), '--out', str(out),
                 '--quiet'])  # fmt: skip

    assert code != 0
    err = capsys.readouterr().err
    assert str(run_copy) in err
    assert 'replaced' in err
    assert 'rnea_lq' in err
    assert scored[:12] in err
    assert replaced_by[:12] in err
    assert not out.exists()
    assert not out.with_name('eval.partial').exists()


def test_closed_loop_records_the_run_and_refuses_one_replaced_while_it_ran(
    trained: tuple[Path, Path, RobotConfig],
    run_copy: Path,
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    _, _, robot = trained
    result = closed_loop_run(run_copy, robot, tmp_path / 'loop', duration_s=1.0, progress=False)
    created = json.loads((run_copy / RUN_FILE).read_text())['created_unix_s']
    assert result.document['run_identity'] == {
        'created_unix_s': created,
        'artifacts': {'rnea_lq': _digest(run_copy)},
    }
    written = json.loads(result.json_path.read_text())
    assert written['run_identity'] == result.document['run_identity']

    scored = _digest(run_copy)
    other = _another_run(run_copy, tmp_path / 'run1c.new')
    monkeypatch.setattr(
        closed_loop_module,
        'compare_feed_forward',
        _swapping(closed_loop_module.compare_feed_forward, run_copy, other),
    )
    out = tmp_path / 'loop2'
    with pytest.raises(CheckpointError, match='replaced') as caught:
        closed_loop_run(run_copy, robot, out, duration_s=1.0, progress=False)
    assert scored[:12] in str(caught.value)
    assert not out.exists()
    assert not out.with_name('loop2.partial').exists()
