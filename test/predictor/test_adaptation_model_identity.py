"""The adaptation's stored state belongs to one model: never continued on another, nor over it.

Probe A4/A5: a predictor adapting on ``runA/models/rnea_id`` while ``train --force --out runA``
retrained the run wrote its state into the new run at shutdown, and the restart applied the old
model's corrections to the new one. Probe A6: adapting on a model inside ``runB.partial`` while
train finished and renamed it to ``runB`` lost the state at shutdown (no such file). The loop is
driven without ROS; the artifacts are model.json files holding only their ``artifact_sha256``.
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from id_learning.models.artifact import ARTIFACT_HASH, METADATA_FILE
from id_learning.predictor.adaptation import AdaptationConfig, AdaptationLoop
from id_learning.predictor.adaptation_store import adaptation_path
from id_learning.robot.config import RobotConfig

OLD, NEW = 'a1' * 32, 'b2' * 32


def model(folder: Path, digest: str | None) -> Path:
    """An artifact folder whose model.json says ``digest`` (None: a model.json without one)."""
    folder.mkdir(parents=True, exist_ok=True)
    document = {'format': 'id_learning.model/1'}
    if digest is not None:
        document[ARTIFACT_HASH] = digest
    (folder / METADATA_FILE).write_text(json.dumps(document), encoding='utf-8')
    return folder


def learnt(robot: RobotConfig, artifact: Path, samples: int = 40) -> AdaptationLoop:
    """A loop started on ``artifact`` (``load``) that accepted ``samples`` updates."""
    loop = AdaptationLoop.for_robot(robot, robot.joints, AdaptationConfig())
    loop.load(artifact, robot.joints)
    rng = np.random.default_rng(3)
    n = len(robot.joints)
    for k in range(samples):
        stamp = 1_000_000 + k * 8_000_000
        loop.serve(stamp, (rng.uniform(-1, 1, n), rng.uniform(-1, 1, n), np.zeros(n)), np.zeros(n))
        effort = list(rng.normal(0.0, 0.5, n))
        loop.measured_message(stamp, list(robot.joints), effort, list(robot.joints))
    assert loop.session_updates == samples
    return loop


def test_the_state_records_the_model_it_was_learnt_on_and_the_same_model_continues_it(
    mabi: RobotConfig, tmp_path: Path
) -> None:
    artifact = model(tmp_path / 'runA' / 'models' / 'rnea_id', OLD)
    first = learnt(mabi, artifact)
    is_warning, line = first.finish(artifact, mabi.joints)
    assert not is_warning, line
    assert json.loads(adaptation_path(artifact).read_text())[ARTIFACT_HASH] == OLD

    second = AdaptationLoop.for_robot(mabi, mabi.joints, AdaptationConfig())
    base = second.load(artifact, mabi.joints)
    assert base.problem is None
    assert base.updates_before == 40


def test_a_state_learnt_on_another_model_is_not_continued_and_is_kept_aside_naming_both(
    mabi: RobotConfig, tmp_path: Path
) -> None:
    """Probe A4/A5: the run was retrained under the predictor; the restart starts from zero."""
    artifact = model(tmp_path / 'runA' / 'models' / 'rnea_id', OLD)
    learnt(mabi, artifact).finish(artifact, mabi.joints)
    path = adaptation_path(artifact)
    old_text = path.read_text()
    model(artifact, NEW)  # train --force --out runA: another model in the same place

    loop = AdaptationLoop.for_robot(mabi, mabi.joints, AdaptationConfig())
    base = loop.load(artifact, mabi.joints)

    assert base.problem is not None
    said = base.line()
    assert said is not None
    is_warning, line = said
    assert is_warning
    assert 'continues' not in line
    assert str(path) in line
    assert OLD[:12] in line
    assert NEW[:12] in line
    assert not loop.adapter.theta.any()  # starts from zero
    assert path.read_text() == old_text  # untouched at start

    rng = np.random.default_rng(4)
    n = len(mabi.joints)
    for k in range(10):
        loop.serve(k, (rng.uniform(-1, 1, n), rng.uniform(-1, 1, n), np.zeros(n)), np.zeros(n))
        loop.measured_message(k, list(mabi.joints), list(rng.normal(0, 0.5, n)), mabi.joints)
    loop.finish(artifact, mabi.joints)

    aside = path.with_name(f'{path.name}.model-{OLD[:12]}')
    assert aside.read_text() == old_text  # kept under a name that says whose it is
    stored = json.loads(path.read_text())
    assert stored[ARTIFACT_HASH] == NEW
    assert stored['updates_total'] == 10  # nothing of the other model's 40 counted


def test_a_state_written_before_states_recorded_their_model_is_not_continued(
    mabi: RobotConfig, tmp_path: Path
) -> None:
    artifact = model(tmp_path / 'run' / 'models' / 'rnea_id', OLD)
    learnt(mabi, artifact).finish(artifact, mabi.joints)
    path = adaptation_path(artifact)
    state = json.loads(path.read_text())
    del state[ARTIFACT_HASH]
    path.write_text(json.dumps(state))

    loop = AdaptationLoop.for_robot(mabi, mabi.joints, AdaptationConfig())
    base = loop.load(artifact, mabi.joints)

    assert base.problem is not None
    assert 'records no model' in base.problem
    assert OLD[:12] in base.problem
    assert not loop.adapter.theta.any()


def test_a_model_replaced_during_the_session_gets_the_state_in_a_side_file_never_over_the_new(
    mabi: RobotConfig, tmp_path: Path
) -> None:
    """Probe A4: at shutdown the model under the predictor is another one (and has a state)."""
    artifact = model(tmp_path / 'runA' / 'models' / 'rnea_id', OLD)
    loop = learnt(mabi, artifact)
    model(artifact, NEW)
    path = adaptation_path(artifact)
    path.write_text('{"the new model": "its own state"}')

    is_warning, line = loop.finish(artifact, mabi.joints)

    assert is_warning
    assert path.read_text() == '{"the new model": "its own state"}'
    side = path.with_name(f'{path.name}.model-{OLD[:12]}')
    assert str(side) in line
    assert OLD[:12] in line
    assert NEW[:12] in line
    stored = json.loads(side.read_text())
    assert stored[ARTIFACT_HASH] == OLD
    assert stored['updates'] == 40


def test_a_run_folder_renamed_when_train_completed_gets_the_state_in_the_final_folder(
    mabi: RobotConfig, tmp_path: Path
) -> None:
    """Probe A6: runB.partial became runB under the predictor; the state follows the model."""
    partial = tmp_path / 'runB.partial'
    artifact = model(partial / 'models' / 'rnea_id', OLD)
    loop = learnt(mabi, artifact)
    partial.rename(tmp_path / 'runB')

    is_warning, line = loop.finish(artifact, mabi.joints)

    final = adaptation_path(tmp_path / 'runB' / 'models' / 'rnea_id')
    assert 'not saved' not in line
    assert str(final) in line
    assert 'runB.partial' in line  # says where the model went
    assert not is_warning, line
    assert json.loads(final.read_text())['updates'] == 40


@pytest.mark.parametrize('final', ['absent', 'another model'])
def test_an_artifact_gone_without_its_model_elsewhere_gets_a_fallback_file_named_in_the_warning(
    mabi: RobotConfig, tmp_path: Path, final: str
) -> None:
    """The partial run was removed (train failed), or the final run holds another model."""
    partial = tmp_path / 'runs' / 'runB.partial'
    artifact = model(partial / 'models' / 'rnea_id', OLD)
    loop = learnt(mabi, artifact)
    shutil.rmtree(partial)
    if final == 'another model':
        model(tmp_path / 'runs' / 'runB' / 'models' / 'rnea_id', NEW)

    is_warning, line = loop.finish(artifact, mabi.joints)

    assert is_warning
    assert 'not saved' not in line
    written = [p for p in (tmp_path / 'runs').iterdir() if p.is_file()]
    assert len(written) == 1, written
    assert str(written[0]) in line
    assert OLD[:12] in written[0].name
    stored = json.loads(written[0].read_text())
    assert (stored[ARTIFACT_HASH], stored['updates']) == (OLD, 40)
    assert stored['artifact'] == str(artifact)
    assert not adaptation_path(tmp_path / 'runs' / 'runB' / 'models' / 'rnea_id').exists()


def test_a_state_that_cannot_be_written_where_it_belongs_is_written_beside_and_said(
    mabi: RobotConfig, tmp_path: Path
) -> None:
    artifact = model(tmp_path / 'run' / 'models' / 'rnea_id', OLD)
    loop = learnt(mabi, artifact)
    path = adaptation_path(artifact)
    path.with_name(f'.{path.name}.tmp').mkdir()  # the temporary file cannot be opened

    is_warning, line = loop.finish(artifact, mabi.joints)

    assert is_warning
    side = path.with_name(f'{path.name}.model-{OLD[:12]}')
    assert str(side) in line
    assert str(path) in line  # where it could not go
    assert json.loads(side.read_text())['updates'] == 40


def test_a_session_that_learnt_nothing_and_found_no_state_says_none_was_written(
    mabi: RobotConfig, tmp_path: Path
) -> None:
    """Probe A6's second finding: '... is left as it was' of a file that does not exist."""
    artifact = model(tmp_path / 'run' / 'models' / 'rnea_id', OLD)
    loop = AdaptationLoop.for_robot(mabi, mabi.joints, AdaptationConfig())
    loop.load(artifact, mabi.joints)

    is_warning, line = loop.finish(artifact, mabi.joints)

    assert not is_warning
    assert 'left as it was' not in line
    assert 'none written' in line
    assert not adaptation_path(artifact).exists()


def test_a_restart_names_the_state_an_earlier_session_saved_in_a_fallback_place(
    mabi: RobotConfig, tmp_path: Path
) -> None:
    """Probe 15 B78: the restart said only 'there is none at <artifact>.adaptation.json'."""
    artifact = model(tmp_path / 'run' / 'models' / 'rnea_id', OLD)
    path = adaptation_path(artifact)
    blocker = path.with_name(f'.{path.name}.tmp')
    blocker.mkdir()  # the state cannot be written beside its model
    is_warning, _ = learnt(mabi, artifact).finish(artifact, mabi.joints)
    assert is_warning
    blocker.rmdir()
    side = path.with_name(f'{path.name}.model-{OLD[:12]}')
    assert side.is_file()

    again = AdaptationLoop.for_robot(mabi, mabi.joints, AdaptationConfig())
    said = again.load(artifact, mabi.joints).line()

    assert said is not None
    assert said[0]  # a warning
    assert f'there is no {path}' in said[1]
    assert f'lies at {side}' in said[1]
    assert f'move it to {path}' in said[1]


def test_a_session_whose_every_sample_was_gated_says_so_as_a_warning(
    mabi: RobotConfig, tmp_path: Path
) -> None:
    """Probe 15 B48: joint torques on measured_topic (~420 x the currents) gated every sample;
    the last line blamed the latest frozen sample instead."""
    artifact = model(tmp_path / 'run' / 'models' / 'rnea_id', OLD)
    loop = AdaptationLoop.for_robot(mabi, mabi.joints, AdaptationConfig())
    loop.load(artifact, mabi.joints)
    rng = np.random.default_rng(5)
    n = len(mabi.joints)
    for k in range(200):
        stamp = 1_000_000 + k * 8_000_000
        loop.serve(stamp, (rng.uniform(-1, 1, n), rng.uniform(-1, 1, n), np.zeros(n)), np.zeros(n))
        torques = list(420.0 * rng.normal(0.0, 5.0, n) + 4000.0)
        loop.measured_message(stamp, list(mabi.joints), torques, list(mabi.joints))
    assert loop.session_updates == 0

    is_warning, line = loop.finish(artifact, mabi.joints)

    assert is_warning
    assert 'joint samples gated' in line
    assert 'currents [A] on measured_topic?' in line
